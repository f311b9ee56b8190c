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
