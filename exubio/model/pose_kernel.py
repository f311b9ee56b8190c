"""The terms of the weighted marker least-squares problem at a batch of poses, compiled: what one
Gauss-Newton iteration of the LS method needs (exubio.methods.poses), from one forward-kinematics
pass per frame.

For q (B, m), measured marker positions (B, k, 3) (m) and weights (B, k) (0 where a marker is
missing):

    cost = sum_i w_i |r_i(q) - r_Mi|^2 (m^2), H = J^T W J, grad = J^T W e,
    g_j = e_j^T A e_j - 1 and G = dg/dq for the two ellipsoid contact points (paper Eq. 1-2).

``least_squares_terms`` runs a numba kernel (compiled on first use, cached on disk: ``cache=True``),
one frame at a time in plain loops: a frame costs about 2 us instead of some 10 us of numpy calls
on small arrays. ``least_squares_terms_numpy`` is the same arithmetic in numpy on the batch (the
reference: tests/model/test_pose_kernel.py holds the two equal to 1e-12 on random poses). The
two differ by round-off only (other summation orders). This module imports numba (about 0.2 s):
import it where it is used (exubio.methods.poses does, inside the function), not at the top of a
module that every command loads.
"""
from __future__ import annotations

import numba
import numpy as np

from exubio.errors import ModelError
from exubio.model.kinematics import Kinematics, PointSet


def least_squares_terms_numpy(kin: Kinematics, points: PointSet, q: np.ndarray, target: np.ndarray,
                              w: np.ndarray):
    """(cost (B,), H (B, m, m), grad (B, m), g (B, 2), G (B, 2, m)) in numpy: the reference."""
    fr = kin.frames(q)
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
    tables = _tables(kin, points)
    q = np.ascontiguousarray(q, dtype=float)
    B, m = q.shape
    cost, H, grad = np.empty(B), np.empty((B, m, m)), np.empty((B, m))
    g, G = np.empty((B, 2)), np.empty((B, 2, m))
    _terms_loops(q, np.ascontiguousarray(target, dtype=float), np.ascontiguousarray(w, dtype=float), *tables,
              cost, H, grad, g, G)
    return cost, H, grad, g, G


def _tables(kin: Kinematics, points: PointSet) -> tuple[np.ndarray, ...]:
    """The kinematic structure as flat arrays for the kernel, built once per (Kinematics, points)."""
    cache = kin.__dict__.setdefault("_pose_kernel_tables", {})
    key = (points.segment_index.tobytes(), points.local_m.tobytes())
    t = cache.get(key)
    if t is None:
        model = kin.model
        n_seg = kin.n_segments
        parent = np.asarray(kin.parent_index, dtype=np.int64)
        if any(seg.joint is None for seg in model.segments[1:]) or any(parent[s] >= s for s in range(1, n_seg)):
            raise ModelError(f"{model.source}: the compiled pose kernel needs every segment but the root jointed "
                             "and listed after its parent")
        centre = np.zeros((n_seg, 3))
        first, count = np.zeros(n_seg, dtype=np.int64), np.zeros(n_seg, dtype=np.int64)
        axes = np.zeros((kin.n_coordinates, 3))
        for s in range(1, n_seg):
            joint = model.segments[s].joint
            idx = kin.joint_coordinate_indices(s)
            if np.any(np.diff(idx) != 1):
                raise ModelError(f"{model.source}: joint '{joint.name}': its coordinates must be consecutive")
            centre[s] = joint.centre_m
            first[s], count[s] = idx[0], len(idx)
            axes[idx] = np.asarray(joint.axes, dtype=float).reshape(-1, 3)
        t = (parent, centre, first, count, axes, kin._sk.copy(), kin._sk2.copy(), kin.affects.astype(np.bool_),
             np.asarray(points.segment_index, dtype=np.int64), np.ascontiguousarray(points.local_m, dtype=float),
             np.asarray(kin.contacts.segment_index, dtype=np.int64),
             np.ascontiguousarray(kin.contacts.local_m, dtype=float), np.asarray(kin.a_diag, dtype=float),
             np.asarray(kin.centre, dtype=float))
        cache[key] = t
    return t


@numba.njit(cache=True, nogil=True)
def _terms_loops(q, target, w, parent, centre, first, count, axes, sk, sk2, affects, pt_seg, pt_local,
                 c_seg, c_local, a_diag, ell_centre, cost, H, grad, g, G):
    """The kernel in plain loops (compiled): forward kinematics, then each point's
    residual and Jacobian columns a_j x (r - c_j), accumulated into H (upper triangle, mirrored),
    grad and cost; then the two contact points' g and G."""
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
        for i in range(3):
            for j in range(3):
                R[0, i, j] = 1.0 if i == j else 0.0
            p[0, i] = 0.0
        for s in range(1, n_seg):
            par = parent[s]
            for i in range(3):
                p[s, i] = p[par, i] + R[par, i, 0] * centre[s, 0] + R[par, i, 1] * centre[s, 1] + R[par, i, 2] * centre[s, 2]
                for j in range(3):
                    Rc[i, j] = R[par, i, j]
            for c in range(first[s], first[s] + count[s]):
                for i in range(3):
                    ax[c, i] = Rc[i, 0] * axes[c, 0] + Rc[i, 1] * axes[c, 1] + Rc[i, 2] * axes[c, 2]
                    piv[c, i] = p[s, i]
                sq = np.sin(q[b, c])
                cq = 1.0 - np.cos(q[b, c])
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
