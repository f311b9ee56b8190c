"""The live reconstruction loop: marker samples in, joint angles, rates, residuals and a running
verdict out, frame by frame, with PF on a calibrated model; shared exactly by ``exubio live`` and
the offline causal run (``reconstruct_causal``, exubio.run.live.offline), so the two give the same
numbers.

Frames. Every sample is placed on the stream's uniform grid by its timestamp (frame =
round((t - t_first) rate)). A frame that never came (dropped) has every marker missing: the PF
springs are off for the steps that touch it and the model coasts on its own inertia. A sample for a
frame already processed (late, duplicate) is counted and dropped. A hole in the stream longer than
``max_coast_s`` (a stall), timestamps that go back (a restarted sender), a frame with no active
spring for that long, or a PF run that diverges end the current PF run: the next frame with a
static equilibrium of the springs (the LS pose) starts a new one. Each of these is an Event,
reported live (``on_event``) and kept in the recording.

Falling behind. Frames are processed in order as they come; when the solver is slower than the
stream, samples queue up and are all processed as fast as possible (the backlog is reported, in
frames, on every frame's output). A backlog beyond ``max_behind_s`` is not carried on: the queued
frames are skipped (recorded as missing, an Event says how many) and a new PF run starts at the
newest frame. The first ``catch_up_s`` seconds (2 s) after the session's first frame is solved are exempt:
the start-up backlog (set-up, first solve) is worked off at full speed. With the defaults the angles are
never more than about 0.5 s late after that (a run that starts after a skip starts at the newest frame).

Labels. A label swap in the stream shows as two markers far from their model points but each
close to the other's: where that holds for LABEL_SWAP_FRAMES frames in a row, both springs are
switched off (the posture is carried by the other markers) and an Event names the pair; they come
back on once their own model points fit again.

Ctrl-C (``stop``) or the end of the stream end the loop; the recording (LiveRecording) then holds
every frame: the raw samples, the causal targets, the PF result, the events.
"""
from __future__ import annotations

import gc
import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from exubio.trust import quality as Q
from exubio.errors import InputError, ReconstructionError
from exubio.run.live.causal import CausalFrame, CausalTargets
from exubio.run.live.intake import EndRun, Sample, SampleIntake
from exubio.run.live.frame import LiveFrame
from exubio.run.live.monitor import LiveMonitor
from exubio.run.live.options import LiveOptions
from exubio.run.live.outputs import ISB_NAMES, VERDICT_CODES, Event, FrameRecord, LiveRecording
from exubio.run.live.sources import MarkerSource
from exubio.backend.pf_types import stack_motions
from exubio.methods.pf import _Frames, pf_setup
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Trajectories

log = logging.getLogger(__name__)

__all__ = ["LiveSession", "SessionHooks"]

DEFER_FRAMES = 16
"""Frames whose bookkeeping (rates, constraint residuals, noise gains, running figures, the record)
is done together, vectorised, after their angles went out (a fixed count: the same batches live and
offline)."""


def _settle_heap(*, collect: bool = True, freeze: bool = True) -> None:
    """Freeze every object alive (undone at the session's end), after collecting those made since the last
    freeze: a full collection walks all the process's objects (78 ms at 1000 Hz, once a minute), frozen only
    the newer. At the set-up (not collected: 64 ms) and as each PF run starts (0.1 ms)."""
    if freeze and collect:
        gc.collect()
    if freeze:
        gc.freeze()


@dataclass(frozen=True)
class SessionHooks:
    """What a LiveSession calls out to: ``publish`` (row, timestamp) each result, ``on_event`` /
    ``on_status`` (the display), ``on_ready`` once the session is set up, ``calibrate`` (trial,
    frames) -> (model, protocol, report) for a calibration on the first frames, and the ``clock``."""

    publish: Callable[[np.ndarray, float], None] | None = None
    on_event: Callable[[Event], None] | None = None
    on_status: Callable[[dict], None] | None = None
    on_ready: Callable[["LiveSession"], None] | None = None
    calibrate: Callable[[Trajectories, slice], tuple[Model, Protocol, Any]] | None = None
    clock: Callable[[], float] = time.perf_counter


class LiveSession:
    """One live reconstruction: ``run()`` pulls ``source`` until it ends or ``stop()`` is called,
    hands every frame's output row (OUTPUT_CHANNELS) to ``publish(row, input_timestamp)`` and
    returns the LiveRecording.

    on_event(event): every Event as it happens; on_status(dict): about every ``status_every_s`` a
    summary for a display (latency, frames behind, residual, verdict, a few angles).
    static_frames: calibrate the model from these frames of the stream first (the frames are
    buffered, the model calibrated, then every frame, these included, is reconstructed; the
    ``calibrated`` function receives (model, protocol, report))."""

    def __init__(self, model: Model, protocol: Protocol, source: MarkerSource, /, *, options: LiveOptions = LiveOptions(),
                 hooks: "SessionHooks | None" = None, static_frames: slice | None = None, status_every_s: float = 0.2):
        hooks = hooks if hooks is not None else SessionHooks()
        self.model, self.protocol, self.source, self.options = model, protocol, source, options
        self.publish, self.on_event, self.on_status = hooks.publish, hooks.on_event, hooks.on_status
        self.status_every_s, self.static_frames, self.calibrate = status_every_s, static_frames, hooks.calibrate
        self.clock, self.on_ready = hooks.clock, hooks.on_ready
        self._stop = threading.Event()

    # ------------------------------------------------------------------ control
    def stop(self) -> None:
        """End the session at the next frame (safe from a signal handler or another thread)."""
        self._stop.set()
        try:
            self.source.wake()
        except Exception:  # noqa: BLE001 - a source that cannot be woken ends at its pull timeout
            pass

    def _event(self, kind: str, frame: int, message: str, markers: Sequence[str] = ()) -> None:
        ev = Event(kind, int(frame), frame / self.rate, message, tuple(markers))
        self.events.append(ev)
        log.info("live %s at frame %d: %s", kind, frame, message)
        if self.on_event is not None:
            self.on_event(ev)

    # ------------------------------------------------------------------ samples
    def _wait_for_sample(self, *, first: bool = False) -> bool:
        """Block until a sample is queued (SampleIntake.wait); False when the stream ended or the
        session stops, ``ended_by`` saying which."""
        why = self.intake.wait(self._stop, first=first)
        if why:
            self.ended_by = why
        return not why

    def _may_skip(self) -> bool:
        """A backlog may be skipped: in any PF run after the first, or ``catch_up_s`` into it."""
        return self.run_id > 0 or self.clock() - self.run_started > self.options.catch_up_s

    # ------------------------------------------------------------------ frames
    def _record_input(self, g: int, raw: np.ndarray, sample: Sample | None, frame: CausalFrame, *,
                      blank: bool = False) -> None:
        self.intake.taken(g, sample, blank=blank)
        self.record.input(g, raw, sample, frame)
        if not blank:
            self.monitor.track_gaps(g, frame.present, sample is None)

    def _frame(self, g: int) -> tuple[CausalFrame, np.ndarray]:
        raw, sample = self.intake.next_raw(g, wait=self._wait_for_sample, restart=self.causal.restart,
                                           may_skip=self._may_skip)
        frame = self.causal.push(raw)
        self._record_input(g, raw, sample, frame)
        self.current_sample = sample
        active = frame.present & ~self.monitor.quarantine
        self.record.rows["active"].set(g, active)
        return frame, active

    # ------------------------------------------------------------------ outputs
    def _empty(self, g: int, status: FrameStatus = FrameStatus.TOO_FEW_MARKERS, *, publish: bool = True) -> None:
        """A frame no PF run holds (before a run starts, a failed frame): published (unless it already was,
        with its angles: a diverged frame) and recorded empty."""
        if publish:
            self._publish(g, None, None)
        self.record.output(g, status)
        failed = status == FrameStatus.NOT_CONVERGED
        self.n_failed, self.n_no_state = self.n_failed + int(failed), self.n_no_state + int(not failed)
        self._frames_done(g, g)

    def _publish(self, g: int, q: np.ndarray | None, measured_m: np.ndarray | None) -> tuple:
        """The frame's output row: the ISB angles of q, their rates (backward differences of the
        published angles), the measured flags, the residuals, the running verdict."""
        if q is not None:
            out = self.frame_out.outputs(q, measured_m)  # one compiled call (exubio.run.live.frame)
            isb, rate, res, pts, mean_res = out.isb, out.rate, out.residuals, out.points, out.mean_residual_mm
            self.monitor.gh_elevation(g, out.gh_elevation)
        else:
            isb, rate = self.frame_out.none()
            res, pts, mean_res = np.full(len(self.marker_names), np.nan), None, np.nan
        self.out_isb = isb
        behind = self.intake.backlog(g)
        sample = self.current_sample
        ts = np.nan if sample is None else sample.timestamp
        self.out_mean_res, self.out_behind = mean_res, behind
        if self.publish is not None:
            row = np.concatenate([np.degrees(isb) * self.angle_signs, np.degrees(rate) * self.angle_signs,
                                  self.monitor.measured.astype(float), res * 1e3,
                                  [mean_res, VERDICT_CODES[self.monitor.quality.verdict], float(q is not None), behind,
                                   g, ts]])
            self.publish(row, ts)
        self.record.published(g, self.clock(), sample, isb, rate, self.monitor.measured)
        return res, pts

    def _flush(self, frames) -> None:
        """The deferred frames' rates, model points, residuals and constraint residuals, vectorised
        over the batch, then recorded in order."""
        if not self.deferred:
            return
        batch, self.deferred = self.deferred, []
        gs = [b[0] for b in batch]
        if batch[0][4] is not None:  # rates computed (and projected) before publishing
            q, qd, qdd = (np.vstack([b[4][k] for b in batch]) for k in range(3))
        else:
            q = np.vstack([b[1] for b in batch])
            q, qd, qdd = frames.rates(q, stack_motions([b[2] for b in batch]))
        targets = MarkerTargets(time_s=np.array(gs) / self.rate, marker_names=self.marker_names,
                                positions_m=np.stack([b[3].positions_m for b in batch]),
                                velocities_m_s=np.stack([b[3].velocities_m_s for b in batch]),
                                accelerations_m_s2=np.stack([b[3].accelerations_m_s2 for b in batch]))
        recon = frames.finish(q, qd, qdd, targets)  # diverged frames never get here (checked at publishing)
        self._record_outputs(gs[0], recon)  # (a PF run's frames, one after the other)

    def _record_outputs(self, g0: int, recon) -> None:
        """The PF results (a Reconstruction of n frames) of frames g0 ... g0 + n - 1 recorded a block at a time,
        with the running checks and the verdicts where they fall due, as a frame at a time gives them."""
        n, q, res, mon = recon.n_frames, recon.q_rad, recon.residuals_m, self.monitor
        self.record.outputs(g0, recon, self.run_id)
        active, start = self.record.rows["active"], 0
        while start < n:  # up to the frame the next verdict falls due on
            stop = n if mon.verdict_due > g0 + n - 1 else max(mon.verdict_due - g0, start) + 1
            for i in range(start, stop):
                if g0 + i >= mon.det_due:
                    mon.determinacy(g0 + i, q[i], active.get(g0 + i))
            mon.running(g0 + start, q[start:stop], res[start:stop])
            self._frames_done(g0 + start, g0 + stop - 1)
            start = stop

    def _frames_done(self, first: int, g: int) -> None:
        """Frames first ... g recorded: the verdict if due at g, the verdict's code of each frame, the status."""
        self.n_frames = g + 1
        verdict = self.record.rows["verdict"]
        if g > first:
            verdict.set_rows(first, np.full(g - first, VERDICT_CODES[self.monitor.quality.verdict]))
        if self.monitor.verdict_due <= g:
            self.monitor.verdict(g, self._counts(), self.events)
        verdict.set(g, VERDICT_CODES[self.monitor.quality.verdict])
        if self.on_status is not None and (now := self.clock()) >= self.status_due:
            self.status_due = now + self.status_every_s
            self.on_status(self.monitor.status(g, self.out_isb, self.out_mean_res, self.out_behind,
                                               latency=self.record.latency, counts=self._counts(),
                                               tracking=self.tracking))

    def _counts(self) -> dict[str, int]:
        """The frames dropped, late, skipped, failed and without a PF state so far."""
        intake = self.intake
        return {"dropped": intake.n_dropped, "late": intake.n_late, "skipped": intake.n_skipped,
                "failed": self.n_failed, "no_state": self.n_no_state}

    # ------------------------------------------------------------------ PF runs
    def _start_run(self, g: int) -> int | None:
        """Find the first frame from g with a static equilibrium of the springs and start a PF run
        there; returns the frame it starts on (None at the end)."""
        while True:
            try:
                frame, active = self._frame(g)
            except EndRun:
                g = self.intake.queue[0].index if self.intake.queue else g
                for i in range(self.n_frames, g):
                    self._blank(i)
                continue
            targets = MarkerTargets(time_s=np.array([0.0]), marker_names=self.marker_names,
                                    positions_m=np.where(active[:, None], frame.positions_m, np.nan)[None],
                                    velocities_m_s=frame.velocities_m_s[None],
                                    accelerations_m_s2=frame.accelerations_m_s2[None], source=self.info.name)
            if active.sum() >= self.min_markers:
                try:
                    self.setup = pf_setup(self.binding, targets, self.options.pf)
                    self.start_frame = (frame, active)
                    return g
                except ReconstructionError as exc:
                    log.debug("no LS start at frame %d: %s", g, exc)
            self._empty(g)
            g += 1

    def _blank(self, g: int) -> None:
        """A frame that never came and no PF run holds (inside a skipped backlog or a long hole)."""
        nan = np.full((self.n_labels, 3), np.nan)
        frame = CausalFrame(np.full((len(self.marker_names), 3), np.nan), np.zeros((len(self.marker_names), 3)),
                            np.zeros((len(self.marker_names), 3)), np.zeros(len(self.marker_names), dtype=bool))
        self.current_sample = None
        self.causal.restart()  # the next sample has no predecessor: no velocity from across the hole
        self._record_input(g, nan, None, frame, blank=True)
        self.record.rows["active"].set(g, frame.present)
        self._empty(g)

    def _run_pf(self, g0: int) -> int:
        """One PF run from frame g0 until it must end; returns the next frame to start from."""
        setup = self.setup
        b = setup.binding
        frames = _Frames(b.kin, b.points, None, setup.q0, b.held, self.options.pf, None, 1.0 / self.rate)
        self.run_id += 1
        self.frame_out.start_run(setup.q0)
        _settle_heap(freeze=self.own_gc)  # the new run's system is built: frozen with the rest
        self.run_started = self.clock()
        self.tracking = True
        self._event("run_start", g0, f"PF run {self.run_id} starts from the LS pose of frame {g0}")
        state = {"end": None, "last": g0 - 1, "idle": 0}

        def next_frame(i: int):
            if self._stop.is_set():
                self.ended_by = "stopped"
                return None
            if i == 0:
                frame, active = self.start_frame
            else:
                if state["end"] is not None:
                    return None
                try:
                    frame, active = self._frame(g0 + i)
                except EndRun:
                    state["end"] = "hole"
                    return None
                except StopIteration:
                    state["end"] = "stream"
                    return None
            state["idle"] = 0 if active.any() else state["idle"] + 1
            if state["idle"] > self.intake.coast_frames:
                state["end"] = "no marker"
                self._event("run_end", g0 + i, f"no active spring for {state['idle']} frames: the PF run ends")
                return None
            self.pending[g0 + i] = (frame, self.current_sample)
            self.n_stepped += 1
            return frame.positions_m, frame.velocities_m_s, active

        def on_frame(i: int, part) -> None:
            g = g0 + i
            frame, self.current_sample = self.pending.pop(g)  # (a reduced step may have fetched the next)
            # the angles first (published at once); what does not steer the next steps (rates,
            # constraint residuals, noise gains, running figures) a batch of frames at a time
            q = self.frame_out.coordinates(part.rotations)[None]
            rates = frames.rates(q, stack_motions([part])) if projected else None  # published: the projected ones
            if rates is not None:
                q = rates[0]
            res, pts = self._publish(g, q[0], frame.positions_m)
            why = self.monitor.diverged(g, q[0], res, frame.present)
            if why:
                self._flush(frames)
                self._event("diverged", g, f"{why}; the PF run restarts from the LS pose")
                state["end"] = "diverged"
                self._empty(g, FrameStatus.NOT_CONVERGED, publish=False)  # (published with its angles)
                return
            self.monitor.label_check(g, res, pts, frame.positions_m)
            state["last"] = g
            self.deferred.append((g, q, part, frame, rates))
            if len(self.deferred) >= DEFER_FRAMES:
                self._flush(frames)
            if i == 0 and self.run_id == 0:  # the session's first frame solved: the catch-up grace starts now, so
                self.run_started = self.clock()  # its one-off costs (first step, kernels compiled) do not eat it

        projected = self.options.pf.project_constraints
        from exubio.backend.exudyn_system import IntegratorOptions

        pf = self.options.pf
        integ = IntegratorOptions(step_s=None, spectral_radius=pf.spectral_radius,
                                  newton_relative_tolerance=pf.newton_relative_tolerance,
                                  modified_newton=pf.modified_newton, timing_breakdown=False)
        try:
            run = setup.system.run_live(next_frame, on_frame, frame_dt_s=1.0 / self.rate, options=integ,
                                        interrupt=self.stop)
        finally:
            self._flush(frames)
        self.tracking = False
        for g in sorted(self.pending):  # a frame taken but not solved (the solver stopped)
            _, self.current_sample = self.pending.pop(g)
            self._empty(g, FrameStatus.NOT_CONVERGED)
        if run.message and state["end"] is None and not self._stop.is_set():
            self._event("diverged", state["last"] + 1, f"the PF solver stopped: {run.message.strip()}; "
                        "the PF run restarts from the LS pose")
            state["end"] = "solver"
        if state["end"] == "stream" or self._stop.is_set():
            return -1
        if state["end"] == "hole" and self.intake.queue:
            nxt = self.intake.queue[0].index
            if not self.intake.restarted and nxt - (state["last"] + 1) > self.intake.coast_frames:
                self._event("run_end", state["last"] + 1, f"{nxt - state['last'] - 1} frames "
                            f"({(nxt - state['last'] - 1) / self.rate:.2f} s) without samples, more than "
                            f"{self.options.max_coast_s:g} s: the PF run ends")
            self.intake.restarted = False
            for i in range(self.n_frames, nxt):
                self._blank(i)
            return nxt
        return self.n_frames

    # ------------------------------------------------------------------ the session
    def _open(self) -> None:
        self.intake = SampleIntake(self.source, self.options, self.clock, self._event)
        self.info, self.rate, self.labels, self.n_labels = (self.intake.info, self.intake.rate, self.intake.labels,
                                                            self.intake.n_labels)
        self.events: list[Event] = []
        self.ended_by = ""
        self.n_failed = self.n_no_state = self.n_stepped = 0

    def _bind(self) -> None:
        from exubio.protocol.bind import bind

        self.causal = CausalTargets(self.protocol, self.labels, self.rate, options=self.options.causal,
                                    source=self.info.name)
        if self.causal.unused:
            log.info("%s: labels not used by protocol '%s': %s", self.info.name, self.protocol.name, list(self.causal.unused))
        self.marker_names = self.protocol.marker_names
        self.binding = bind(self.model, self.protocol)  # once per session (and again after a calibration)
        self.kin, self.points = self.binding.kin, self.binding.points
        self.monitor = LiveMonitor(self.binding, self.rate, self.options,
                                   self.causal.columns >= 0,  # optional markers the stream does not carry: no gap events
                                   self._event)
        self.min_markers = 3
        self.record = FrameRecord(self.n_labels, len(self.marker_names), self.model.n_coordinates)
        self.pending: dict[int, tuple] = {}  # frame -> (CausalFrame, its sample) taken, not yet solved
        self.deferred: list = []
        self.run_id, self.run_started, self.n_frames, self.tracking = -1, self.clock(), 0, False
        self.frame_out = LiveFrame(self.model, self.kin, self.points, self.rate, self.monitor.gh_axes)
        from exubio.model.signs import factors

        self.angle_signs = factors(ISB_NAMES, self.protocol.signs)  # the stream's convention (ISB inside)
        self.current_sample, self.status_due = None, 0.0

    def _calibrate_from_stream(self) -> Any:
        """Buffer the static frames, calibrate the model on them (their raw samples), and rebind."""
        sl = self.static_frames
        raws = self.intake.static_frames(sl.stop, self._wait_for_sample)
        traj = Trajectories(labels=self.labels, positions_m=raws, rate_hz=self.rate,
                            time_s=np.arange(len(raws)) / self.rate, source=self.info.name, units_in_file=self.info.units)
        model, protocol, report = self.calibrate(traj, sl)
        self.model, self.protocol = model, protocol
        self.intake.put_back()
        return report

    def run(self) -> LiveRecording:
        """Run until the stream ends or ``stop()``; returns the recording (also after Ctrl-C)."""
        self._open()
        self.own_gc = gc.get_freeze_count() == 0  # (a host that froze objects itself keeps its own policy)
        try:
            return self._run()
        finally:
            if self.own_gc:
                gc.unfreeze()

    def _run(self) -> LiveRecording:
        report = None
        if self.static_frames is None:
            self._bind()  # before the first sample: the stream's start is not kept waiting
            if self.on_ready is not None:
                self.on_ready(self)
        if not self.intake.pull(1.0) or not self.intake.queue:
            if not self._wait_for_sample(first=True):
                raise InputError(f"{self.info.name}: no sample came within {self.options.open_timeout_s:g} s of "
                                 "opening the stream")
        self.run_started = self.clock()  # the start-up grace counts from the first sample
        if self.static_frames is not None:
            if self.calibrate is None:
                raise InputError("static_frames given without a calibrate function")
            report = self._calibrate_from_stream()
            self._bind()
            from exubio.calibration import SCALE_BOUNDS

            self.monitor.calibration, self.monitor.scale_bounds = report, SCALE_BOUNDS  # as for the recording
            self.monitor.off_segment = Q.off_segment_markers(self.model, self.protocol)
            if self.on_ready is not None:
                self.on_ready(self)
        self.intake.check_units(self.causal)
        _settle_heap(collect=False, freeze=self.own_gc)
        g = 0
        cpu0, wall0 = time.process_time(), time.perf_counter()
        try:
            while not self._stop.is_set():
                try:
                    g = self._start_run(g)
                except StopIteration:
                    break
                g = self._run_pf(g)
                if g < 0:
                    break
        except KeyboardInterrupt:
            self.ended_by = "stopped (Ctrl-C)"
        self.cpu_s, self.wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
        if not self.ended_by:
            self.ended_by = "stopped" if self._stop.is_set() else "end of stream"
        dropped_run = self.intake.dropped_run
        if dropped_run:
            self._event("dropped", self.n_frames - dropped_run, f"{dropped_run} frame(s) never came")
        if self.n_frames:
            self.monitor.verdict(self.n_frames - 1, self._counts(), self.events)
        self._event("end", self.n_frames,
                    f"{self.ended_by}: {self.n_frames} frames, verdict {self.monitor.quality.verdict}")
        return self._recording(report)

    def _recording(self, report: Any) -> LiveRecording:
        n = self.n_frames
        intake = self.intake
        stats = {"frames": n, "dropped": intake.n_dropped, "late": intake.n_late, "skipped": intake.n_skipped,
                 "failed": self.n_failed, "no_pf_state": self.n_no_state, "runs": self.run_id + 1,
                 "cpu_ms_per_frame": 1e3 * self.cpu_s / max(self.n_stepped, 1),
                 "cpu_definition": "the process's CPU time (solver, bookkeeping, LSL threads; waiting excluded) per "
                                   "frame PF stepped through (skipped frames cost nothing)",
                 "loop_latency_ms": self.record.latency_ms()}
        return LiveRecording(
            info=self.info, model=self.model, protocol=self.protocol, options=self.options,
            marker_names=self.marker_names, **self.record.arrays(n), events=list(self.events),
            live_quality=self.monitor.quality, ended_by=self.ended_by, calibration=report, stats=stats)
