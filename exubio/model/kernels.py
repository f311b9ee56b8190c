"""Compiled (numba) kernels of the model's kinematics, one frame at a time in plain loops, for the
batches where numpy's cost per call on 3x3 matrices dominates: forward kinematics
(``forward``) and the terms of the weighted marker least-squares problem (``least_squares``).

Arrays only, no exubio imports: the structure comes as the flat tables of
``exubio.model.kinematics.Kinematics.kernel_tables`` (parent of each segment, joint centre in the
parent, first coordinate and number of coordinates of each joint, each coordinate's axis and the
skew matrices of its Rodrigues rotation). Every kernel has a numpy reference that the tests hold
it equal to (1e-12): ``Kinematics.frames`` on small batches and
``exubio.model.pose_kernel.least_squares_terms_numpy``. Compiled on the first call (a few seconds)
and cached on disk (``cache=True``). Importing this module imports numba (about 0.2 s): import it
where it is used, inside the function.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def _forward_one(q, parent, centre, first, count, axes, sk, sk2, R, p, ax, piv, Rc, T, E):
    """Forward kinematics of one frame q (m,) into R (n_seg, 3, 3), p (n_seg, 3), the world axes
    ax (m, 3) and pivots piv (m, 3); Rc, T, E are 3x3 work arrays."""
    for i in range(3):
        for j in range(3):
            R[0, i, j] = 1.0 if i == j else 0.0
        p[0, i] = 0.0
    for s in range(1, parent.shape[0]):
        par = parent[s]
        for i in range(3):
            p[s, i] = p[par, i] + R[par, i, 0] * centre[s, 0] + R[par, i, 1] * centre[s, 1] + R[par, i, 2] * centre[s, 2]
            for j in range(3):
                Rc[i, j] = R[par, i, j]
        for c in range(first[s], first[s] + count[s]):
            for i in range(3):
                ax[c, i] = Rc[i, 0] * axes[c, 0] + Rc[i, 1] * axes[c, 1] + Rc[i, 2] * axes[c, 2]
                piv[c, i] = p[s, i]
            sq = np.sin(q[c])
            cq = 1.0 - np.cos(q[c])
            for i in range(3):
                for j in range(3):
                    E[i, j] = (1.0 if i == j else 0.0) + sq * sk[c, i, j] + cq * sk2[c, i, j]
            for i in range(3):
                for j in range(3):
                    T[i, j] = Rc[i, 0] * E[0, j] + Rc[i, 1] * E[1, j] + Rc[i, 2] * E[2, j]
            for i in range(3):
                for j in range(3):
                    Rc[i, j] = T[i, j]
        for i in range(3):
            for j in range(3):
                R[s, i, j] = Rc[i, j]


@numba.njit(cache=True, nogil=True)
def forward(q, parent, centre, first, count, axes, sk, sk2, R, p, ax, piv):
    """Forward kinematics of every frame of q (B, m) into R (B, n_seg, 3, 3), p (B, n_seg, 3),
    ax (B, m, 3), piv (B, m, 3)."""
    Rc = np.zeros((3, 3))
    T = np.zeros((3, 3))
    E = np.zeros((3, 3))
    for b in range(q.shape[0]):
        _forward_one(q[b], parent, centre, first, count, axes, sk, sk2, R[b], p[b], ax[b], piv[b], Rc, T, E)


@numba.njit(cache=True, nogil=True)
def least_squares(q, target, w, parent, centre, first, count, axes, sk, sk2, affects, pt_seg, pt_local,
                  c_seg, c_local, a_diag, ell_centre, cost, H, grad, g, G):
    """For every frame of q (B, m): cost = sum_n w_n |r_n - target_n|^2, H = J^T W J (upper
    triangle accumulated, mirrored), grad = J^T W e over the points with w > 0 (J's columns
    a_j x (r - c_j) where coordinate j moves the point), then the two ellipsoid contact points'
    g = e^T A e - 1 and G = 2 e^T A J."""
    B, m = q.shape
    n_seg = parent.shape[0]
    R = np.zeros((n_seg, 3, 3))
    p = np.zeros((n_seg, 3))
    ax = np.zeros((m, 3))
    piv = np.zeros((m, 3))
    Rc = np.zeros((3, 3))
    T = np.zeros((3, 3))
    E = np.zeros((3, 3))
    J = np.zeros((3, m))
    r = np.zeros(3)
    e = np.zeros(3)
    for b in range(B):
        _forward_one(q[b], parent, centre, first, count, axes, sk, sk2, R, p, ax, piv, Rc, T, E)
        total = 0.0
        for i in range(m):
            grad[b, i] = 0.0
            for j in range(m):
                H[b, i, j] = 0.0
        for n in range(pt_seg.shape[0]):
            wn = w[b, n]
            if not wn > 0.0:
                continue
            s = pt_seg[n]
            _point(R, p, s, pt_local[n], r)
            for i in range(3):
                e[i] = r[i] - target[b, n, i]
                total += wn * e[i] * e[i]
            _columns(ax, piv, affects[s], r, J)
            for i in range(m):
                if not affects[s, i]:
                    continue
                grad[b, i] += wn * (J[0, i] * e[0] + J[1, i] * e[1] + J[2, i] * e[2])
                for j in range(i, m):
                    if affects[s, j]:
                        H[b, i, j] += wn * (J[0, i] * J[0, j] + J[1, i] * J[1, j] + J[2, i] * J[2, j])
        for i in range(m):
            for j in range(i + 1, m):
                H[b, j, i] = H[b, i, j]
        cost[b] = total
        for n in range(c_seg.shape[0]):
            s = c_seg[n]
            _point(R, p, s, c_local[n], r)
            gn = -1.0
            for i in range(3):
                e[i] = r[i] - ell_centre[i]
                gn += a_diag[i] * e[i] * e[i]
            g[b, n] = gn
            _columns(ax, piv, affects[s], r, J)
            for j in range(m):
                G[b, n, j] = 2.0 * (a_diag[0] * e[0] * J[0, j] + a_diag[1] * e[1] * J[1, j] + a_diag[2] * e[2] * J[2, j])


@numba.njit(cache=True, nogil=True)
def _point(R, p, s, local, out):
    for i in range(3):
        out[i] = R[s, i, 0] * local[0] + R[s, i, 1] * local[1] + R[s, i, 2] * local[2] + p[s, i]


@numba.njit(cache=True, nogil=True)
def _columns(ax, piv, moves, r, J):
    """J[:, j] = a_j x (r - c_j) where coordinate j moves the point, 0 elsewhere."""
    for j in range(ax.shape[0]):
        if moves[j]:
            dx, dy, dz = r[0] - piv[j, 0], r[1] - piv[j, 1], r[2] - piv[j, 2]
            J[0, j] = ax[j, 1] * dz - ax[j, 2] * dy
            J[1, j] = ax[j, 2] * dx - ax[j, 0] * dz
            J[2, j] = ax[j, 0] * dy - ax[j, 1] * dx
        else:
            J[0, j] = 0.0
            J[1, j] = 0.0
            J[2, j] = 0.0


@numba.njit(cache=True, nogil=True)
def euler_parameter_motion(X, Xt, Xtt, ltg, ep_ref, p_ref, R, p, v, a, w, al):
    """The motion of rigid bodies on Euler-parameter nodes, frame by frame: X, Xt, Xtt (n, N) the
    system coordinates and their rates; ltg (s, 7) each body's node coordinates in them (3 of
    position, 4 Euler parameters, both as displacements from ep_ref (s, 4), p_ref (s, 3)).
    Into R (n, s + 1, 3, 3), p, v, a, w (angular velocity), al (angular acceleration) (n, s + 1, 3),
    index 0 the fixed root (identity, zeros). With e the unit Euler parameters,
    omega = G(e) ė and alpha = G(e) ë (G_t ė = 0), G = 2 [[-e1, e0, -e3, e2], [-e2, e3, e0, -e1],
    [-e3, -e2, e1, e0]]; R the textbook matrix of e."""
    e = np.zeros(4)
    G = np.zeros((3, 4))
    for f in range(X.shape[0]):
        for i in range(3):
            for j in range(3):
                R[f, 0, i, j] = 1.0 if i == j else 0.0
            p[f, 0, i] = v[f, 0, i] = a[f, 0, i] = w[f, 0, i] = al[f, 0, i] = 0.0
        for s in range(ltg.shape[0]):
            b = s + 1
            norm = 0.0
            for i in range(4):
                e[i] = X[f, ltg[s, 3 + i]] + ep_ref[s, i]
                norm += e[i] * e[i]
            norm = np.sqrt(norm)
            for i in range(4):
                e[i] = e[i] / norm
            e0, e1, e2, e3 = e[0], e[1], e[2], e[3]
            R[f, b, 0, 0] = 1 - 2 * (e2 * e2 + e3 * e3)
            R[f, b, 0, 1] = 2 * (e1 * e2 - e0 * e3)
            R[f, b, 0, 2] = 2 * (e1 * e3 + e0 * e2)
            R[f, b, 1, 0] = 2 * (e1 * e2 + e0 * e3)
            R[f, b, 1, 1] = 1 - 2 * (e1 * e1 + e3 * e3)
            R[f, b, 1, 2] = 2 * (e2 * e3 - e0 * e1)
            R[f, b, 2, 0] = 2 * (e1 * e3 - e0 * e2)
            R[f, b, 2, 1] = 2 * (e2 * e3 + e0 * e1)
            R[f, b, 2, 2] = 1 - 2 * (e1 * e1 + e2 * e2)
            G[0, 0], G[0, 1], G[0, 2], G[0, 3] = -2 * e1, 2 * e0, -2 * e3, 2 * e2
            G[1, 0], G[1, 1], G[1, 2], G[1, 3] = -2 * e2, 2 * e3, 2 * e0, -2 * e1
            G[2, 0], G[2, 1], G[2, 2], G[2, 3] = -2 * e3, -2 * e2, 2 * e1, 2 * e0
            for i in range(3):
                p[f, b, i] = X[f, ltg[s, i]] + p_ref[s, i]
                v[f, b, i] = Xt[f, ltg[s, i]]
                a[f, b, i] = Xtt[f, ltg[s, i]]
                wi = 0.0
                ali = 0.0
                for j in range(4):
                    wi += G[i, j] * Xt[f, ltg[s, 3 + j]]
                    ali += G[i, j] * Xtt[f, ltg[s, 3 + j]]
                w[f, b, i] = wi
                al[f, b, i] = ali


@numba.njit(cache=True, nogil=True)
def _wrap(q, lo, hi, ref):
    """ranges.wrap_into_range for one angle: q + 2 pi k, k nearest (ref - q) / 2 pi or one either
    side, whichever is inside the range [lo, hi] or nearest to it."""
    two_pi = 2.0 * np.pi
    k0 = np.rint((ref - q) / two_pi)
    best = q + two_pi * k0
    best_cost = abs(max(best - hi, 0.0) - max(lo - best, 0.0))
    for dk in (-1.0, 1.0):
        cand = q + two_pi * (k0 + dk)
        cost = abs(max(cand - hi, 0.0) - max(lo - cand, 0.0))
        if cost < best_cost - 1e-12:
            best, best_cost = cand, cost
    return best


@numba.njit(cache=True, nogil=True)
def coordinates_from_rotations(R, ref, has_previous, parents, children, B, rev, rev_q, rev_axes, rev_proj, card,
                               card_q, sph, sph_q, sph_sign, ranges, out):
    """Kinematics.coordinates_from_rotations frame by frame (its docstring says the rule): segment
    rotations R (n, n_seg, 3, 3) -> coordinates ``out`` (n, m); ``ref`` (n, m) the previous
    coordinates (``has_previous``) or the middles of the ranges. The joint tables are those of
    exubio.model.kinematics._InverseTable (B the joints' axis bases, rev_proj I - a a^T)."""
    for f in range(R.shape[0]):
        _coordinates_one(R[f], ref[f], has_previous, parents, children, B, rev, rev_q, rev_axes, rev_proj, card,
                         card_q, sph, sph_q, sph_sign, ranges, out[f])


@numba.njit(cache=True, nogil=True)
def _coordinates_one(R, ref, has_previous, parents, children, B, rev, rev_q, rev_axes, rev_proj, card,
                     card_q, sph, sph_q, sph_sign, ranges, out):
    n_joints = parents.shape[0]
    Rrel = np.empty((n_joints, 3, 3))
    Rs = np.empty((n_joints, 3, 3))
    T = np.empty((3, 3))
    for n in range(n_joints):
        par, ch = parents[n], children[n]
        for i in range(3):
            for j in range(3):
                Rrel[n, i, j] = R[par, 0, i] * R[ch, 0, j] + R[par, 1, i] * R[ch, 1, j] + R[par, 2, i] * R[ch, 2, j]
        for i in range(3):  # B^T Rrel
            for j in range(3):
                T[i, j] = B[n, 0, i] * Rrel[n, 0, j] + B[n, 1, i] * Rrel[n, 1, j] + B[n, 2, i] * Rrel[n, 2, j]
        for i in range(3):  # (B^T Rrel) B
            for j in range(3):
                Rs[n, i, j] = T[i, 0] * B[n, 0, j] + T[i, 1] * B[n, 1, j] + T[i, 2] * B[n, 2, j]
    m = out.shape[0]
    qa = np.empty(m)
    for r in range(rev.shape[0]):  # revolute: the angle about the axis, cos from R orthogonal to it
        Rr = Rrel[rev[r]]
        a = rev_axes[r]
        s = (Rr[2, 1] - Rr[1, 2]) * a[0] + (Rr[0, 2] - Rr[2, 0]) * a[1] + (Rr[1, 0] - Rr[0, 1]) * a[2]
        P = rev_proj[r]
        c = 0.0
        for i in range(3):  # trace(P Rr P)
            for j in range(3):
                for k in range(3):
                    c += P[i, j] * Rr[j, k] * P[k, i]
        qa[rev_q[r]] = np.arctan2(0.5 * s, 0.5 * c)
    for r in range(card.shape[0]):  # cardan: Rx(q1) Ry(q2)
        Rc = Rs[card[r]]
        qa[card_q[r, 0]] = np.arctan2(Rc[2, 1], Rc[1, 1])
        qa[card_q[r, 1]] = np.arctan2(Rc[0, 2], Rc[0, 0])
    lo, hi = ranges[:, 0], ranges[:, 1]
    for j in range(m):
        out[j] = _wrap(qa[j], lo[j], hi[j], ref[j])
    for r in range(sph.shape[0]):  # spherical: Rx(q1) Ry(q2) Rz(sign q3), two angle triples
        Rp = Rs[sph[r]]
        j1, j2, j3 = sph_q[r, 0], sph_q[r, 1], sph_q[r, 2]
        q2 = np.arctan2(Rp[0, 2], np.hypot(Rp[0, 0], Rp[0, 1]))
        q1 = np.arctan2(-Rp[1, 2], Rp[2, 2])
        q3 = np.arctan2(-Rp[0, 1], Rp[0, 0])
        if np.cos(q2) < 1e-6:  # Rx(q1) Ry(+-90) Rz(q3): keep q1 (the previous one, or 0), solve q3
            q1 = ref[j1] if has_previous else 0.0
            q3 = np.arctan2(Rp[1, 0], Rp[1, 1]) - np.sign(Rp[0, 2]) * q1
        sg = sph_sign[r]
        a1, a2, a3 = _wrap(q1, lo[j1], hi[j1], ref[j1]), _wrap(q2, lo[j2], hi[j2], ref[j2]), _wrap(sg * q3, lo[j3], hi[j3], ref[j3])
        b1 = _wrap(q1 + np.pi, lo[j1], hi[j1], ref[j1])
        b2 = _wrap(np.pi - q2, lo[j2], hi[j2], ref[j2])
        b3 = _wrap(sg * (q3 + np.pi), lo[j3], hi[j3], ref[j3])
        cost_a = (abs(max(a1 - hi[j1], 0.0) - max(lo[j1] - a1, 0.0)) + abs(max(a2 - hi[j2], 0.0) - max(lo[j2] - a2, 0.0))
                  + abs(max(a3 - hi[j3], 0.0) - max(lo[j3] - a3, 0.0)))
        cost_b = (abs(max(b1 - hi[j1], 0.0) - max(lo[j1] - b1, 0.0)) + abs(max(b2 - hi[j2], 0.0) - max(lo[j2] - b2, 0.0))
                  + abs(max(b3 - hi[j3], 0.0) - max(lo[j3] - b3, 0.0)))
        take_b = cost_b < cost_a - 1e-12
        if has_previous and abs(cost_b - cost_a) <= 1e-12:
            near_a = abs(a1 - ref[j1]) + abs(a2 - ref[j2]) + abs(a3 - ref[j3])
            near_b = abs(b1 - ref[j1]) + abs(b2 - ref[j2]) + abs(b3 - ref[j3])
            take_b = take_b or near_b < near_a
        if take_b:
            out[j1], out[j2], out[j3] = b1, b2, b3
        else:
            out[j1], out[j2], out[j3] = a1, a2, a3


@numba.njit(cache=True, nogil=True)
def _basic(axis, angle, out):
    """angles._basic_rotation: the rotation about coordinate axis ``axis`` by ``angle``."""
    c, s = np.cos(angle), np.sin(angle)
    u, v = (axis + 1) % 3, (axis + 2) % 3
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
    out[axis, axis] = 1.0
    out[u, u] = c
    out[v, v] = c
    out[v, u] = s
    out[u, v] = -s


@numba.njit(cache=True, nogil=True)
def isb_angles(R, segments, A, prox, dist, seq, negative, out):
    """exubio.model.angles.isb_table's angles of one frame: segment rotations R (n_seg, 3, 3), the
    anatomical frames A (f, 3, 3) of the segments ``segments`` (f,), each joint's proximal and
    distal frame (prox, dist (n,)), its sequence's axes seq (n, 3) and whether its middle angle is
    negative (HT); into out (n, 3), wrapped into (-pi, pi] (euler_angles' rule, gimbal tolerance
    1e-9: the first angle 0 at the lock)."""
    f = segments.shape[0]
    Rg = np.empty((f, 3, 3))
    for n in range(f):
        s = segments[n]
        for i in range(3):
            for j in range(3):
                Rg[n, i, j] = R[s, i, 0] * A[n, 0, j] + R[s, i, 1] * A[n, 1, j] + R[s, i, 2] * A[n, 2, j]
    Rr = np.empty((3, 3))
    Ra = np.empty((3, 3))
    Rb = np.empty((3, 3))
    P = np.empty((3, 3))
    M = np.empty((3, 3))
    two_pi = 2.0 * np.pi
    for r in range(prox.shape[0]):
        pa, da = prox[r], dist[r]
        for i in range(3):
            for j in range(3):
                Rr[i, j] = Rg[pa, 0, i] * Rg[da, 0, j] + Rg[pa, 1, i] * Rg[da, 1, j] + Rg[pa, 2, i] * Rg[da, 2, j]
        i, j, k = seq[r, 0], seq[r, 1], seq[r, 2]
        s = 1.0 if (j - i) % 3 == 1 else -1.0
        if i != k:  # Tait-Bryan
            b = np.arctan2(s * Rr[i, k], np.hypot(Rr[i, i], Rr[i, j]))
            a = np.arctan2(-s * Rr[j, k], Rr[k, k])
            locked = np.cos(b) < 1e-9
        else:  # proper Euler
            mm = 3 - i - j
            sb = np.hypot(Rr[i, j], Rr[i, mm])
            b = np.arctan2(sb, Rr[i, i])
            a = np.arctan2(Rr[j, i], -s * Rr[mm, i])
            if negative[r]:
                b, a = -b, a + np.pi
            locked = sb < 1e-9
        if locked:
            a = 0.0
        _basic(i, a, Ra)
        _basic(j, b, Rb)
        for x in range(3):  # P = Ra Rb
            for y in range(3):
                P[x, y] = Ra[x, 0] * Rb[0, y] + Ra[x, 1] * Rb[1, y] + Ra[x, 2] * Rb[2, y]
        for x in range(3):  # M = P^T Rr
            for y in range(3):
                M[x, y] = P[0, x] * Rr[0, y] + P[1, x] * Rr[1, y] + P[2, x] * Rr[2, y]
        u, v = (k + 1) % 3, (k + 2) % 3
        c = np.arctan2(M[v, u] - M[u, v], M[u, u] + M[v, v])
        out[r, 0] = np.pi - (np.pi - a) % two_pi
        out[r, 1] = np.pi - (np.pi - b) % two_pi
        out[r, 2] = np.pi - (np.pi - c) % two_pi


@numba.njit(cache=True, nogil=True)
def _invert_small(N, k, out):
    """out = N^-1 for the leading k x k block of N (k = 1, 2, 3; closed form: the joints' axis Gram
    matrices, near the identity)."""
    if k == 1:
        out[0, 0] = 1.0 / N[0, 0]
    elif k == 2:
        det = N[0, 0] * N[1, 1] - N[0, 1] * N[1, 0]
        out[0, 0], out[0, 1] = N[1, 1] / det, -N[0, 1] / det
        out[1, 0], out[1, 1] = -N[1, 0] / det, N[0, 0] / det
    else:
        c00 = N[1, 1] * N[2, 2] - N[1, 2] * N[2, 1]
        c01 = N[1, 2] * N[2, 0] - N[1, 0] * N[2, 2]
        c02 = N[1, 0] * N[2, 1] - N[1, 1] * N[2, 0]
        det = N[0, 0] * c00 + N[0, 1] * c01 + N[0, 2] * c02
        out[0, 0] = c00 / det
        out[1, 0] = c01 / det
        out[2, 0] = c02 / det
        out[0, 1] = (N[0, 2] * N[2, 1] - N[0, 1] * N[2, 2]) / det
        out[1, 1] = (N[0, 0] * N[2, 2] - N[0, 2] * N[2, 0]) / det
        out[2, 1] = (N[0, 1] * N[2, 0] - N[0, 0] * N[2, 1]) / det
        out[0, 2] = (N[0, 1] * N[1, 2] - N[0, 2] * N[1, 1]) / det
        out[1, 2] = (N[0, 2] * N[1, 0] - N[0, 0] * N[1, 2]) / det
        out[2, 2] = (N[0, 0] * N[1, 1] - N[0, 1] * N[1, 0]) / det


@numba.njit(cache=True, nogil=True)
def coordinate_rates(q, omega, alpha, with_alpha, parent, centre, first, count, axes, sk, sk2, qd, qdd):
    """Kinematics.coordinate_rates frame by frame: per joint, W q̇_joint = omega_child - omega_parent
    (least squares, W the joint's world axes as columns: q̇ = (W^T W)^-1 W^T dw) and, with
    ``with_alpha``, W q̈_joint = alpha_child - alpha_parent - sum_n (Omega_n x w_n) q̇_n (Omega_n the
    angular velocity of the frame that carries axis n). q (B, m), omega and alpha (B, n_seg, 3);
    into qd, qdd (B, m)."""
    B, m = q.shape
    n_seg = parent.shape[0]
    R = np.zeros((n_seg, 3, 3))
    p = np.zeros((n_seg, 3))
    ax = np.zeros((m, 3))
    piv = np.zeros((m, 3))
    Rc = np.zeros((3, 3))
    T = np.zeros((3, 3))
    E = np.zeros((3, 3))
    N = np.zeros((3, 3))
    Ni = np.zeros((3, 3))
    P = np.zeros((3, 3))
    d = np.zeros(3)
    om = np.zeros(3)
    bias = np.zeros(3)
    for b in range(B):
        _forward_one(q[b], parent, centre, first, count, axes, sk, sk2, R, p, ax, piv, Rc, T, E)
        for s in range(1, n_seg):
            k, f0, par = count[s], first[s], parent[s]
            for u in range(k):
                for v in range(k):
                    N[u, v] = ax[f0 + u, 0] * ax[f0 + v, 0] + ax[f0 + u, 1] * ax[f0 + v, 1] + ax[f0 + u, 2] * ax[f0 + v, 2]
            _invert_small(N, k, Ni)
            for u in range(k):  # the pseudo-inverse (W^T W)^-1 W^T, k x 3
                for c in range(3):
                    acc = 0.0
                    for v in range(k):
                        acc += Ni[u, v] * ax[f0 + v, c]
                    P[u, c] = acc
            for c in range(3):
                d[c] = omega[b, s, c] - omega[b, par, c]
            for u in range(k):
                qd[b, f0 + u] = P[u, 0] * d[0] + P[u, 1] * d[1] + P[u, 2] * d[2]
            if not with_alpha:
                continue
            for c in range(3):
                om[c] = omega[b, par, c]
                bias[c] = 0.0
            for n in range(k):
                j = f0 + n
                if n > 0:
                    for c in range(3):
                        om[c] += ax[j - 1, c] * qd[b, j - 1]
                bias[0] += (om[1] * ax[j, 2] - om[2] * ax[j, 1]) * qd[b, j]
                bias[1] += (om[2] * ax[j, 0] - om[0] * ax[j, 2]) * qd[b, j]
                bias[2] += (om[0] * ax[j, 1] - om[1] * ax[j, 0]) * qd[b, j]
            for c in range(3):
                d[c] = alpha[b, s, c] - alpha[b, par, c] - bias[c]
            for u in range(k):
                qdd[b, f0 + u] = P[u, 0] * d[0] + P[u, 1] * d[1] + P[u, 2] * d[2]


@numba.njit(cache=True, nogil=True)
def points(R, p, seg, local, out):
    """Model points of every frame: out[b, n] = R[b, seg[n]] @ local[n] + p[b, seg[n]]; R (B, n_seg,
    3, 3), p (B, n_seg, 3), out (B, k, 3)."""
    for b in range(R.shape[0]):
        for n in range(seg.shape[0]):
            _point(R[b], p[b], seg[n], local[n], out[b, n])
