"""Potential-field (PF) reconstruction (paper Eq. 4-7) on Exudyn.

Every protocol marker pulls its segment-fixed model point through a linear spring-damper
(c_i, d_i from the protocol); the arm's equations of motion with the two ellipsoid constraints
are integrated forward in time by Exudyn's implicit generalized-alpha solver (index 3, 10 ms
steps by default), so q, q̇ and q̈ come out of one consistent trajectory. A final projection in
minimal coordinates (one Newton step on g, then G q̇ = 0 and G q̈ + eta = 0) removes what is left
of the constraint violations at the size of Exudyn's Newton tolerance, so g, G q̇ and G q̈ + eta
vanish to round-off at every frame (the raw values are kept in ``info``). What separates the model
points from noise-free markers is the physics of the method: the springs must accelerate the
segments, so every point lags its marker by about m a / c (0.05 mm, 0.05 deg on the simulated
abduction with c = 1500 N/m; 100x less with 100x lighter segments), whatever the step.

Initial state (the paper: "static equilibrium ... unstrained springs at time zero"): the springs
have zero rest length, so their static equilibrium at the first frame is the minimum of
sum_i c_i |R_i - M_i|^2 subject to g = 0, i.e. the weighted LS solution of that frame. The run
starts there, with the consistent velocity (J q̇ = ṙ_M, G q̇ = 0), so the net spring force is zero
at t = 0 and q and q̇ start without a transient; q̈ would start at its force-free value (0) and
reach the tracked motion within about 0.05 s (the stiff spring-damper mode, d/m ~ 1e3 1/s): measured
on the simulated abduction, noise-free, up to 80 deg/s^2 of q̈ error in the first 40 ms, 0.02-0.36
deg/s^2 after it, so that transient was the whole of PF's noise-free q̈ error (RMSE up to 3.8 deg/s^2
on a 10 s trial instead of 0.36). The run therefore starts ``PFOptions.lead_in_s`` (0.1 s) before
the first frame, on the targets extrapolated backwards from it with their spline velocity and
acceleration (r(t) = r_0 + v_0 t + a_0 t^2 / 2, t < 0), from the static equilibrium of that earlier
instant: by the first frame the springs have settled onto the tracked motion and q̈ starts on it.
The lead-in frames are not part of the result. Gravity is off by default: with it on, the springs
must also carry the limb's weight and every model point sags below its marker (about 1-2 mm
and 1° on the synthetic trials; see the README).

Segments that no marker observes (no marker on them or on a segment they carry) have their joints
locked at the start posture; LS holds the same coordinates at their start value. Coordinates a
protocol lists under ``hold`` (e.g. the clavicle's axial rotation for a set without clavicle
markers) are held at 0 by both methods.

A marker missing in a frame switches its spring off for that stretch (reported as a gap). A run
whose solver stops, or whose spring deflections grow beyond ``divergence_deflection_m``, raises a
ReconstructionError naming the time and the worst marker.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from exubio.backend.exudyn_system import IntegratorOptions, PFSystem
from exubio.errors import InputError, ReconstructionError
from exubio.model.kinematics import Kinematics
from exubio.methods.common import CHUNK_FRAMES, ChunkSink, Collector, assemble, target_chunk
from exubio.methods.constraints import project_on_constraints
from exubio.methods.pf_time import integration_step, lead_in_frames, lead_in_run
from exubio.types import StopReason
from exubio.methods.poses import RATES_REGULARISATION, Limits, LSOptions, solve_positions, solve_rates
from exubio.protocol.bind import Binding, bind
from exubio.model.ranges import DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Reconstruction

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PFOptions:
    """Settings of the PF reconstruction (c_i, d_i come from the protocol, not from here).

    step_s: the longest integration step (s). At least a frame: a whole number of frames per
        step (the springs are set to the frame each step ends on; the frames inside a step are
        quintic Hermite interpolations of q, q̇, q̈ at the step ends), and only for targets the
        protocol low-passes to cutoff <= 1 / (4 step): unfiltered targets get one step per frame
        (see ``integration_step``). Shorter than a frame: a whole number of steps per frame
        (targets between frames: cubic Hermite). None: one step per frame. The default 10 ms (2
        frames at 200 Hz, 1 at 100 Hz) costs a third less than 5 ms steps at the same joint-angle
        accuracy: the tracking error is the inertial lag m a / c, not a step-size effect.
    spectral_radius: generalized-alpha rho_inf. At 10 ms steps 0.5 keeps q̈ closest to the
        derivative of q̇: smaller values lag q̈ by up to a step, larger ones let the stiff
        spring mode (c/m ~ 1e3 1/s^2) ring from step to step.
    newton_relative_tolerance: Exudyn's Newton stops at this reduction of its residual. The spring
        stiffness turns any position error into q̈ (times c/m): 1e-4 is as accurate in q but
        makes q̈ 2-5x worse for 10 % less time.
    project_constraints: finish with one Newton step on the ellipsoid constraints in minimal
        coordinates (q <- q - G+ g, then q̇ <- q̇ - G+ G q̇ and q̈ <- q̈ - G+ (G q̈ + eta)) so that
        g, G q̇ and G q̈ + eta vanish to round-off. The corrections are what Exudyn's Newton
        tolerance leaves (|g| ~ 1e-8 noise-free, 1e-7 with filtered noise, more on unfiltered
        noisy targets; index 3 does not hold G q̇, ~1e-5 1/s) and move the angles by < 1e-5 deg
        noise-free. False reports Exudyn's own constraint residuals.
    lead_in_s: the run starts this long before the first frame, on the targets extrapolated
        backwards from it (quadratically, with the first frame's spline velocity and acceleration),
        so that the stiff spring-damper mode has settled by the first frame and q̈ starts on the
        tracked motion instead of at its force-free value (see the module docstring); rounded to
        whole steps; 0: no lead-in.
    inertia_scale: the segments' anthropometric masses and inertias are multiplied by this in the
        dynamics the springs drive (gravity, when on, still loads the real weight). The springs'
        tracking error is the inertial lag m a / c, so the mass is a numerical choice, not a
        property of the subject: noise-free, 0.1 cuts the worst coordinate's RMSE from 0.078 to
        0.008 deg (forearm pronation in flexion; abduction 0.044 -> 0.004, SIER 0.047 -> 0.005),
        halves the q̈ error against the truth, and leaves the noisy results as they were (1.5 mm
        noise: worst angle 0.63 -> 0.62 deg); the stiff mode (c/m ~ 1e4 1/s^2) stays damped by the
        generalized-alpha step (studies/README.md, "PF's inertia"). 1.0: the paper's physical
        segments.
    fallback: a run whose integration stops (Newton fails, or the springs diverge) is run once more
        from the start with FALLBACK_OPTIONS (inertia x 0.01, the Jacobian rebuilt every Newton
        iteration), when the sink can start again (``restart``); the result's ``info["fallback"]``
        gives the first run's reason, and the trial's verdict notes it. Measured (studies/README.md,
        "PF across its parameters"): those options finish every run of the sensitivity grid and every
        real trial, with the defaults' angles to 0.1 deg RMSE on every real run (worst 0.091 deg; model
        points <= 1.05 mm), at 1.4-1.9 times the CPU time, and x 0.01
        with modified Newton stops two strained real trials at their first frame: hence a fallback,
        not the defaults. False: the first stop is raised. Offline runs only: the live loop
        (exubio.run.live) cannot run a stream again and starts a new run instead.
    limit_stiffness_nm_per_rad: k_lim of the range-of-motion limits (the model's coordinate ranges;
        one-sided quadratic potential beyond each limit, the same as LS's: exubio.model.ranges; the
        Exudyn elements: exubio.backend.exudyn_system.PFSystem).
    """

    step_s: float | None = 0.01
    lead_in_s: float = 0.1  # integrate from this long before the first frame (extrapolated targets)
    spectral_radius: float = 0.5
    newton_relative_tolerance: float = 1e-5
    modified_newton: bool = True
    project_constraints: bool = True
    gravity: bool = False
    divergence_deflection_m: float = 0.25  # a spring longer than this means the run diverged
    timing_breakdown: bool = True
    limit_stiffness_nm_per_rad: float | None = DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD  # None or 0: no limits
    inertia_scale: float = 0.1  # the segments' masses and inertias the springs accelerate, x this
    fallback: bool = True  # a run that stops is run once more with FALLBACK_OPTIONS (info["fallback"] says so)


FALLBACK_OPTIONS = {"inertia_scale": 0.01, "modified_newton": False}  # PFOptions.fallback's second run


def limits_stiffness(options: PFOptions) -> float:
    """The limit stiffness PFSystem gets (its default where the limits are off: no element is built)."""
    k = options.limit_stiffness_nm_per_rad
    return float(k) if k else DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD


def initial_state(kin: Kinematics, points, targets: MarkerTargets, stiffness: np.ndarray, /, *,
                  held: np.ndarray | None = None, limits: Limits | None = None):
    """Static equilibrium of the springs at the first frame with its consistent velocity."""
    first = 0
    present = targets.present
    weights = stiffness / stiffness.mean()
    q0, _, ok, stop = solve_positions(kin, points, targets.positions_m[first:first + 1], weights,
                                      q_start=np.zeros(kin.n_coordinates),
                                      options=LSOptions(tol_rad=1e-12, max_iterations=60),
                                      frame_dt=1.0, held=held, limits=limits)
    if not ok[0]:
        raise ReconstructionError(
            f"{targets.source or 'trial'}: no static equilibrium at t = {targets.time_s[0]:.3f} s "
            f"(markers present: {int(present[0].sum())} of {present.shape[1]}; the pose solve stopped: "
            f"{StopReason(int(stop[0])).label})")
    qd0, _ = solve_rates(kin, points, q0, targets.velocities_m_s[:1], targets.accelerations_m_s2[:1], weights,
                         RATES_REGULARISATION, held, limits)
    return q0[0], qd0[0]


def reconstruct_pf(model: Model, protocol: Protocol, targets: MarkerTargets, /, *,
                   options: PFOptions = PFOptions(),
                   progress: Callable[[int], None] | None = None) -> Reconstruction:
    """Reconstruct a trial with the potential-field method (``model`` and ``protocol`` bound
    here: a run takes its session's binding, stream_pf)."""
    chunks = Collector()
    timings, info = stream_pf(bind(model, protocol), targets, chunks, options=options, progress=progress,
                              chunk_frames=max(targets.n_frames, 1))  # one chunk: every frame at the end
    return chunks.reconstruction(targets, timings_s=timings, info=info)


@dataclass(frozen=True)
class PFSetup:
    """What a PF run starts from: the binding (kinematics, tracked points, held mask), the start state
    (q0, qd0) and the Exudyn system built on it (shared by the offline run and the live one,
    exubio.run.live)."""

    binding: Binding
    q0: np.ndarray
    qd0: np.ndarray
    system: PFSystem
    equilibrium_s: float
    build_s: float


def pf_setup(binding: Binding, targets: MarkerTargets, options: PFOptions = PFOptions(), /) -> PFSetup:
    """The start of a PF run on ``targets`` (only its first frame is used): the static equilibrium of the
    springs there with its consistent velocity, the locked segments, and the PFSystem."""
    t0 = time.perf_counter()
    model, protocol, kin, points, held = binding.model, binding.protocol, binding.kin, binding.points, binding.held
    stiffness = np.array([m.stiffness_n_per_m for m in protocol.markers])
    limits = Limits.of(model, protocol, options.limit_stiffness_nm_per_rad)
    q0, qd0 = initial_state(kin, points, targets, stiffness, held=held, limits=limits)
    for i in binding.unobserved:  # held at their start value, like LS does through its regularisation
        qd0[kin.joint_coordinate_indices(i)] = 0.0
    t1 = time.perf_counter()
    if not (math.isfinite(options.inertia_scale) and options.inertia_scale > 0):
        raise InputError(f"PFOptions.inertia_scale must be a number > 0, got {options.inertia_scale}")
    system = PFSystem(binding, q0=q0, qd0=qd0, gravity=options.gravity,
                      limits_rad=model.coordinate_ranges_rad if limits is not None else None,
                      limit_stiffness_nm_per_rad=limits_stiffness(options), inertia_scale=options.inertia_scale)
    return PFSetup(binding, q0, qd0, system, t1 - t0, time.perf_counter() - t1)


def stream_pf(binding: Binding, targets: MarkerTargets, sink: ChunkSink, /, *,
              options: PFOptions = PFOptions(), progress: Callable[[int], None] | None = None,
              chunk_frames: int = CHUNK_FRAMES) -> tuple[dict[str, float], dict]:
    """Reconstruct a trial with the potential-field method, handing the result to ``sink`` in chunks
    of ``chunk_frames`` frames as the integration reaches them (one integration through the whole
    trial; exubio.methods.common). A divergence is raised as soon as a chunk shows it. Returns
    (timings_s, info)."""
    t0 = time.perf_counter()
    if targets.n_frames < 2:
        raise ReconstructionError(f"{targets.source or 'trial'}: the PF method needs at least 2 frames")
    dt = float(np.median(np.diff(targets.time_s)))
    if np.abs(np.diff(targets.time_s) - dt).max() > 1e-6 * dt:
        raise ReconstructionError(f"{targets.source or 'trial'}: frames are not evenly spaced in time")
    restart = getattr(sink, "restart", None)
    reported = [0]  # frames handed to ``progress``: a second run reports only those beyond them

    def counted(k: int) -> None:
        if progress:
            progress(k)
        reported[0] += k

    try:
        return _stream_pf_once(binding, targets, sink, dt, options, counted, chunk_frames, t0)
    except ReconstructionError as first:
        first_s = time.perf_counter() - t0
        robust = dataclasses.replace(options, fallback=False, **FALLBACK_OPTIONS)
        if not options.fallback or restart is None or robust == dataclasses.replace(options, fallback=False):
            raise
        log.warning("PF stopped (%s); run again with %s (PFOptions.fallback)", first, FALLBACK_OPTIONS)
        restart()
        seen = [0]

        def beyond(k: int) -> None:  # the second run's frames, reported once they pass the first's
            seen[0] += k
            if seen[0] > reported[0]:
                counted(seen[0] - reported[0])
        try:
            timings, info = _stream_pf_once(binding, targets, sink, dt, robust, beyond, chunk_frames,
                                            time.perf_counter())
        except ReconstructionError as second:
            raise ReconstructionError(f"{first}; run again with inertia x {FALLBACK_OPTIONS['inertia_scale']:g} and full "
                                      f"Newton (PFOptions.fallback), it stopped too: {second}") from None
        info["fallback"] = {"first_run": str(first), "first_run_s": first_s, "options": dict(FALLBACK_OPTIONS),
                            "asked_inertia_scale": options.inertia_scale}
        return timings, info


def _stream_pf_once(binding: Binding, targets: MarkerTargets, sink: ChunkSink, dt: float,
                    options: PFOptions, progress: Callable[[int], None], chunk_frames: int,
                    t0: float) -> tuple[dict[str, float], dict]:
    """One integration through the trial (stream_pf's first run, or its fallback)."""
    protocol = binding.protocol
    cutoff_hz = (max(targets.cutoff_hz.values(), default=None) if protocol.cutoff_hz == "auto"  # widest applied
                 else protocol.cutoff_hz)
    step = integration_step(dt, options.step_s, cutoff_hz)
    lead = lead_in_frames(options.lead_in_s, dt, step)
    start, lead_pos, lead_vel = lead_in_run(targets, lead, dt)  # the run reads them before the targets: no copy
    setup = pf_setup(binding, start, options)  # the start state at the lead-in's first frame
    kin, points, held, q0, system = binding.kin, binding.points, binding.held, setup.q0, setup.system
    t1, t2 = t0 + setup.equilibrium_s, t0 + setup.equilibrium_s + setup.build_s
    integ = IntegratorOptions(step_s=step,
                              spectral_radius=options.spectral_radius,
                              newton_relative_tolerance=options.newton_relative_tolerance,
                              modified_newton=options.modified_newton, timing_breakdown=options.timing_breakdown)
    done = [0]

    seen = [0]

    def tick(n: int) -> None:  # frames of the trial (the lead-in's are not counted)
        seen[0] += n
        k = min(max(seen[0] - lead, 0), targets.n_frames) - done[0]
        if k > 0:
            done[0] += k
            if progress:
                progress(k)

    frames = _Frames(kin, points, targets, q0, held, options, sink, dt, lead=lead)
    active = np.concatenate([~np.isnan(lead_pos).any(axis=2), targets.present])  # the lead-in's frames, then the trial's
    run = system.run(targets.positions_m, targets.velocities_m_s, active,
                     frame_dt_s=dt, options=integ, progress=tick, on_frames=frames, chunk_frames=chunk_frames,
                     first_chunk_extra=lead, lead_in=(lead_pos, lead_vel))
    completed = max(run.completed_frames - lead, 0)
    if progress and completed > done[0]:
        progress(completed - done[0])
    if not run.success:
        _raise_failure(kin, points, targets, run, frames.last_q, lead=lead, qd_last=frames.last_qd)
    total = time.perf_counter() - t0 - frames.sink_s  # the method's own time, not the sink's
    timings = {"equilibrium": t1 - t0, "build": t2 - t1, "integration": total - (t2 - t0) - frames.busy_s,
               "recovery": frames.recovery_s, "residuals": frames.residuals_s, "total": total}
    info = {
        "mean_spring_deflection_mm": frames.mean_deflection_m() * 1000.0,
        "steps": run.steps,
        "newton_iterations_per_step": run.newton_iterations / max(run.steps, 1),
        "jacobian_updates_per_step": run.jacobian_updates / max(run.steps, 1),
        "exudyn_cpu_times_s": dict(run.solver_times_s),
        "gravity": options.gravity,
        "step_s": run.step_s,
        "exudyn_max_abs_g": frames.raw_g,  # before the final projection (NaN without it)
        "exudyn_max_abs_G_qd": frames.raw_gqd,
        "options": options.__dict__,
        "initial_q_rad": q0.tolist(),  # at the start of the lead-in
        "lead_in_s": lead * dt,
        "limit_active_s": dict(run.limit_active_s),  # per joint with a range: time its limit element was on
    }
    return timings, info


class _Frames:
    """Receives the segment motion from PFSystem.run chunk by chunk and hands the Reconstruction
    chunks to the sink: joint coordinates on the start posture's branch (unwrapped across chunks),
    their rates, the projection on the constraints, model points and residuals, the divergence check."""

    def __init__(self, kin: Kinematics, points, targets: MarkerTargets, q0: np.ndarray, held: np.ndarray,
                 options: PFOptions, sink: ChunkSink, dt: float, *, lead: int = 0):
        self.kin, self.points, self.targets, self.q0, self.held, self.dt = kin, points, targets, q0, held, dt
        self.lead = lead  # frames of lead-in before the trial's first: unwrapped, not handed on
        self.options, self.sink = options, sink
        self.last_raw = self.last_unwrapped = self.last_q = self.last_qd = self.shift = None  # the frame before this chunk
        self.raw_g = self.raw_gqd = float("nan")
        self.sum_res, self.n_res = 0.0, 0
        self.sink_s = self.recovery_s = self.residuals_s = 0.0

    @property
    def busy_s(self) -> float:
        return self.recovery_s + self.residuals_s

    def __call__(self, run) -> None:
        q = self.coordinates(run)
        ta = time.perf_counter()
        qd, qdd = self.kin.coordinate_rates(q, run.angular_velocities_rad_s, run.angular_accelerations_rad_s2)
        start = int(round(run.time_s[0] / self.dt)) - self.lead  # the chunk's first frame in the trial
        if start < 0:  # drop the lead-in frames
            skip = min(-start, q.shape[0])
            q, qd, qdd, start = q[skip:], qd[skip:], qdd[skip:], start + skip
            if q.shape[0] == 0:
                self.recovery_s += time.perf_counter() - ta
                return
        q, qd, qdd = self._project(q, qd, qdd)
        self.recovery_s += time.perf_counter() - ta
        recon = self.finish(q, qd, qdd, target_chunk(self.targets, start, start + q.shape[0]))
        tc = time.perf_counter()
        self.sink(recon)
        self.sink_s += time.perf_counter() - tc

    def _project(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.options.project_constraints:
            q, qd, qdd, (g, gqd) = project_on_constraints(self.kin, q, qd, qdd, held=self.held)
            self.raw_g, self.raw_gqd = _nanmax(self.raw_g, g), _nanmax(self.raw_gqd, gqd)
        return q, qd, qdd

    def coordinates(self, run) -> np.ndarray:
        """Joint coordinates (n, m) of the frames of ``run`` on the start posture's branch (unwrapped
        across chunks), before the projection on the constraints (the live loop does the same a frame at a
        time: exubio.run.live.frame)."""
        ta = time.perf_counter()
        raw = self.kin.coordinates_from_rotations(run.rotations)
        if self.last_raw is None:
            q = np.unwrap(raw, axis=0)
            self.shift = 2.0 * np.pi * np.round((q[0] - self.q0) / (2.0 * np.pi))  # same branch as the start posture
        else:  # continue the unwrapping of the frames before
            q = np.unwrap(np.vstack([self.last_raw[None], raw]), axis=0)[1:] + (self.last_unwrapped - self.last_raw)
        self.last_raw, self.last_unwrapped = raw[-1], q[-1]
        self.recovery_s += time.perf_counter() - ta
        return q - self.shift

    def rates(self, q: np.ndarray, run) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q̇, q̈ of the frames of ``run``, projected on the constraints if the options say so."""
        ta = time.perf_counter()
        qd, qdd = self.kin.coordinate_rates(q, run.angular_velocities_rad_s, run.angular_accelerations_rad_s2)
        q, qd, qdd = self._project(q, qd, qdd)
        self.recovery_s += time.perf_counter() - ta
        return q, qd, qdd

    def finish(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, part: MarkerTargets) -> Reconstruction:
        """Model points, residuals and constraint residuals of q (the frames of ``part``); the
        divergence check."""
        tb = time.perf_counter()
        recon = assemble(self.kin, self.points, part, method="pf", q=q, qd=qd, qdd=qdd,
                         status=np.full(part.n_frames, FrameStatus.CONVERGED), timings_s={}, info={})
        _check_divergence(recon, self.options.divergence_deflection_m, part, self.kin)
        with np.errstate(all="ignore"):
            ok = ~np.isnan(recon.residuals_m)
            self.sum_res += float(recon.residuals_m[ok].sum())
            self.n_res += int(ok.sum())
        self.last_q, self.last_qd = q[-1], qd[-1]
        self.residuals_s += time.perf_counter() - tb
        return recon

    def mean_deflection_m(self) -> float:
        return self.sum_res / self.n_res if self.n_res else float("nan")


def _nanmax(a: float, b: float) -> float:
    return b if not np.isfinite(a) else (a if not np.isfinite(b) else max(a, b))


def _worst(kin: Kinematics, points, targets: MarkerTargets, q: np.ndarray, frame: int) -> tuple[str, float]:
    r = kin.points(q, points)
    d = np.linalg.norm(r - targets.positions_m[frame], axis=1)
    if np.all(np.isnan(d)):
        return "none", float("nan")
    j = int(np.nanargmax(d))
    return points.names[j], float(d[j])


def _where(kin: Kinematics, q_last: np.ndarray | None, qd_last: np.ndarray | None) -> str:
    """Where the state was when the solver stopped: coordinates beyond their range of motion (the
    limit potential acting) and the fastest coordinate, at the last completed frame."""
    if q_last is None:
        return ""
    names = kin.model.coordinate_names
    rng = kin.model.coordinate_ranges_rad
    beyond = [f"{names[j]} {np.degrees(q_last[j]):.0f} deg (range {np.degrees(rng[j, 0]):.0f}..{np.degrees(rng[j, 1]):.0f})"
              for j in range(len(names)) if q_last[j] < rng[j, 0] or q_last[j] > rng[j, 1]]
    out = "; beyond their range of motion there: " + ", ".join(beyond) if beyond else ""
    if qd_last is not None and np.all(np.isfinite(qd_last)):
        j = int(np.argmax(np.abs(qd_last)))
        out += f"; fastest coordinate {names[j]} at {abs(qd_last[j]):.1f} rad/s"
    return out


def _raise_failure(kin, points, targets, run, q_last: np.ndarray | None, *, lead: int = 0,
                   qd_last: np.ndarray | None = None) -> None:
    last = max(run.completed_frames - 1 - lead, 0)
    name, defl = _worst(kin, points, targets, q_last, last) if q_last is not None else ("none", float("nan"))
    raise ReconstructionError(
        f"{targets.source or 'trial'}: the PF solver stopped at t = {targets.time_s[min(last + 1, targets.n_frames - 1)]:.3f} s "
        f"(frame {last + 1} of {targets.n_frames}): {run.message.strip() or 'no convergence'}; worst marker {name} "
        f"with a spring deflection of {defl * 1000:.1f} mm at the last completed frame{_where(kin, q_last, qd_last)}")


def _check_divergence(recon: Reconstruction, limit_m: float, targets: MarkerTargets, kin: Kinematics | None = None
                      ) -> None:
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
    where = _where(kin, recon.q_rad[frame], recon.qd_rad_s[frame]) if kin is not None else ""
    raise ReconstructionError(
        f"{targets.source or 'trial'}: the PF run diverged at t = {recon.time_s[frame]:.3f} s: spring "
        f"'{recon.marker_names[worst]}' is {res[frame, worst] * 1000:.0f} mm long (limit {limit_m * 1000:.0f} mm){where}; "
        f"check the marker labels and the model, or raise the spring constants")
