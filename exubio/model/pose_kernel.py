"""The terms of the weighted marker least-squares problem at a batch of poses: what one
Gauss-Newton iteration of the LS method needs (exubio.methods.poses), from one forward-kinematics
pass per frame.

For q (B, m), measured marker positions (B, k, 3) (m) and weights (B, k) (0 where a marker is
missing):

    cost = sum_i w_i |r_i(q) - r_Mi|^2 (m^2), H = J^T W J, grad = J^T W e,
    g_j = e_j^T A e_j - 1 and G = dg/dq for the two ellipsoid contact points (paper Eq. 1-2).

``least_squares_terms`` runs the compiled kernel (exubio.model.kernels.least_squares): a frame
costs about 2 us instead of some 10 us of numpy calls on small arrays.
``least_squares_terms_numpy`` is the same arithmetic in numpy on the batch (the reference:
tests/model/test_pose_kernel.py holds the two equal to 1e-12 on random poses); the two differ by
round-off only (other summation orders). Import this module where it is used: it imports numba.
"""
from __future__ import annotations

import numpy as np

from exubio.model import kernels
from exubio.model.kinematics import Kinematics, PointSet


def least_squares_terms_numpy(kin: Kinematics, points: PointSet, q: np.ndarray, target: np.ndarray,
                              w: np.ndarray):
    """(cost (B,), H (B, m, m), grad (B, m), g (B, 2), G (B, 2, m)) in numpy: the reference."""
    fr = kin.frames_numpy(q)
    B, k = w.shape
    r = kin.points(q, points, frames=fr)
    J = kin.point_jacobian(q, points, frames=fr, positions=r).reshape(B, 3 * k, -1)  # (B, 3k, m)
    e = np.where(w[..., None] > 0, r - target, 0.0).reshape(B, 3 * k, 1)
    Jw_t = np.swapaxes(J * np.repeat(w, 3, axis=1)[..., None], 1, 2)  # (B, m, 3k)
    rc = kin.points(q, kin.contacts, frames=fr)
    Jc = kin.point_jacobian(q, kin.contacts, frames=fr, positions=rc)  # (B, 2, 3, m)
    ec = rc - kin.centre
    return ((e[..., 0] ** 2 * np.repeat(w, 3, axis=1)).sum(axis=1), Jw_t @ J, (Jw_t @ e)[..., 0],
            (ec * ec) @ kin.a_diag - 1.0, 2.0 * ((ec * kin.a_diag)[..., None, :] @ Jc)[..., 0, :])


def least_squares_terms(kin: Kinematics, points: PointSet, q: np.ndarray, target: np.ndarray, w: np.ndarray):
    """(cost (B,), H (B, m, m), grad (B, m), g (B, 2), G (B, 2, m)), compiled (see the module)."""
    q = np.ascontiguousarray(q, dtype=float)
    B, m = q.shape
    cost, H, grad = np.empty(B), np.empty((B, m, m)), np.empty((B, m))
    g, G = np.empty((B, 2)), np.empty((B, 2, m))
    kernels.least_squares(q, np.ascontiguousarray(target, dtype=float), np.ascontiguousarray(w, dtype=float),
                          *kin.kernel_tables(), *_point_tables(kin, points), cost, H, grad, g, G)
    return cost, H, grad, g, G


def _point_tables(kin: Kinematics, points: PointSet) -> tuple[np.ndarray, ...]:
    """The points' and the ellipsoid's arrays for the kernel, built once per (Kinematics, points)."""
    cache = kin.__dict__.setdefault("_pose_kernel_tables", {})
    key = (points.segment_index.tobytes(), points.local_m.tobytes())
    t = cache.get(key)
    if t is None:
        t = cache[key] = (
            kin.affects.astype(np.bool_), np.asarray(points.segment_index, dtype=np.int64),
            np.ascontiguousarray(points.local_m, dtype=float), np.asarray(kin.contacts.segment_index, dtype=np.int64),
            np.ascontiguousarray(kin.contacts.local_m, dtype=float), np.asarray(kin.a_diag, dtype=float),
            np.asarray(kin.centre, dtype=float))
    return t
