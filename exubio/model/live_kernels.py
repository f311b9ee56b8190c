"""One live frame's outputs in one compiled (numba) call: from the segment rotations a PF step gives
to the joint coordinates on the run's branch, the ISB angles and their rates, the model points, the
residuals and what the live checks read (exubio.run.live.frame wraps it).

Before, these were six compiled kernels and some forty numpy calls on 13-vectors and 21 x 3
arrays, whose per-call costs were most of a frame's time. The kernels are called as they were
(exubio.model.kernels: the inverse map, the forward kinematics, the ISB angles, the model points),
and the numpy steps between them are written out in numpy's own order of operations, so the
results are bit for bit those of the numpy steps (tests/run/test_live_frame.py): np.unwrap's
correction, the remainder's sign rule, a norm over 3 columns summed left to right and a mean over
the markers summed pairwise as numpy's reductions do (``_numpy_sum``). Arrays only, no exubio
imports beyond the kernels; compiled on the first call and cached on disk.
"""
from __future__ import annotations

import numba
import numpy as np

from exubio.model.kernels import _coordinates_one, _forward_one, _point, isb_angles

TWO_PI = 2.0 * np.pi


@numba.njit(cache=True, nogil=True)
def _block_sum(a, start, n):
    """numpy's pairwise summation of a[start:start + n], n <= 128: 8 partial sums, then the rest."""
    if n < 8:
        r = -0.0
        for i in range(n):
            r += a[start + i]
        return r
    r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
    r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
    i = 8
    while i < n - n % 8:
        s = start + i
        r0 += a[s]
        r1 += a[s + 1]
        r2 += a[s + 2]
        r3 += a[s + 3]
        r4 += a[s + 4]
        r5 += a[s + 5]
        r6 += a[s + 6]
        r7 += a[s + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i]
        i += 1
    return res


@numba.njit(cache=True, nogil=True)
def _numpy_sum(a, n):
    """np.add.reduce(a[:n]) (1-D, float64) bit for bit: numpy's pairwise summation, blocks of up to
    128 values summed by ``_block_sum`` and halves above added as numpy's recursion adds them (here
    with an explicit stack: numba's cache does not keep recursive functions)."""
    starts, sizes, expanded = np.empty(128, np.int64), np.empty(128, np.int64), np.empty(128, np.bool_)
    results = np.empty(64)
    top, n_res = 0, 0
    starts[0], sizes[0], expanded[0] = 0, n, False
    while top >= 0:
        s, m, done = starts[top], sizes[top], expanded[top]
        top -= 1
        if done:  # both halves summed: their sum
            n_res -= 1
            results[n_res - 1] = results[n_res - 1] + results[n_res]
        elif m <= 128:
            results[n_res] = _block_sum(a, s, m)
            n_res += 1
        else:  # the left half first, then the right, then their sum
            half = m // 2
            half -= half % 8
            starts[top + 1], sizes[top + 1], expanded[top + 1] = s, m, True
            starts[top + 2], sizes[top + 2], expanded[top + 2] = s + half, m - half, False
            starts[top + 3], sizes[top + 3], expanded[top + 3] = s, half, False
            top += 3
    return results[0]


@numba.njit(cache=True, nogil=True)
def frame_coordinates(Rd, mid, q0, parents, children, B, rev, rev_q, rev_axes, rev_proj, card, card_q, sph, sph_q,
                      sph_sign, ranges, state, has_last, q):
    """The coordinates q (m,) of one frame's segment rotations Rd (n_seg, 3, 3) on the run's branch:
    exubio.methods.pf._Frames.coordinates of one frame. parents ... ranges: the inverse map's tables
    (kernels.coordinates_from_rotations'); ``mid``: its reference (the middles of the ranges); state (3, m): the last frame's raw and unwrapped coordinates and the run's
    2 pi shift, updated (``has_last`` False: the run's first frame, whose shift puts it nearest q0)."""
    m = q.shape[0]
    raw = np.empty(m)
    _coordinates_one(Rd, mid, False, parents, children, B, rev, rev_q, rev_axes, rev_proj, card, card_q, sph, sph_q,
                     sph_sign, ranges, raw)
    last_raw, last_unwrapped, shift = state[0], state[1], state[2]
    if has_last:
        small = True
        for j in range(m):
            if not abs(raw[j] - last_raw[j]) < np.pi:
                small = False
        for j in range(m):
            dd = raw[j] - last_raw[j]
            corr = 0.0
            if not small and not abs(dd) < np.pi:  # np.unwrap's correction
                ddmod = (dd + np.pi) % TWO_PI - np.pi
                if ddmod == -np.pi and dd > 0:
                    ddmod = np.pi
                corr = ddmod - dd
            u = (raw[j] + corr) + (last_unwrapped[j] - last_raw[j])
            last_raw[j], last_unwrapped[j] = raw[j], u
            q[j] = u - shift[j]
    else:
        for j in range(m):
            shift[j] = TWO_PI * np.rint((raw[j] - q0[j]) / TWO_PI)
            last_raw[j] = last_unwrapped[j] = raw[j]
            q[j] = raw[j] - shift[j]


@numba.njit(cache=True, nogil=True)
def frame_outputs(q, parent, centre, first, count, axes, sk, sk2, segments, A, prox, dist, seq, negative, pt_seg,
                  pt_local, gh_seg, gh_axes, measured, angle_state, has_angles, rate_hz, R, p, isb, rate, pts, res):
    """From one frame's coordinates q (m,): the segment rotations and origins R, p (the forward
    kinematics: kernels.forward's tables parent ... sk2), the ISB angles isb (15,) unwrapped against the last
    published ones and their rates ``rate`` (backward differences; 0 after a frame without angles),
    the model points pts (k, 3) and their distances res (k,) from the measured positions.
    angle_state (2, 15): the last angles unwrapped against and the last published ones, updated;
    has_angles (2,): whether each is set. segments ... negative: kernels.isb_angles' tables; gh_seg (2,) the
    scapula's and the humerus's segments and gh_axes (2, 3) their long axes (gh_seg[0] < 0: none).
    Returns (the mean of the finite residuals in mm (NaN: none), the GH elevation (rad, NaN: none))."""
    m = q.shape[0]
    ax, piv = np.empty((m, 3)), np.empty((m, 3))
    Rc, T, E = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    _forward_one(q, parent, centre, first, count, axes, sk, sk2, R, p, ax, piv, Rc, T, E)
    out = np.empty((prox.shape[0], 3))
    isb_angles(R, segments, A, prox, dist, seq, negative, out)
    last, row = angle_state[0], angle_state[1]
    for j in range(isb.shape[0]):
        v = out[j // 3, j % 3]
        if has_angles[0]:  # PublishedAngles: unwrapped against the last frame with angles
            v = (last[j] + (v - last[j] + np.pi) % TWO_PI) - np.pi
        isb[j] = v
        last[j] = v
        rate[j] = (v - row[j]) * rate_hz if has_angles[1] else 0.0
        row[j] = v
    has_angles[0] = has_angles[1] = True
    gh = np.nan
    if gh_seg[0] >= 0:  # the angle between the scapula's and the humerus's long axes
        s, h = gh_seg[0], gh_seg[1]
        u, w = np.empty(3), np.empty(3)
        for i in range(3):
            u[i] = (R[s, i, 0] * gh_axes[0, 0] + R[s, i, 1] * gh_axes[0, 1]) + R[s, i, 2] * gh_axes[0, 2]
            w[i] = (R[h, i, 0] * gh_axes[1, 0] + R[h, i, 1] * gh_axes[1, 1]) + R[h, i, 2] * gh_axes[1, 2]
        gh = np.arccos(min(1.0, max(-1.0, (u[0] * w[0] + u[1] * w[1]) + u[2] * w[2])))
    k = pt_seg.shape[0]
    finite = np.empty(k)
    n_ok = 0
    for n in range(k):
        _point(R, p, pt_seg[n], pt_local[n], pts[n])
        d0, d1, d2 = pts[n, 0] - measured[n, 0], pts[n, 1] - measured[n, 1], pts[n, 2] - measured[n, 2]
        res[n] = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
        if np.isfinite(res[n]):
            finite[n_ok] = res[n]
            n_ok += 1
    mean = _numpy_sum(finite, n_ok) / n_ok * 1e3 if n_ok else np.nan
    return mean, gh


@numba.njit(cache=True, nogil=True)
def _point_jacobian(R, p, ax, piv, wc, affects, seg, local, r, J):
    """The point ``local`` of segment ``seg`` at r (3,) and its Jacobian J (3, m) (Kinematics.point_jacobian:
    column j = a_j x r - a_j x c_j where coordinate j moves the segment)."""
    _point(R, p, seg, local, r)
    for j in range(ax.shape[0]):
        f = affects[seg, j]
        J[0, j] = ((ax[j, 1] * r[2] - ax[j, 2] * r[1]) - wc[j, 0]) * f
        J[1, j] = ((ax[j, 2] * r[0] - ax[j, 0] * r[2]) - wc[j, 1]) * f
        J[2, j] = ((ax[j, 0] * r[1] - ax[j, 1] * r[0]) - wc[j, 2]) * f


@numba.njit(cache=True, nogil=True)
def frame_noise_gains(q, parent, centre, first, count, axes, sk, sk2, affects, pt_seg, pt_local, ct_seg, ct_local,
                      ell_centre, a_diag, weights, present, free, gain):
    """exubio.trust.observability's noise gains (deg per mm of marker noise) of one frame q (m,) into gain
    (m,): NaN where q is not finite and for the coordinates not in ``free`` (f,), inf for those a direction
    no present marker sees moves. The markers: pt_seg, pt_local (k,), weighted by weights (k,) where present;
    the ellipsoid's contact points ct_seg, ct_local, its centre and a_diag; parent ... sk2 the forward
    kinematics' tables and affects (n_seg, m) which coordinates move which segment. The same formulas as
    observability._gains (the constrained design's null space by an SVD, the information's pseudo-inverse
    and rank by its eigen-decomposition, as numpy's hermitian pinv and matrix_rank take them), to round-off:
    the flags a threshold draws on them are the trial function's (tests/trust/test_frame_determinacy.py)."""
    m, k, nf = q.shape[0], pt_seg.shape[0], free.shape[0]
    for j in range(m):
        gain[j] = np.nan
    for j in range(m):
        if not np.isfinite(q[j]):
            return
    n_seg = parent.shape[0]
    R, p = np.empty((n_seg, 3, 3)), np.empty((n_seg, 3))
    ax, piv, wc = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    Rc, T, E = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    _forward_one(q, parent, centre, first, count, axes, sk, sk2, R, p, ax, piv, Rc, T, E)
    for j in range(m):
        wc[j, 0] = ax[j, 1] * piv[j, 2] - ax[j, 2] * piv[j, 1]
        wc[j, 1] = ax[j, 2] * piv[j, 0] - ax[j, 0] * piv[j, 2]
        wc[j, 2] = ax[j, 0] * piv[j, 1] - ax[j, 1] * piv[j, 0]
    r, Jp = np.empty(3), np.empty((3, m))
    G = np.zeros((ct_seg.shape[0], nf))
    for c in range(ct_seg.shape[0]):
        _point_jacobian(R, p, ax, piv, wc, affects, ct_seg[c], ct_local[c], r, Jp)
        for a in range(nf):
            s = 0.0
            for i in range(3):
                s += (r[i] - ell_centre[i]) * a_diag[i] * Jp[i, free[a]]
            G[c, a] = 2.0 * s
    _, _, Vt = np.linalg.svd(G)
    nn = nf - G.shape[0]
    N = np.ascontiguousarray(Vt[G.shape[0]:, :].T)  # (f, f - 2): the directions the constraints allow
    M, S = np.zeros((nn, nn)), np.zeros((nn, nn))
    A = np.empty((3, nn))
    for n in range(k):
        if not present[n] or weights[n] == 0.0:
            continue
        _point_jacobian(R, p, ax, piv, wc, affects, pt_seg[n], pt_local[n], r, Jp)
        for i in range(3):
            for b in range(nn):
                s = 0.0
                for a in range(nf):
                    s += Jp[i, free[a]] * N[a, b]
                A[i, b] = s
        w = weights[n]
        for b in range(nn):
            for c in range(nn):
                s = A[0, b] * A[0, c] + A[1, b] * A[1, c] + A[2, b] * A[2, c]
                M[b, c] += w * s
                S[b, c] += w * w * s
    lam, U = np.linalg.eigh(M)
    top = np.abs(lam).max()
    Minv = np.zeros((nn, nn))
    rank = 0
    for i in range(nn):
        if abs(lam[i]) > 1e-12 * top:  # numpy's pinv and matrix_rank (hermitian, rcond = rtol = 1e-12)
            rank += 1
            for b in range(nn):
                for c in range(nn):
                    Minv[b, c] += U[b, i] * U[c, i] / lam[i]
    P = N @ Minv  # (f, nn)
    cov_diag = np.sum((P @ S) * P, axis=1)
    for a in range(nf):
        gain[free[a]] = np.degrees(np.sqrt(max(cov_diag[a], 0.0))) / 1000.0
    if rank < nn:  # the coordinates a direction no marker sees moves: undetermined
        NU = N @ U
        for a in range(nf):
            for i in range(nn):
                if lam[i] <= 1e-12 * lam[nn - 1] and abs(NU[a, i]) > 1e-6:
                    gain[free[a]] = np.inf
