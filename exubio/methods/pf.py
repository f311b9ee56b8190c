"""Potential-field (PF) reconstruction (paper Eq. 4-7) on Exudyn.

Every protocol marker pulls its segment-fixed model point through a linear spring-damper
(c_i, d_i from the protocol); the arm's equations of motion with the two ellipsoid constraints
are integrated forward in time by Exudyn's implicit generalized-alpha solver (index 3), so q, q̇
and q̈ come out of one consistent trajectory and satisfy the constraints at every level.

Initial state (the paper: "static equilibrium ... unstrained springs at time zero"): the springs
have zero rest length, so their static equilibrium at the first frame is the minimum of
sum_i c_i |R_i - M_i|^2 subject to g = 0, i.e. the weighted LS solution of that frame. The run
starts there, with the consistent velocity (J q̇ = ṙ_M, G q̇ = 0), so the net spring force is zero
at t = 0 and there is no start-up transient. Gravity is off by default: with it on, the springs
must also carry the limb's weight and every model point sags below its marker (about 1-2 mm
and 1° on the synthetic trials; see the README).

A marker missing in a frame switches its spring off for that stretch (reported as a gap). A run
whose solver stops, or whose spring deflections grow beyond ``divergence_deflection_m``, raises a
ReconstructionError naming the time and the worst marker.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from exubio.backend.exudyn_system import IntegratorOptions, PFSystem, SpringSet
from exubio.errors import ReconstructionError
from exubio.kinematics import Kinematics
from exubio.methods.common import assemble, tracked_points
from exubio.methods.ls import RATES_REGULARISATION, LSOptions, solve_positions, solve_rates
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Reconstruction

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PFOptions:
    step_s: float | None = None  # integration step; None = one step per input frame
    spectral_radius: float = 0.0  # generalized-alpha numerical damping (0 = most damping)
    newton_relative_tolerance: float = 1e-5
    modified_newton: bool = True
    gravity: bool = False
    divergence_deflection_m: float = 0.25  # a spring longer than this means the run diverged
    timing_breakdown: bool = True


def initial_state(kin: Kinematics, points, targets: MarkerTargets, stiffness: np.ndarray, /):
    """Static equilibrium of the springs at the first frame with its consistent velocity."""
    first = 0
    present = targets.present
    weights = stiffness / stiffness.mean()
    q0, _, ok = solve_positions(kin, points, targets.positions_m[first:first + 1], weights,
                                q_start=np.zeros(kin.n_coordinates), options=LSOptions(tol_rad=1e-12, max_iterations=60),
                                frame_dt=1.0)
    if not ok[0]:
        raise ReconstructionError(
            f"{targets.source or 'trial'}: no static equilibrium at t = {targets.time_s[0]:.3f} s "
            f"(markers present: {int(present[0].sum())} of {present.shape[1]})")
    qd0, _ = solve_rates(kin, points, q0, targets.velocities_m_s[:1], targets.accelerations_m_s2[:1], weights,
                         RATES_REGULARISATION)
    return q0[0], qd0[0]


def reconstruct_pf(model: Model, protocol: Protocol, targets: MarkerTargets, /, *,
                   options: PFOptions = PFOptions(),
                   progress: Callable[[int], None] | None = None) -> Reconstruction:
    """Reconstruct a trial with the potential-field method."""
    t0 = time.perf_counter()
    if targets.n_frames < 2:
        raise ReconstructionError(f"{targets.source or 'trial'}: the PF method needs at least 2 frames")
    dt = float(np.median(np.diff(targets.time_s)))
    if np.abs(np.diff(targets.time_s) - dt).max() > 1e-6 * dt:
        raise ReconstructionError(f"{targets.source or 'trial'}: frames are not evenly spaced in time")
    kin = Kinematics(model)
    points = tracked_points(kin, protocol)
    stiffness = np.array([m.stiffness_n_per_m for m in protocol.markers])
    damping = np.array([m.damping_ns_per_m for m in protocol.markers])
    q0, qd0 = initial_state(kin, points, targets, stiffness)
    t1 = time.perf_counter()
    springs = SpringSet.from_points(points, stiffness_n_per_m=stiffness, damping_ns_per_m=damping)
    system = PFSystem(model, springs, q0=q0, qd0=qd0, gravity=options.gravity, kinematics=kin)
    t2 = time.perf_counter()
    integ = IntegratorOptions(step_s=options.step_s, spectral_radius=options.spectral_radius,
                              newton_relative_tolerance=options.newton_relative_tolerance,
                              modified_newton=options.modified_newton, timing_breakdown=options.timing_breakdown)
    run = system.run(targets.positions_m, targets.velocities_m_s, targets.present, frame_dt_s=dt, options=integ)
    t3 = time.perf_counter()
    if progress:
        progress(run.completed_frames)
    if not run.success:
        _raise_failure(kin, points, targets, run)
    q = kin.coordinates_from_rotations(run.rotations)
    q = np.unwrap(q, axis=0)
    qd, qdd = kin.coordinate_rates(q, run.angular_velocities_rad_s, run.angular_accelerations_rad_s2)
    t4 = time.perf_counter()
    recon = assemble(kin, points, targets, method="pf", q=q, qd=qd, qdd=qdd,
                     status=np.full(targets.n_frames, FrameStatus.CONVERGED), timings_s={}, info={})
    _check_divergence(recon, options.divergence_deflection_m, targets)
    timings = {"equilibrium": t1 - t0, "build": t2 - t1, "integration": t3 - t2, "recovery": t4 - t3,
               "total": t4 - t0}
    with np.errstate(all="ignore"):
        mean_defl = float(np.nanmean(recon.residuals_m))
    info = {
        "mean_spring_deflection_mm": mean_defl * 1000.0,
        "steps": run.steps,
        "newton_iterations_per_step": run.newton_iterations / max(run.steps, 1),
        "jacobian_updates_per_step": run.jacobian_updates / max(run.steps, 1),
        "exudyn_cpu_times_s": dict(run.solver_times_s),
        "gravity": options.gravity,
        "options": options.__dict__,
        "initial_q_rad": q0.tolist(),
    }
    return Reconstruction(**{**recon.__dict__, "timings_s": timings, "info": info})


def _worst(kin: Kinematics, points, targets: MarkerTargets, q: np.ndarray, frame: int) -> tuple[str, float]:
    r = kin.points(q, points)
    d = np.linalg.norm(r - targets.positions_m[frame], axis=1)
    if np.all(np.isnan(d)):
        return "none", float("nan")
    j = int(np.nanargmax(d))
    return points.names[j], float(d[j])


def _raise_failure(kin, points, targets, run) -> None:
    last = max(run.completed_frames - 1, 0)
    q_last = kin.coordinates_from_rotations(run.rotations[last])
    name, defl = _worst(kin, points, targets, q_last, last)
    raise ReconstructionError(
        f"{targets.source or 'trial'}: the PF solver stopped at t = {targets.time_s[min(last + 1, targets.n_frames - 1)]:.3f} s "
        f"(frame {last + 1} of {targets.n_frames}): {run.message.strip() or 'no convergence'}; worst marker {name} "
        f"with a spring deflection of {defl * 1000:.1f} mm at the last completed frame")


def _check_divergence(recon: Reconstruction, limit_m: float, targets: MarkerTargets) -> None:
    res = recon.residuals_m
    if not np.any(res > limit_m):
        if np.all(np.isfinite(recon.q_rad)):
            return
    bad = np.argwhere(~(res <= limit_m) & ~np.isnan(targets.positions_m).any(axis=2))
    if bad.size == 0:
        if np.all(np.isfinite(recon.q_rad)):
            return
        frame = int(np.argmax(~np.isfinite(recon.q_rad).all(axis=1)))
        raise ReconstructionError(f"{targets.source or 'trial'}: the PF solution is not finite from t = {recon.time_s[frame]:.3f} s")
    frame, j = (int(v) for v in bad[0])
    worst = int(np.nanargmax(res[frame]))
    raise ReconstructionError(
        f"{targets.source or 'trial'}: the PF run diverged at t = {recon.time_s[frame]:.3f} s: spring "
        f"'{recon.marker_names[worst]}' is {res[frame, worst] * 1000:.0f} mm long (limit {limit_m * 1000:.0f} mm); "
        f"check the marker labels and the model, or raise the spring constants")
