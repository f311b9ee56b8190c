"""The constrained pose of every frame from its markers, and its consistent rates: the solve that
the LS method (exubio.methods.ls), PF's start (exubio.methods.pf.initial_state) and the calibration
share.

Per frame: minimise sum_i w_i |r_Ri(q) - r_Mi|^2 (+ the joint-range potential, exubio.model.ranges)
subject to the two ellipsoid constraints g(q) = 0, with markers missing in that frame left out of
the sum. Solver: Gauss-Newton SQP on the KKT system [J^T W J + mu I, G^T; G, 0] [dq; lambda] =
[-J^T W e; -g] with the analytic Jacobians of exubio.model.kinematics, on the batched core of exubio.methods.lsq;
its fixed points satisfy the first-order optimality conditions exactly. A step is kept only if it
lowers the l1 merit function (cost + rho |g|_1); otherwise the Levenberg-Marquardt damping mu
grows, which keeps large-residual frames (a generic model on a real subject) convergent.

Frames are solved in short blocks that run through numpy together: every frame of a block starts
from the previous block's last solution (the warm start; blocks are ``block_s`` = 0.2 s long) and
iterates until its step is below ``tol_rad`` or its merit no longer decreases; its stop reason
says why it stopped (exubio.types.StopReason).

Velocities and accelerations are the consistent linearisations: J q̇ = ṙ_M with G q̇ = 0, and
J q̈ = r̈_M - J̇ q̇ with G q̈ = -eta (weighted least squares with the same weights).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.methods.lsq import Evaluation, Settings, fix_variables, levenberg_marquardt
from exubio.types import StopReason
from exubio.methods.constraints import project_on_constraints
from exubio.model.ranges import DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD, penalty_weight, violation
from exubio.types import Model, Protocol

log = logging.getLogger(__name__)

RATES_REGULARISATION = 1e-10  # mu of the linear q̇/q̈ solves: only guards unobservable coordinates
MIN_MARKERS = 5  # fewer markers than this in a frame: the 11-DOF pose is not determined


@dataclass(frozen=True)
class LSOptions:
    tol_rad: float = 1e-8  # convergence: largest coordinate step (rad)
    max_iterations: int = 100  # per frame (the first frame gets 10x per start posture)
    block_s: float = 0.2  # frames solved together: about this much time
    max_step_rad: float = 0.3  # step cap, for robustness far from the solution
    regularisation: float = 1e-6  # mu (m^2/rad^2): damps steps in weakly observed directions and
    # keeps unobservable coordinates where they were; it does not move the converged optimum
    limit_stiffness_nm_per_rad: float | None = DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD  # k_lim of the
    # joint ranges (exubio.model.ranges); None or 0: no ranges in the solve


@dataclass(frozen=True)
class Limits:
    """The joint ranges inside the solve: cost + kappa sum_j v_j(q)^2 with v_j the excursion beyond
    the range (exubio.model.ranges; kappa = k_lim / c_default, the same potential as PF's limits)."""

    ranges_rad: np.ndarray  # (m, 2)
    kappa: float  # m^2/rad^2

    @classmethod
    def of(cls, model: Model, protocol: Protocol, limit_stiffness_nm_per_rad: float | None) -> "Limits | None":
        if limit_stiffness_nm_per_rad is None or limit_stiffness_nm_per_rad <= 0:
            return None
        rng = model.coordinate_ranges_rad
        if not np.isfinite(rng).any():
            return None
        return cls(rng, penalty_weight(limit_stiffness_nm_per_rad, protocol.default_stiffness_n_per_m))


def _add_limits(lin: Evaluation, q: np.ndarray, limits: Limits | None) -> None:
    """Add the one-sided limit potential to cost, gradient and Gauss-Newton matrix (in place)."""
    if limits is None:
        return
    v = violation(q, limits.ranges_rad)
    if not v.any():
        return
    lin.cost += limits.kappa * (v * v).sum(axis=-1)
    lin.grad += limits.kappa * v
    lin.H += limits.kappa * (v != 0)[..., :, None] * np.eye(q.shape[-1])


def _linearise(kin: Kinematics, points: PointSet, q: np.ndarray, target: np.ndarray, w: np.ndarray,
               limits: Limits | None = None) -> Evaluation:
    """Everything one kinematics evaluation gives at q for a batch of frames (B, ...): the cost
    e^T W e (B,) (m^2, plus the limit potential), H = J^T W J (B, m, m), grad = J^T W e (B, m), the
    constraints g (B, 2) and G (B, 2, m)."""
    from exubio.model.pose_kernel import least_squares_terms  # compiled (numba): imported where used

    cost, H, grad, g, G = least_squares_terms(kin, points, q, target, w)
    lin = Evaluation(cost=cost, H=H, grad=grad, g=g, G=G)
    _add_limits(lin, q, limits)
    return lin


def _settings(options: LSOptions, max_iterations: int) -> Settings:
    """The LS solve in terms of the core: damping from ``regularisation`` (also its floor), tenfold
    up and threefold down, given up beyond 1e8; a step is kept if the merit does not grow by more
    than rounding (1e-12 relative), and a kept step that lowers it by no more than that stalls."""
    return Settings(max_iterations=max_iterations, step_tol=options.tol_rad, damping=options.regularisation,
                    damping_floor=options.regularisation, step_cap=options.max_step_rad, damping_decrease=3.0,
                    damping_increase=10.0, damping_cap=1e8, accept_rtol=1e-12, accept_atol=1e-18, stall_rtol=1e-12)


def _start_postures(kin: Kinematics, q_start: np.ndarray) -> np.ndarray:
    """q_start and the same with the humerus abducted or flexed by 45 and 90 degrees."""
    names = kin.model.coordinate_names
    out = [np.asarray(q_start, dtype=float)]
    for name in ("gh_abduction", "gh_flexion"):
        if name in names:
            for angle in (np.pi / 4, np.pi / 2):
                q = out[0].copy()
                q[names.index(name)] += angle
                out.append(q)
    return np.array(out)


def solve_positions(kin: Kinematics, points: PointSet, targets_m: np.ndarray, weights: np.ndarray, /, *,
                    q_start: np.ndarray, options: LSOptions, frame_dt: float,
                    progress: Callable[[int], None] | None = None, held: np.ndarray | None = None,
                    limits: Limits | None = None, q_previous: np.ndarray | None = None):
    """q (n, m) per frame, iterations (n,), converged (n,) bool, stop reasons (n,) int8
    (exubio.types.StopReason codes; converged = CONVERGED or STALLED). The first frame is solved from
    several start postures around ``q_start`` (its stop reason is the best start's); with
    ``q_previous`` (the solution of the frame before these, when a trial is solved in chunks) every
    frame is warm-started like the frames after the first, so that chunks starting at 1 + a
    multiple of the block give the one-pass result."""
    n = targets_m.shape[0]
    m = kin.n_coordinates
    present = ~np.isnan(targets_m).any(axis=2)
    w_all = np.where(present, weights[None, :], 0.0)
    tgt_all = np.where(present[..., None], targets_m, 0.0)
    q_out = np.zeros((n, m))
    iters = np.zeros(n, dtype=int)
    converged = np.zeros(n, dtype=bool)
    reasons = np.full(n, StopReason.MAX_ITERATIONS, dtype=np.int8)
    block = max(1, int(round(options.block_s / frame_dt)))

    def run(idx: slice | np.ndarray, q0: np.ndarray, max_it: int):
        """Levenberg-Marquardt-safeguarded SQP on the frames ``idx`` from q0 (exubio.methods.lsq): a step
        is kept only if it lowers the l1 merit cost + rho |g|_1 (rho above the multipliers);
        otherwise the damping grows tenfold. Returns q, iterations, converged, stop reasons."""
        tgt, w = tgt_all[idx], w_all[idx]
        res = levenberg_marquardt(q0, lambda q, rows: _linearise(kin, points, q, tgt[rows], w[rows], limits),
                                  settings=_settings(options, max_it), fixed=held)
        return res.x, res.iterations, res.converged, res.reason

    if q_previous is not None:
        prev, start = np.asarray(q_previous, dtype=float), 0
    else:  # first frame: several start postures (arm down, abducted, flexed), many iterations, best kept
        starts = _start_postures(kin, q_start)
        q0, it0, ok0, why0 = run(np.zeros(len(starts), dtype=int), starts, options.max_iterations * 10)
        cost0 = np.array([_linearise(kin, points, q0[i:i + 1], tgt_all[:1], w_all[:1], limits).cost[0]
                          for i in range(len(starts))])
        best = int(np.argmin(np.where(ok0, cost0, cost0 + 1e9)))
        q_out[0], iters[0], converged[0], reasons[0] = q0[best], it0.sum(), ok0[best], why0[best]
        prev = q_out[0]
        start = 1
        if progress:
            progress(1)
    while start < n:
        stop = min(n, start + block)
        guess = np.repeat(prev[None], stop - start, axis=0)  # warm start: the previous solution
        q_blk, it_blk, ok_blk, why_blk = run(slice(start, stop), guess, options.max_iterations)
        q_out[start:stop], iters[start:stop], converged[start:stop], reasons[start:stop] = q_blk, it_blk, ok_blk, why_blk
        prev = q_out[stop - 1]
        if progress:
            progress(stop - start)
        start = stop
    # every returned frame satisfies the constraints, also where the optimisation stopped early
    q_out = project_on_constraints(kin, q_out, held=held, max_iterations=10)[0]
    return q_out, iters, converged, reasons



RATES_BLOCK_FRAMES = 4096
"""solve_rates works through the frames in blocks of this many (each frame is independent): the
per-frame Jacobians and KKT matrices of a whole 20-minute trial would take ~12 GB at once."""


def solve_rates(kin: Kinematics, points: PointSet, q: np.ndarray, vel: np.ndarray, acc: np.ndarray,
                weights: np.ndarray, mu: float, held: np.ndarray | None = None, limits: Limits | None = None):
    """Consistent q̇, q̈ (n, m) from marker velocities/accelerations (weighted LS + constraints);
    a coordinate beyond its limit adds the limit potential's stiffness kappa to its diagonal (the
    time derivative of the optimality conditions). Frames in blocks of RATES_BLOCK_FRAMES."""
    n = q.shape[0]
    if n > RATES_BLOCK_FRAMES:
        qd, qdd = np.empty_like(q), np.empty_like(q)
        for a in range(0, n, RATES_BLOCK_FRAMES):
            b = min(a + RATES_BLOCK_FRAMES, n)
            qd[a:b], qdd[a:b] = _solve_rates_block(kin, points, q[a:b], vel[a:b], acc[a:b], weights, mu, held, limits)
        return qd, qdd
    return _solve_rates_block(kin, points, q, vel, acc, weights, mu, held, limits)


def _solve_rates_block(kin: Kinematics, points: PointSet, q: np.ndarray, vel: np.ndarray, acc: np.ndarray,
                       weights: np.ndarray, mu: float, held: np.ndarray | None, limits: Limits | None):
    n, m = q.shape
    present = ~np.isnan(vel).any(axis=2) & ~np.isnan(acc).any(axis=2)
    w = np.where(present, weights[None, :], 0.0)
    fr = kin.frames(q)  # once for every kinematic term of the block
    J = kin.point_jacobian(q, points, frames=fr)
    Jw = J * w[..., None, None]
    K = np.zeros((n, m + 2, m + 2))
    K[:, :m, :m] = np.swapaxes(Jw.reshape(n, -1, m), 1, 2) @ J.reshape(n, -1, m) + mu * np.eye(m)
    if limits is not None:
        K[:, :m, :m] += limits.kappa * (violation(q, limits.ranges_rad) != 0)[..., :, None] * np.eye(m)
    G = kin.G(q, frames=fr)
    K[:, :m, m:] = np.swapaxes(G, 1, 2)
    K[:, m:, :m] = G
    v = np.where(present[..., None], vel, 0.0)
    rhs = np.concatenate([(v.reshape(n, 1, -1) @ Jw.reshape(n, -1, m))[:, 0], np.zeros((n, 2))], axis=1)
    fix_variables(K, rhs, held)
    qd = np.linalg.solve(K, rhs[..., None])[..., 0][:, :m]
    bias = kin.point_bias_acceleration(q, qd, points, frames=fr, jacobian=J)
    a = np.where(present[..., None], acc - bias, 0.0)
    rhs = np.concatenate([(a.reshape(n, 1, -1) @ Jw.reshape(n, -1, m))[:, 0], -kin.eta(q, qd, frames=fr)], axis=1)
    fix_variables(K, rhs, held)
    qdd = np.linalg.solve(K, rhs[..., None])[..., 0][:, :m]
    return qd, qdd
