"""Constrained least-squares (LS) reconstruction, the paper's reference method (Eq. 9).

Per frame: minimise sum_i w_i |r_Ri(q) - r_Mi|^2 subject to the two ellipsoid constraints
g(q) = 0, with markers missing in that frame left out of the sum. Solver: Gauss-Newton SQP on the
KKT system [J^T W J + mu I, G^T; G, 0] [dq; lambda] = [-J^T W e; -g] with the analytic Jacobians
of exubio.kinematics; its fixed points satisfy the first-order optimality conditions exactly.

Frames are solved in short blocks that run through numpy together: every frame of a block starts
from the previous block's last solution (the warm start; blocks are ``block_s`` = 0.2 s long) and
iterates until its step is below ``tol_rad``; its status says whether it converged.

Velocities and accelerations are the consistent linearisations: J q̇ = ṙ_M with G q̇ = 0, and
J q̈ = r̈_M - J̇ q̇ with G q̈ = -eta (weighted least squares with the same weights).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from exubio.kinematics import Kinematics, PointSet
from exubio.methods.common import assemble, tracked_points
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Reconstruction

log = logging.getLogger(__name__)

RATES_REGULARISATION = 1e-10  # mu of the linear q̇/q̈ solves: only guards unobservable coordinates
MIN_MARKERS = 5  # fewer markers than this in a frame: the 11-DOF pose is not determined


@dataclass(frozen=True)
class LSOptions:
    tol_rad: float = 1e-8  # convergence: largest coordinate step (rad)
    max_iterations: int = 30  # per frame (the first frame gets 10x)
    block_s: float = 0.2  # frames solved together: about this much time
    max_step_rad: float = 0.3  # step cap, for robustness far from the solution
    regularisation: float = 1e-6  # mu (m^2/rad^2): damps steps in weakly observed directions and
    # keeps unobservable coordinates where they were; it does not move the converged optimum


def _solve_kkt(kin: Kinematics, points: PointSet, q: np.ndarray, target: np.ndarray, w: np.ndarray, mu: float):
    """One Gauss-Newton SQP step for a batch (B, m); returns dq (B, m) and weighted cost (B,)."""
    fr = kin.frames(q)
    r = kin.points(q, points, frames=fr)
    J = kin.point_jacobian(q, points, frames=fr, positions=r)  # (B, k, 3, m)
    e = np.where(w[..., None] > 0, r - target, 0.0)  # (B, k, 3)
    Jw = J * w[..., None, None]
    H = np.einsum("bkcm,bkcn->bmn", Jw, J)
    grad = np.einsum("bkcm,bkc->bm", Jw, e)
    rc = kin.points(q, kin.contacts, frames=fr)
    Jc = kin.point_jacobian(q, kin.contacts, frames=fr, positions=rc)
    ec = rc - kin.centre
    G = 2.0 * np.einsum("bkc,bkcm->bkm", ec * kin.a_diag, Jc)
    g = np.einsum("bkc,c->bk", ec * ec, kin.a_diag) - 1.0
    m = q.shape[1]
    K = np.zeros((q.shape[0], m + 2, m + 2))
    K[:, :m, :m] = H + mu * np.eye(m)
    K[:, :m, m:] = np.swapaxes(G, 1, 2)
    K[:, m:, :m] = G
    rhs = np.concatenate([-grad, -g], axis=1)
    sol = np.linalg.solve(K, rhs[..., None])[..., 0]
    cost = np.einsum("bk,bkc->b", w, e * e)
    return sol[:, :m], cost


def solve_positions(kin: Kinematics, points: PointSet, targets_m: np.ndarray, weights: np.ndarray, /, *,
                    q_start: np.ndarray, options: LSOptions, frame_dt: float,
                    progress: Callable[[int], None] | None = None):
    """q (n, m) per frame, iterations (n,), converged (n,) bool."""
    n = targets_m.shape[0]
    m = kin.n_coordinates
    present = ~np.isnan(targets_m).any(axis=2)
    w_all = np.where(present, weights[None, :], 0.0)
    tgt_all = np.where(present[..., None], targets_m, 0.0)
    q_out = np.zeros((n, m))
    iters = np.zeros(n, dtype=int)
    converged = np.zeros(n, dtype=bool)
    block = max(1, int(round(options.block_s / frame_dt)))

    def run(idx: slice, q0: np.ndarray, max_it: int):
        q = q0.copy()
        active = np.ones(q.shape[0], dtype=bool)
        it = np.zeros(q.shape[0], dtype=int)
        for _ in range(max_it):
            a = np.flatnonzero(active)
            if a.size == 0:
                break
            dq, _ = _solve_kkt(kin, points, q[a], tgt_all[idx][a], w_all[idx][a], options.regularisation)
            big = np.abs(dq).max(axis=1, keepdims=True)
            dq = np.where(big > options.max_step_rad, dq * (options.max_step_rad / np.maximum(big, 1e-300)), dq)
            q[a] += dq
            it[a] += 1
            active[a] = np.abs(dq).max(axis=1) > options.tol_rad
        return q, it, ~active

    # first frame: from the start posture, many iterations
    q0, it0, ok0 = run(slice(0, 1), q_start[None, :], options.max_iterations * 10)
    q_out[0], iters[0], converged[0] = q0[0], it0[0], ok0[0]
    prev = q_out[0]
    start = 1
    if progress:
        progress(1)
    while start < n:
        stop = min(n, start + block)
        guess = np.repeat(prev[None], stop - start, axis=0)  # warm start: the previous solution
        q_blk, it_blk, ok_blk = run(slice(start, stop), guess, options.max_iterations)
        q_out[start:stop], iters[start:stop], converged[start:stop] = q_blk, it_blk, ok_blk
        prev = q_out[stop - 1]
        if progress:
            progress(stop - start)
        start = stop
    return q_out, iters, converged


def solve_rates(kin: Kinematics, points: PointSet, q: np.ndarray, vel: np.ndarray, acc: np.ndarray,
                weights: np.ndarray, mu: float):
    """Consistent q̇, q̈ (n, m) from marker velocities/accelerations (weighted LS + constraints)."""
    n, m = q.shape
    present = ~np.isnan(vel).any(axis=2) & ~np.isnan(acc).any(axis=2)
    w = np.where(present, weights[None, :], 0.0)
    J = kin.point_jacobian(q, points)
    Jw = J * w[..., None, None]
    K = np.zeros((n, m + 2, m + 2))
    K[:, :m, :m] = np.einsum("nkcm,nkcl->nml", Jw, J) + mu * np.eye(m)
    G = kin.G(q)
    K[:, :m, m:] = np.swapaxes(G, 1, 2)
    K[:, m:, :m] = G
    v = np.where(present[..., None], vel, 0.0)
    rhs = np.concatenate([np.einsum("nkcm,nkc->nm", Jw, v), np.zeros((n, 2))], axis=1)
    qd = np.linalg.solve(K, rhs[..., None])[..., 0, ][:, :m]
    bias = kin.point_bias_acceleration(q, qd, points)
    a = np.where(present[..., None], acc - bias, 0.0)
    rhs = np.concatenate([np.einsum("nkcm,nkc->nm", Jw, a), -kin.eta(q, qd)], axis=1)
    qdd = np.linalg.solve(K, rhs[..., None])[..., 0][:, :m]
    return qd, qdd


def reconstruct_ls(model: Model, protocol: Protocol, targets: MarkerTargets, /, *,
                   options: LSOptions = LSOptions(), q_start: np.ndarray | None = None,
                   progress: Callable[[int], None] | None = None) -> Reconstruction:
    """Reconstruct a trial with the constrained least-squares method."""
    t0 = time.perf_counter()
    kin = Kinematics(model)
    points = tracked_points(kin, protocol)
    weights = protocol.weights
    dt = float(np.median(np.diff(targets.time_s))) if targets.n_frames > 1 else 1.0
    q0 = np.zeros(kin.n_coordinates) if q_start is None else np.asarray(q_start, dtype=float)
    t1 = time.perf_counter()
    q, iters, converged = solve_positions(kin, points, targets.positions_m, weights, q_start=q0,
                                          options=options, frame_dt=dt, progress=progress)
    t2 = time.perf_counter()
    qd, qdd = solve_rates(kin, points, q, targets.velocities_m_s, targets.accelerations_m_s2, weights,
                          RATES_REGULARISATION)
    t3 = time.perf_counter()
    n_present = targets.present.sum(axis=1)
    status = np.where(converged, FrameStatus.CONVERGED, FrameStatus.NOT_CONVERGED)
    status = np.where(n_present < MIN_MARKERS, FrameStatus.TOO_FEW_MARKERS, status)
    if (~converged).any():
        log.warning("LS: %d of %d frames did not converge", int((~converged).sum()), len(converged))
    timings = {"setup": t1 - t0, "positions": t2 - t1, "rates": t3 - t2, "total": t3 - t0}
    info = {"iterations_mean": float(iters.mean()), "iterations_max": int(iters.max()),
            "frames_not_converged": int((~converged).sum()), "options": options.__dict__}
    return assemble(kin, points, targets, method="ls", q=q, qd=qd, qdd=qdd, status=status,
                    timings_s=timings, info=info)
