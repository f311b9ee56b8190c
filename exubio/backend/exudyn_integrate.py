"""Integrating the PF system (exubio.backend.exudyn_system.PFSystem) through the marker targets.

The equations of motion are integrated with Exudyn's implicit generalized-alpha solver (index 3,
modified Newton, Eigen's sparse LU with the analysed pattern reused). A step may span several
frames: the springs are then set to the frame each step ends on and the frames inside a step are
quintic Hermite interpolations of the step states (q, q̇, q̈ of one polynomial, so the three stay
consistent); a last, shorter step ends on the last frame. Segment poses, velocities and
accelerations are returned at the frame times.

A run is an object that holds its state and whose ``pre_step`` and ``post_step`` Exudyn calls
around every step. ``Integration`` holds what every run shares (the springs' first targets, the
limit switching, the solve, Ctrl-C); ``_TrialRun`` here is ``PFSystem.run`` (every frame known
before the start), ``exubio.backend.exudyn_live`` has ``PFSystem.run_live`` (frames as they come).
"""
from __future__ import annotations

import bisect
import dataclasses
import logging
import math
import signal
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

import exudyn as exu

from exubio.backend.exudyn_limits import LimitSwitching
from exubio.backend.pf_numerics import JoinedRows, LimitElement, StateRecord, finite_rows, frames_from_steps, hermite
from exubio.backend.pf_types import FrameMotion, IntegratorOptions, PFRun, SpringSet

__all__ = ["BuiltSystem", "Integration", "SpringTargets", "integrate_trial", "solver_settings"]

log = logging.getLogger(__name__)

_ROW_BLOCK = 4096  # spring targets of this many step ends are made at a time
_TIMER_FIELDS = (
    "total", "factorization", "newtonIncrement", "integrationFormula", "ODE2RHS", "AERHS",
    "totalJacobian", "massMatrix", "reactionForces", "python", "postNewton", "writeSolution", "overhead",
)  # fmt: skip


# --------------------------------------------------------------------------------------------
# What a run needs of the system
# --------------------------------------------------------------------------------------------
class SpringTargets:
    """The marker springs' targets and switches, set before every step: a native spring's offset
    r_M + (d/c) v_M, or a symbolic spring's target vector [r_M, v_M] (exubio.backend.exudyn_system)."""

    def __init__(self, mbs, objects: Sequence[int], symbolic: Sequence, native: bool, springs: SpringSet):
        self.k = k = len(objects)
        self.objects, self.symbolic, self.native = list(objects), list(symbolic), native
        self.set_parameter = mbs.SetObjectParameter
        self.d_over_c = np.divide(springs.damping_ns_per_m, springs.stiffness_n_per_m,
                                  out=np.zeros(k), where=springs.stiffness_n_per_m > 0)[:, None]

    def rows(self, p: np.ndarray, v: np.ndarray) -> list:
        """What the springs are set to for positions p and velocities v (..., k, 3), as nested lists
        (fast setters)."""
        return self.values(p, v).tolist()

    def values(self, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``rows`` as an array (..., k, 3 or 6): a block of frames is kept as one array and turned
        into lists a frame at a time (a block's worth of nested lists alive at once made Python's
        full garbage collection run during the solve, 15 us per frame in every other run)."""
        return p + self.d_over_c * v if self.native else np.concatenate([p, v], axis=-1)

    def set(self, row: list) -> None:
        objects, symbolic, set_parameter = self.objects, self.symbolic, self.set_parameter
        if self.native:
            for j in range(self.k):
                set_parameter(objects[j], "offset", row[j])
        else:
            for j in range(self.k):
                symbolic[j].SetVector(row[j])

    def set_to(self, p: np.ndarray, v: np.ndarray) -> None:
        self.set(self.rows(p, v))

    def switch_all(self, on: np.ndarray) -> None:
        for j in range(self.k):
            self.set_parameter(self.objects[j], "activeConnector", bool(on[j]))

    def switch(self, now: np.ndarray, state: np.ndarray) -> None:
        """The springs whose markers the next step uses (``now``, (k,) bool) on, the others off;
        ``state`` (the switches as they are) follows."""
        changed = now != state
        if changed.any():
            for j in np.flatnonzero(changed):
                self.set_parameter(self.objects[j], "activeConnector", bool(now[j]))
            state[:] = now


@dataclass(frozen=True)
class BuiltSystem:
    """What a run needs of a built PF system (exubio.backend.exudyn_system.PFSystem).

    mbs:        the assembled Exudyn MainSystem.
    targets:    its marker springs.
    limits:     its range-of-motion limit elements (exubio.backend.exudyn_limits), and
                ``limit_max_rate_rad_s``, the joint rate their switching allows for.
    n_ode2, n_segments: the system's coordinates and the model's segments.
    decode:     (X, Xt, Xtt, frame_dt_s, *, first) -> PFRun: the segment motion of system states.
    decode_frame: (X, Xt, Xtt) -> FrameMotion: the same of one state (a live run's frame).
    """

    mbs: Any
    targets: SpringTargets
    limits: Sequence[LimitElement]
    limit_max_rate_rad_s: float
    n_ode2: int
    n_segments: int
    decode: Callable[..., PFRun]
    decode_frame: Callable[..., FrameMotion]


# --------------------------------------------------------------------------------------------
# What every run shares
# --------------------------------------------------------------------------------------------
class Integration:
    """The state both kinds of run share, the start and the solve; ``pre_step`` (before a step,
    with the time it ends at) and ``post_step`` (after every accepted step, and once at t = 0
    after the initial accelerations) are the subclass's."""

    def __init__(self, system: BuiltSystem, frame_dt_s: float, interrupt: Callable[[], None] | None = None):
        self.system = system
        self.mbs = system.mbs
        self.sd = system.mbs.systemData
        self.targets = system.targets
        self.frame_dt_s = frame_dt_s
        self.interrupt = interrupt  # called by the Ctrl-C handler too
        self.interrupted = False  # Ctrl-C: the next pre-step stops the solver
        self.failure: BaseException | None = None  # raised in a step function: stops the solver, raised by solve
        self.ended = False  # the frames ran out (live): the solver was stopped on purpose
        self.accepted = 0  # accepted steps
        self.state: np.ndarray | None = None  # (k,) bool: the springs' switches
        self.limits: LimitSwitching | None = None
        self.wall_time_s = float("nan")

    def pre_step(self, mbs, t: float) -> bool:
        raise NotImplementedError

    def post_step(self, mbs, t: float) -> bool:
        raise NotImplementedError

    def start(self, row: list, active: np.ndarray, step_s: float) -> None:
        """The springs set to the first frame (``row``; those of missing markers off), then the
        limit elements reset for steps of ``step_s``."""
        self.state = active.copy()
        self.targets.set(row)
        self.targets.switch_all(self.state)
        self.limits = LimitSwitching(self.mbs, self.system.limits, self.system.limit_max_rate_rad_s, step_s)

    def no_frames(self, first: int) -> PFRun:
        """A PFRun without frames (the statistics of a run go in it)."""
        empty = np.zeros((0, self.system.n_ode2))
        return self.system.decode(empty, empty, empty, self.frame_dt_s, first=first)

    def solve(self, settings, step_s: float) -> tuple[Any, bool, str]:
        """Exudyn's implicit solver through this run's steps (of ``step_s``; with adaptive steps the
        solver shortens the last one to end on the last frame: a uniform endTime / numberOfSteps
        would miss the frame times). Returns (the solver, success, its error message or "").
        Ctrl-C raises KeyboardInterrupt, and an exception of a step function is raised, once
        Exudyn has returned."""
        mbs = self.mbs
        mbs.SetPreStepUserFunction(self.pre_step)
        mbs.SetPostStepUserFunction(self.post_step)
        solver = exu.MainSolverImplicitSecondOrder()
        print_before = exu.config.printToConsole
        exu.config.printToConsole = False  # Exudyn prints progress/warnings itself; we log instead
        message = ""
        t0 = time.perf_counter()
        previous_handler = _catch_sigint(self._on_sigint)
        try:
            success = bool(solver.InitializeSolver(mbs, settings))
            if success:
                solver.it.maxStepSize = solver.it.currentStepSize = step_s
                t_steps = time.perf_counter()
                success = bool(solver.SolveSteps(mbs, settings))
                solver.timer.total = time.perf_counter() - t_steps  # SolveSteps alone does not set it
                solver.FinalizeSolver(mbs, settings)
            if not success and not self.ended:
                message = solver.GetErrorString() or "solver did not finish"
        except Exception as exc:  # Exudyn raises its own error types on divergence
            success = False
            message = f"{type(exc).__name__}: {exc}"
        finally:
            exu.config.printToConsole = print_before
            mbs.SetPreStepUserFunction(0)
            mbs.SetPostStepUserFunction(0)
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)
        if self.interrupted:
            raise KeyboardInterrupt
        if self.failure is not None:
            raise self.failure
        self.wall_time_s = time.perf_counter() - t0
        return solver, success, message

    def _on_sigint(self) -> None:
        self.interrupted = True
        if self.interrupt is not None:
            self.interrupt()


# --------------------------------------------------------------------------------------------
# A run through a trial's frames (PFSystem.run)
# --------------------------------------------------------------------------------------------
def integrate_trial(system: BuiltSystem, targets_pos, targets_vel, active, /, *, frame_dt_s: float,
                    options: IntegratorOptions, progress: Callable[[int], None] | None,
                    on_frames: Callable[[PFRun], None] | None, chunk_frames: int, first_chunk_extra: int,
                    lead_in: tuple[np.ndarray, np.ndarray] | None = None) -> PFRun:
    """``PFSystem.run`` (see there): the inputs checked and the steps counted, then the run."""
    pos = np.asarray(targets_pos, dtype=float)
    vel = np.asarray(targets_vel, dtype=float)
    if lead_in is not None:  # frames before targets_pos's first, read with them without copying them
        pos, vel = (JoinedRows(np.asarray(a, dtype=float), b) for a, b in zip(lead_in, (pos, vel)))
    k = system.targets.k
    if pos.ndim != 3 or pos.shape[1:] != (k, 3) or pos.shape[0] < 2:
        raise ValueError(f"run: targets_pos must have shape (n >= 2, {k}, 3), got {pos.shape}")
    if vel.shape != pos.shape:
        raise ValueError(f"run: targets_vel must have shape {pos.shape}, got {vel.shape}")
    n = pos.shape[0]
    act = np.ones((n, k), dtype=bool) if active is None else np.asarray(active, dtype=bool)
    if act.shape != (n, k):
        raise ValueError(f"run: active must have shape ({n}, {k}), got {act.shape}")
    finite = finite_rows(pos) & finite_rows(vel)
    if np.any(act & ~finite):
        f, j = np.argwhere(act & ~finite)[0]
        raise ValueError(f"run: marker {j} is active but not finite at frame {f}; mark missing samples inactive")
    if not frame_dt_s > 0:
        raise ValueError(f"run: frame_dt_s must be > 0, got {frame_dt_s}")
    step = frame_dt_s if options.step_s is None else float(options.step_s)
    if not step > 0:
        raise ValueError(f"run: step_s must be > 0, got {step}")
    if step < frame_dt_s * (1 - 1e-9):  # sub-steps: a whole number per frame
        sub = int(round(frame_dt_s / step))
        if abs(sub * step - frame_dt_s) > 1e-9 * frame_dt_s:
            raise ValueError(f"run: frame_dt_s / step_s must be a positive integer when step_s < frame_dt_s, "
                             f"got {frame_dt_s} / {step}")
        per_frame, n_steps = 1.0 / sub, (n - 1) * sub
    else:  # a whole number of frames per step; a last step over the remaining frames
        per = int(round(step / frame_dt_s))
        if abs(per * frame_dt_s - step) > 1e-9 * step:
            raise ValueError(f"run: step_s / frame_dt_s must be a positive integer when step_s > frame_dt_s, "
                             f"got {step} / {frame_dt_s}")
        per_frame, n_steps = float(per), int(math.ceil((n - 1) / per))
        if (n - 1) % per and not options.adaptive_step:
            raise ValueError(f"run: {n - 1} frame intervals are not a multiple of {per} frames per step "
                             f"(needs adaptive_step=True for the shorter last step)")
    run = _TrialRun(system, pos, vel, act, frame_dt_s, per_frame, n_steps, progress=progress, on_frames=on_frames,
                    chunk_frames=chunk_frames, first_chunk_extra=first_chunk_extra)
    return run.run(options)


class _TrialRun(Integration):
    """A run through n frames known before the start, in steps of ``per_frame`` frames (a fraction:
    sub-steps), ``n_steps`` of them; the frames go to ``on_frames`` in chunks as the steps reach
    them, or are joined at the end."""

    def __init__(self, system: BuiltSystem, pos: np.ndarray, vel: np.ndarray, act: np.ndarray, frame_dt_s: float,
                 per_frame: float, n_steps: int, *, progress, on_frames, chunk_frames: int, first_chunk_extra: int):
        super().__init__(system, frame_dt_s)
        self.pos, self.vel, self.act = pos, vel, act
        self.n = n = pos.shape[0]
        self.per_frame, self.n_steps = per_frame, n_steps
        # the rows of the frames the steps end on (nested lists: fast setters), made a block at a
        # time; other frames on demand
        self.ends = np.unique(np.r_[np.arange(0, n, max(int(round(per_frame)), 1)), n - 1])
        self.ends_list = self.ends.tolist()  # for bisect
        self.block = (0, np.zeros((0, self.targets.k, 3)))  # (index in ends of its first row, the rows)
        # a step uses a spring only if its marker is present in every frame the step touches
        self.cmiss = np.vstack([np.zeros((1, act.shape[1]), dtype=np.int32), np.cumsum(~act, axis=0, dtype=np.int32)])
        self.any_missing = bool(self.cmiss[-1].any())
        self.start(self.frame_row(0), act[0], per_frame * frame_dt_s)

        self.record_t: list[float] = []  # times of the recorded states: t = 0, then every accepted step
        self.on_frames = on_frames
        self.chunk = n if on_frames is None else max(int(chunk_frames), 1)
        self.extra = max(int(first_chunk_extra), 0)
        capacity = min(n_steps, int(math.ceil((self.chunk + self.extra) / per_frame)) + 2) + 16
        self.record = StateRecord(system.n_ode2, capacity=capacity)
        self.eps = 1e-6 * frame_dt_s
        self.flushed = 0  # frames handed on (to on_frames, or to parts)
        self.parts: list[PFRun] = []  # without on_frames: every frame, joined at the end
        self.progress = progress
        self.reported = 0
        self.report_every = max(1, int(round(0.5 / frame_dt_s)))  # progress about every 0.5 s of motion

    # ---------------------------------------------------------------- the targets
    def measured(self, i):
        """Positions and velocities of frame(s) i, zero where a marker is missing."""
        a = self.act[i][..., None]
        return np.where(a, self.pos[i], 0.0), np.where(a, self.vel[i], 0.0)

    def frame_row(self, i: int) -> list:
        e = bisect.bisect_left(self.ends_list, i)
        if e == len(self.ends_list) or self.ends_list[e] != i:  # a reduced step that ends on another frame
            return self.targets.rows(*self.measured(i))
        first, rows = self.block
        if not first <= e < first + len(rows):
            rows = self.targets.values(*self.measured(self.ends[e:e + _ROW_BLOCK]))
            first = e
            self.block = (first, rows)
        return rows[e - first].tolist()

    def rows_between(self, x: float) -> list:
        """A step that ends between frames (sub-steps, reduced steps): cubic Hermite."""
        i = min(max(int(math.floor(x + 1e-9)), 0), self.n - 2)
        (p0, p1), (v0, v1) = self.measured(np.array([i, i + 1]))
        p, v = hermite(p0, v0, p1, v1, x - i, self.frame_dt_s)
        return self.targets.rows(p, v)

    # ---------------------------------------------------------------- the steps
    def pre_step(self, mbs, t: float) -> bool:  # receives t_{n+1}: the end of the step about to be solved
        if self.interrupted or self.failure is not None:  # Ctrl-C, or on_frames failed: stop the solver here
            return False
        limits = self.limits
        if limits.elements:  # the current state is that of the step's start, the last accepted time
            t_start = self.record_t[-1] if self.record_t else 0.0
            if t_start >= limits.next_check:
                limits.check(t_start)
        dt, n = self.frame_dt_s, self.n
        x = t / dt
        i = int(x + 0.5)
        if self.any_missing:
            start = self.record_t[-1] if self.record_t else 0.0  # the step starts at the last accepted time
            lo = min(max(int(math.floor(start / dt + 1e-6)), 0), n - 1)
            hi = min(max(int(math.ceil(x - 1e-6)), 0), n - 1)
            self.targets.switch((self.cmiss[hi + 1] - self.cmiss[lo]) == 0, self.state)
        if abs(x - i) < 1e-6:
            row = self.frame_row(i)
        else:
            row = self.rows_between(x)
        self.targets.set(row)
        return True

    def post_step(self, mbs, t: float) -> bool:  # every accepted step, and once at t = 0 after the initial accelerations
        sd = self.sd
        self.record_t.append(t)
        self.record.append(sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t(), sd.GetODE2Coordinates_tt())
        if t > 0.0:
            self.accepted += 1
        n, dt = self.n, self.frame_dt_s
        upto = min(self.flushed + self.chunk + (self.extra if self.flushed == 0 else 0), n)
        if upto < n and t >= (upto - 1) * dt - self.eps and self.failure is None:
            try:
                self.flush(upto)
            except BaseException as exc:  # raised from run() once Exudyn has returned
                self.failure = exc
        if self.progress is not None:
            frame = int(t / dt + 0.5)
            if frame - self.reported >= self.report_every:
                self.progress(frame - self.reported)
                self.reported = frame
        return True

    def flush(self, upto: int) -> None:
        """Frames [flushed, upto) that the recorded steps reach go on; steps no later frame needs
        are dropped."""
        first, dt = self.flushed, self.frame_dt_s
        t_steps = np.asarray(self.record_t)
        X, Xt, Xtt, done = frames_from_steps(t_steps, self.record.arrays(), upto - first, dt, self.system.n_ode2,
                                             first=first)
        if done == 0:
            return
        part = self.system.decode(X[:done], Xt[:done], Xtt[:done], dt, first=first)
        self.flushed = first + done
        keep_from = max(int(np.searchsorted(t_steps, self.flushed * dt - self.eps, side="left")) - 1, 0)
        self.record.drop_first(keep_from)
        del self.record_t[:keep_from]
        if self.on_frames is None:
            self.parts.append(part)
        else:
            self.on_frames(part)

    # ---------------------------------------------------------------- the run
    def run(self, options: IntegratorOptions) -> PFRun:
        n, dt = self.n, self.frame_dt_s
        step_s = self.per_frame * dt
        solver, success, message = self.solve(solver_settings(self.n_steps, (n - 1) * dt, options), step_s)
        self.flush(n)  # the frames after the last full chunk, up to the last the solver reached
        completed = self.flushed
        success = success and completed == n
        if not success:
            log.warning("PF integration stopped at frame %d of %d: %s", completed, n, message)

        timer = solver.timer
        times = {name: float(getattr(timer, name)) for name in _TIMER_FIELDS if hasattr(timer, name)} if options.timing_breakdown else {}
        it = solver.it
        t_end = self.record_t[-1] if self.record_t else 0.0
        frames = _join(self.parts, n, dt, self.system.n_segments) if self.on_frames is None else self.no_frames(completed)
        return dataclasses.replace(
            frames, completed_frames=int(completed), success=bool(success), message=message,
            wall_time_s=float(self.wall_time_s), solver_times_s=times, newton_iterations=int(it.newtonStepsCount),
            jacobian_updates=int(it.newtonJacobiCount), steps=self.accepted, step_s=float(step_s),
            limit_active_s=self.limits.active_time_s(t_end))


def _join(parts: Sequence[PFRun], n: int, frame_dt_s: float, n_seg: int) -> PFRun:
    """One PFRun of n frames from consecutive parts; frames no part reached are NaN."""
    shapes = {"rotations": (n_seg, 3, 3), "origins_m": (n_seg, 3), "velocities_m_s": (n_seg, 3),
              "accelerations_m_s2": (n_seg, 3), "angular_velocities_rad_s": (n_seg, 3),
              "angular_accelerations_rad_s2": (n_seg, 3)}
    done = sum(p.n_frames for p in parts)
    out = {}
    for name, shape in shapes.items():
        arrays = [getattr(p, name) for p in parts] + ([np.full((n - done,) + shape, np.nan)] if done < n else [])
        out[name] = np.concatenate(arrays) if len(arrays) > 1 else arrays[0]
    return PFRun(time_s=np.arange(n) * frame_dt_s, completed_frames=done, success=done == n, message="",
                 wall_time_s=0.0, **out)


# --------------------------------------------------------------------------------------------
# The solver
# --------------------------------------------------------------------------------------------
def solver_settings(n_steps: int, end_time: float, options: IntegratorOptions):
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.numberOfSteps = n_steps
    ti.endTime = end_time
    ti.verboseMode = 0
    ti.adaptiveStep = options.adaptive_step
    ti.generalizedAlpha.spectralRadius = options.spectral_radius
    ti.generalizedAlpha.useIndex2Constraints = False  # index 3 (index 2 stalls with the quadratic constraint)
    ti.generalizedAlpha.computeInitialAccelerations = True
    ti.newton.useModifiedNewton = options.modified_newton
    ti.newton.modifiedNewtonContractivity = options.modified_newton_contractivity
    ti.newton.relativeTolerance = options.newton_relative_tolerance
    ti.newton.absoluteTolerance = options.newton_absolute_tolerance
    ti.newton.maxIterations = options.max_newton_iterations
    if options.sparse_solver:  # Eigen's SparseLU, symbolic analysis kept while the pattern holds
        s.linearSolver.solverType = exu.LinearSolverType.EigenSparse
        s.linearSolver.reuseAnalyzedPattern = True
    else:
        s.linearSolver.solverType = exu.LinearSolverType.EXUdense
    s.solution.file.write = False
    s.solution.sensors.active = False
    s.show.computationTime = options.timing_breakdown
    s.show.globalTimers = False
    s.show.statistics = False
    return s


def _catch_sigint(on_interrupt: Callable[[], None]):
    """During a solve, Ctrl-C calls ``on_interrupt`` (the step function then stops the solver, and
    the run raises KeyboardInterrupt once Exudyn has returned) instead of raising inside an Exudyn
    callback, where Exudyn would catch it, print it and go on. Returns the previous handler (None
    when not in the main thread, where handlers cannot be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):  # noqa: ARG001
        on_interrupt()

    return signal.signal(signal.SIGINT, handler)
