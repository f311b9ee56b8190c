"""Compiled (numba) kernels of the per-trial preparation and checks, where numpy's cost per call or
its generic loops dominate: the zero-lag IIR filter of many series at once (``filtfilt_columns``,
the low-pass and the automatic cut-off of exubio.prep.filtering), small batched contractions
(the chain fits of exubio.trust.label_chains, the uncertainty's quadratic forms) and one live
frame's causal targets (``causal_frame``, exubio.run.live.causal).

Each kernel does the same arithmetic in the same order as its numpy (or scipy) reference, so the
results are bit-identical, not only close: the tests (tests/model/test_batch_kernels.py) hold them
equal with ``np.array_equal``. Numba's default (no fastmath) keeps every multiply and add as
written (no fused multiply-add, no reassociation); vectorising across independent series or
problems does not change any one's order of operations. Arrays only, no exubio imports; compiled
on the first call and cached on disk (``cache=True``). Importing this module imports numba: import
it where it is used, inside the function.
"""
from __future__ import annotations

import numba
import numpy as np


# --------------------------------------------------------------------------------------------
# Zero-lag IIR filter (scipy.signal.filtfilt with padtype=None), time first, many series at once
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def _lfilter_pass(bn, an, x, out, z, t0, t1, step):
    """One pass of scipy's lfilter (transposed direct form II, coefficients normalised by a[0]) over
    the rows t0, t0 + step, ... (not t1) of x (L, m) into out (may be x itself); z (nb - 1, m): the
    state, updated. Per series the operations of scipy's C loop, in its order."""
    m = x.shape[1]
    nb = bn.shape[0]
    xr = np.empty(m)
    t = t0
    while t != t1:
        for s in range(m):
            xr[s] = x[t, s]
        yr = out[t]
        for s in range(m):
            yr[s] = z[0, s] + bn[0] * xr[s]
        for k in range(nb - 2):
            zk = z[k]
            zk1 = z[k + 1]
            bk = bn[k + 1]
            ak = an[k + 1]
            for s in range(m):
                zk[s] = zk1[s] + xr[s] * bk - yr[s] * ak
        zl = z[nb - 2]
        bl = bn[nb - 1]
        al = an[nb - 1]
        for s in range(m):
            zl[s] = xr[s] * bl - yr[s] * al
        t += step


@numba.njit(cache=True, nogil=True)
def filtfilt_columns(b, a, zi, x, out):
    """scipy.signal.filtfilt(b, a, x.T, padtype=None).T of x (L, m): every column a series, filtered
    forward from the steady state ``zi`` (scipy.signal.lfilter_zi(b, a)) times its first sample,
    then backward from ``zi`` times the forward pass's last sample, into out (L, m). len(b) ==
    len(a) >= 2. The columns are filtered side by side (one time step of every series, then the
    next): the recursions are independent, and the loops over the series vectorise."""
    L, m = x.shape
    nb = b.shape[0]
    bn = b / a[0]
    an = a / a[0]
    z = np.empty((nb - 1, m))
    for k in range(nb - 1):
        for s in range(m):
            z[k, s] = zi[k] * x[0, s]
    _lfilter_pass(bn, an, x, out, z, 0, L, 1)
    for k in range(nb - 1):
        for s in range(m):
            z[k, s] = zi[k] * out[L - 1, s]
    _lfilter_pass(bn, an, out, out, z, L - 1, -1, -1)


# --------------------------------------------------------------------------------------------
# Chain fits (exubio.trust.label_chains): rigid placement and Levenberg-Marquardt normal equations
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def chain_in_root_frame(R, P, axes, pivots, p, affects, coords, root, rel, jrel):
    """A chain's marker points and their Jacobian in its root segment's frame, per problem b: from
    the forward kinematics (R (b, n_seg, 3, 3), P (b, n_seg, 3), axes and pivots (b, m, 3)) and
    the points p (b, k, 3), rel (b, k, 3) = R_root^T (p - P_root) and jrel (b, k, 3, c) = R_root^T
    dp/dq for the coordinates ``coords`` (c,). The numpy reference (label_chains._chain_in_root_frame_numpy):
    Kinematics.point_jacobian (column j: w_j x r - w_j x c_j, times ``affects`` (k, m): 1.0 where
    coordinate j moves point k, else 0.0), then np.einsum("bji,bkj->bki", ...) and
    np.einsum("bji,bkjc->bkic", ...); the same operations in the same order."""
    b, k, _ = p.shape
    c = coords.shape[0]
    wc = np.empty((c, 3))
    jac = np.empty((3, c))
    d = np.empty(3)
    for n in range(b):
        for cc in range(c):
            j = coords[cc]
            a0, a1, a2 = axes[n, j, 0], axes[n, j, 1], axes[n, j, 2]
            b0, b1, b2 = pivots[n, j, 0], pivots[n, j, 1], pivots[n, j, 2]
            wc[cc, 0] = a1 * b2 - a2 * b1
            wc[cc, 1] = a2 * b0 - a0 * b2
            wc[cc, 2] = a0 * b1 - a1 * b0
        for s in range(k):
            x, y, z = p[n, s, 0], p[n, s, 1], p[n, s, 2]
            for cc in range(c):
                j = coords[cc]
                w0, w1, w2 = axes[n, j, 0], axes[n, j, 1], axes[n, j, 2]
                f = affects[s, j]
                jac[0, cc] = ((w1 * z - w2 * y) - wc[cc, 0]) * f
                jac[1, cc] = ((w2 * x - w0 * z) - wc[cc, 1]) * f
                jac[2, cc] = ((w0 * y - w1 * x) - wc[cc, 2]) * f
            for i in range(3):
                d[i] = p[n, s, i] - P[n, root, i]
            for i in range(3):
                acc = 0.0
                for j in range(3):
                    acc += R[n, root, j, i] * d[j]
                rel[n, s, i] = acc
                for cc in range(c):
                    acc = 0.0
                    for j in range(3):
                        acc += R[n, root, j, i] * jac[j, cc]
                    jrel[n, s, i, cc] = acc


@numba.njit(cache=True, nogil=True)
def chain_normal_equations(rot, rel, jrel, w, e, hess, grad):
    """The Gauss-Newton terms of the chain fit (label_chains._normal_equations_numpy): per problem b
    the weighted Jacobian jw (k, 3, 6 + c) of the residuals R rel + t - target with respect to a
    rotation increment (-R [rel]x), the translation (I) and the chain's coordinates (R jrel), each
    row times w (b, k); hess (b, p, p) = sum over markers and axes of jw^T jw, grad (b, p) = jw^T e,
    accumulated marker by marker, axis by axis, as np.einsum does (which forms hess[p, q] and
    hess[q, p] from the same products: the upper triangle is computed and mirrored)."""
    b, k, _, c = jrel.shape
    npar = 6 + c
    sk = np.empty((3, 3))
    jw = np.empty((k, 3, npar))
    for n in range(b):
        for s in range(k):
            x, y, z = rel[n, s, 0], rel[n, s, 1], rel[n, s, 2]
            sk[0, 0], sk[0, 1], sk[0, 2] = 0.0, -z, y
            sk[1, 0], sk[1, 1], sk[1, 2] = z, 0.0, -x
            sk[2, 0], sk[2, 1], sk[2, 2] = -y, x, 0.0
            ws = w[n, s]
            for i in range(3):
                for col in range(3):
                    acc = 0.0
                    for j in range(3):
                        acc += rot[n, i, j] * sk[j, col]
                    jw[s, i, col] = -acc * ws
                for col in range(3):
                    jw[s, i, 3 + col] = (1.0 if i == col else 0.0) * ws
                for cc in range(c):
                    acc = 0.0
                    for j in range(3):
                        acc += rot[n, i, j] * jrel[n, s, j, cc]
                    jw[s, i, 6 + cc] = acc * ws
        for pp in range(npar):
            grad[n, pp] = 0.0
            for qq in range(npar):
                hess[n, pp, qq] = 0.0
        for s in range(k):
            for i in range(3):
                for pp in range(npar):
                    a = jw[s, i, pp]
                    grad[n, pp] += a * e[n, s, i]
                    for qq in range(pp, npar):  # the upper triangle: a * b is b * a, to the bit
                        hess[n, pp, qq] += a * jw[s, i, qq]
        for pp in range(npar):
            for qq in range(pp):
                hess[n, pp, qq] = hess[n, qq, pp]


# --------------------------------------------------------------------------------------------
# Partial label swaps (exubio.trust.label_ranges): RMS distance errors to the partner markers
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def partner_rms(P, ref, rows, cols, n_cols, own, out):
    """For every frame of P (n, k, 3) and every term t: the RMS over the partners cols[t, :n_cols[t]]
    of (|P[rows[t]] - P[partner]| - ref[own[t], partner]), missing values (NaN) left out (NaN where
    none is left), into out (n, T). The numpy reference (label_ranges._partner_rms_numpy):
    np.linalg.norm of the differences, then np.sqrt(np.nanmean(d ** 2)) over each term's partners,
    whose (frames, partners) array numpy lays out partner by partner and so sums in partner order;
    the same operations in the same order here."""
    n, k, _ = P.shape
    D = np.empty((k, k, n))  # frames last: the loops below run over the frames, side by side
    for a in range(k):
        for b in range(a + 1, k):
            row = D[a, b]
            for f in range(n):
                dx = P[f, a, 0] - P[f, b, 0]
                dy = P[f, a, 1] - P[f, b, 1]
                dz = P[f, a, 2] - P[f, b, 2]
                row[f] = np.sqrt(dx * dx + dy * dy + dz * dz)
            D[b, a, :] = row
    tot = np.empty(n)
    cnt = np.empty(n, dtype=np.int64)
    for t in range(rows.shape[0]):
        r, o = rows[t], own[t]
        for f in range(n):
            tot[f] = 0.0
            cnt[f] = 0
        for j in range(n_cols[t]):
            c = cols[t, j]
            ref_c = ref[o, c]
            row = D[r, c]
            for f in range(n):
                e = row[f] - ref_c
                e = e * e
                seen = not np.isnan(e)
                tot[f] += e if seen else 0.0
                cnt[f] += 1 if seen else 0
        for f in range(n):
            out[f, t] = np.sqrt(tot[f] / cnt[f]) if cnt[f] > 0 else np.nan


# --------------------------------------------------------------------------------------------
# Quadratic forms of the uncertainty (exubio.trust.observability, exubio.trust.angle_uncertainty)
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def quadratic_forms(D, S, out):
    """out[b, a] = sum_i sum_j D[b, a, i] S[b, i, j] D[b, a, j] (D (B, A, n), S (B, n, n)):
    np.einsum("bai,bij,baj->ba", D, S, D), each product formed left to right and the terms added
    in (i, j) order from 0, as einsum does; the rows a are summed side by side (independent sums,
    so the loop over them vectorises)."""
    B, A, n = D.shape
    Dt = np.empty((n, A))
    acc = np.empty(A)
    for b in range(B):
        for i in range(n):
            for a in range(A):
                Dt[i, a] = D[b, a, i]
        for a in range(A):
            acc[a] = 0.0
        for i in range(n):
            di = Dt[i]
            for j in range(n):
                s = S[b, i, j]
                dj = Dt[j]
                for a in range(A):
                    acc[a] += di[a] * s * dj[a]
        for a in range(A):
            out[b, a] = acc[a]


@numba.njit(cache=True, nogil=True)
def bilinear_blocks(X, S, Y, out):
    """out[b, i, x, j, y] = sum_k sum_l X[b, i, x, k] S[b, k, l] Y[b, j, y, l] (X (B, I, 3, p),
    S (B, p, q), Y (B, J, 3, q)): np.einsum("bixk,bkl,bjyl->bixjy", X, S, Y), each product formed
    left to right and the terms added in (k, l) order from 0, as einsum does."""
    B, I, d, p = X.shape
    J, e, q = Y.shape[1], Y.shape[2], Y.shape[3]
    for b in range(B):
        for i in range(I):
            for x in range(d):
                for j in range(J):
                    for y in range(e):
                        acc = 0.0
                        for k in range(p):
                            xk = X[b, i, x, k]
                            for l in range(q):
                                acc += xk * S[b, k, l] * Y[b, j, y, l]
                        out[b, i, x, j, y] = acc


# --------------------------------------------------------------------------------------------
# Pair distances (exubio.trust.label_distances)
# --------------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def pair_distance_series(pos, iu, ju, out):
    """out[c, f] = |pos[f, iu[c]] - pos[f, ju[c]]| (pos (n, k, 3), out (pairs, n)): one row per pair,
    its frames contiguous. np.linalg.norm(pos[:, iu] - pos[:, ju], axis=2): the squares added in
    axis order (x + y) + z, then the square root; NaN where either marker is missing."""
    n = pos.shape[0]
    for c in range(iu.shape[0]):
        a, b = iu[c], ju[c]
        row = out[c]
        for f in range(n):
            dx = pos[f, a, 0] - pos[f, b, 0]
            dy = pos[f, a, 1] - pos[f, b, 1]
            dz = pos[f, a, 2] - pos[f, b, 2]
            row[f] = np.sqrt(dx * dx + dy * dy + dz * dz)


# --------------------------------------------------------------------------------------------
# One live frame's causal targets (exubio.run.live.causal): the thorax frame, the markers in it and their
# backward differences, in one call instead of some twenty numpy calls on (k, 3) arrays. The same
# arithmetic in the same order as CausalTargets' Python path (which does the thorax frame with
# thorax_frame_into and the markers' transform term by term), bit for bit.
# --------------------------------------------------------------------------------------------
FRAME_OK = 0
FRAME_LANDMARK_MISSING = 1  # nothing written: the caller's Python path holds the landmark
FRAME_NO_THORAX = 2  # the landmarks are collinear: every marker missing in this frame


@numba.njit(cache=True, nogil=True)
def thorax_frame_into(L, R, o):
    """exubio.prep.thorax.thorax_frame of one frame's landmarks L (4, 3): IJ, PX, C7, T8, into R (3, 3)
    (local -> lab columns) and the origin o (3,) (IJ); False where they are coincident or collinear
    (thorax_frame's test), R and o then unset. The same formulas, scalar by scalar: the norms are
    summed in this order, so R may differ from thorax_frame's in the last bit."""
    a0, a1, a2 = L[0, 0], L[0, 1], L[0, 2]
    p0, p1, p2 = L[1, 0], L[1, 1], L[1, 2]
    c0, c1, c2 = L[2, 0], L[2, 1], L[2, 2]
    t0, t1, t2 = L[3, 0], L[3, 1], L[3, 2]
    u0, u1, u2 = 0.5 * (a0 + c0), 0.5 * (a1 + c1), 0.5 * (a2 + c2)  # IJ-C7 midpoint
    y0, y1, y2 = u0 - 0.5 * (p0 + t0), u1 - 0.5 * (p1 + t1), u2 - 0.5 * (p2 + t2)  # up, from the PX-T8 midpoint
    d0, d1, d2 = a0 - c0, a1 - c1, a2 - c2
    z0, z1, z2 = d1 * y2 - d2 * y1, d2 * y0 - d0 * y2, d0 * y1 - d1 * y0
    ny = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    nz = np.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
    scale = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) * ny
    if ny <= 1e-12 or nz <= 1e-9 * max(scale, 1e-300):
        return False
    y0, y1, y2, z0, z1, z2 = y0 / ny, y1 / ny, y2 / ny, z0 / nz, z1 / nz, z2 / nz
    x0, x1, x2 = y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0  # exactly orthonormal despite rounding
    R[0, 0], R[0, 1], R[0, 2] = x0, y0, z0
    R[1, 0], R[1, 1], R[1, 2] = x1, y1, z1
    R[2, 0], R[2, 1], R[2, 2] = x2, y2, z2
    o[0], o[1], o[2] = a0, a1, a2
    return True


@numba.njit(cache=True, nogil=True)
def causal_frame(raw, columns, thorax_columns, midpoints, mirror, dt, prev_p, prev_v, prev_present, prev_has_v,
                 p, v, a, present, cont, found):
    """One frame: raw (n_labels, 3) lab m; columns (k,) the raw column of each protocol marker (-1: none);
    thorax_columns: the landmarks' columns, (ij, px, c7, t8), or with ``midpoints`` (ij, ij-c7 midpoint,
    px-t8 midpoint), or empty (no thorax frame); the previous frame's p, v, present and has-velocity.
    Writes p, v, a (k, 3), present, cont (k,) and the landmarks' lab positions found (n_thorax, 3).
    Returns FRAME_OK, FRAME_LANDMARK_MISSING (nothing else written) or FRAME_NO_THORAX."""
    k = columns.shape[0]
    nt = thorax_columns.shape[0]
    for j in range(nt):
        c = thorax_columns[j]
        for i in range(3):
            x = raw[c, i]
            if not np.isfinite(x):
                return FRAME_LANDMARK_MISSING
            found[j, i] = x
    status = FRAME_OK
    R = np.zeros((3, 3))
    o = np.zeros(3)
    if nt:
        L = np.empty((4, 3))  # (IJ, PX, C7, T8)
        for i in range(3):
            L[0, i] = found[0, i]
            if midpoints:  # isb_landmarks: C7 = 2 mid_up - IJ, PX = T8 = mid_low
                L[1, i] = found[2, i]
                L[2, i] = 2.0 * found[1, i] - found[0, i]
                L[3, i] = found[2, i]
            else:
                L[1, i], L[2, i], L[3, i] = found[1, i], found[2, i], found[3, i]
        if not thorax_frame_into(L, R, o):
            status = FRAME_NO_THORAX
    for j in range(k):
        col = columns[j]
        ok = status == FRAME_OK and col >= 0
        if ok:
            for i in range(3):
                if not np.isfinite(raw[col, i]):
                    ok = False
        present[j] = ok
        if not ok:
            for i in range(3):
                p[j, i] = np.nan
        elif nt:
            e0, e1, e2 = raw[col, 0] - o[0], raw[col, 1] - o[1], raw[col, 2] - o[2]
            for i in range(3):
                p[j, i] = e0 * R[0, i] + e1 * R[1, i] + e2 * R[2, i]
        else:
            for i in range(3):
                p[j, i] = raw[col, i]
        if ok and mirror:
            p[j, 2] = p[j, 2] * -1.0
        cont[j] = ok and prev_present[j]
        acc = cont[j] and prev_has_v[j]
        for i in range(3):
            v[j, i] = (p[j, i] - prev_p[j, i]) / dt if cont[j] else 0.0
            a[j, i] = (v[j, i] - prev_v[j, i]) / dt if acc else 0.0
    return status
