"""A compiled (numba) kernel of one causal frame without a filter (exubio.run.live.causal): the
protocol markers of a raw lab frame in the thorax frame and their backward-difference rates, in one
call instead of some twenty numpy calls on (k, 3) arrays (about 8 % of a live frame's CPU before,
benchmarks/README.md). The same formulas as ``CausalTargets.thorax_positions`` and ``CausalTargets.push``
(the thorax frame is ``thorax_frame_into`` in both: ``thorax_frame_one`` calls it); tests hold the two
paths equal (1e-12). A frame whose
thorax landmarks are not all finite is left to the Python path (it holds a missing landmark at its
last value). Importing this module imports numba: import it where it is used.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["causal_frame", "thorax_frame_into", "FRAME_OK", "FRAME_LANDMARK_MISSING", "FRAME_NO_THORAX"]

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
    ny = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    nz = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
    scale = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) * ny
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
            if not math.isfinite(x):
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
                if not math.isfinite(raw[col, i]):
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
