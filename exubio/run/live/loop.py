"""The live reconstruction loop: marker samples in, joint angles, rates, residuals and a running
verdict out, frame by frame, with PF on a calibrated model; shared exactly by ``exubio live`` and
the offline causal run (``reconstruct_causal``), so the two give the same numbers.

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
newest frame. The session's first ``catch_up_s`` seconds (2 s) are exempt: the start-up backlog is
worked off at the solver's full speed. With the defaults the angles are never more than about
0.5 s late after that (a run that starts after a skip starts at the newest frame: no backlog).

Labels. A label swap in the stream shows as two markers far from their model points but each
close to the other's: where that holds for LABEL_SWAP_FRAMES frames in a row, both springs are
switched off (the posture is carried by the other markers) and an Event names the pair; they come
back on once their own model points fit again.

Ctrl-C (``stop``) or the end of the stream end the loop; the recording (LiveRecording) then holds
every frame: the raw samples, the causal targets, the PF result, the events.
"""
from __future__ import annotations

import collections
import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from exubio.trust import quality as Q
from exubio.model.angles import ISB_COLUMNS, isb_table, measured_isb_joints
from exubio.trust.assess import DETERMINACY_PERIOD_S, not_solved_mask
from exubio.errors import InputError, ReconstructionError
from exubio.run.live.causal import CausalFrame, CausalOptions, CausalTargets, frame_index
from exubio.run.live.sources import UNIT_SCALE, MarkerSource, ReplaySource, StreamInfo
from exubio.methods.pf import PFOptions, _Frames, pf_setup
from exubio.trust.observability import determinacy
from exubio.prep.targets import PLAUSIBLE_MEDIAN_DISTANCE_M
from exubio.model.ranges import AT_LIMIT_TOLERANCE_RAD
from exubio.types import FrameStatus, Gap, MarkerTargets, Model, Protocol, Reconstruction, Trajectories

log = logging.getLogger(__name__)

__all__ = ["LiveOptions", "Event", "LiveRecording", "LiveSession", "reconstruct_causal", "angles_measured",
           "OUTPUT_CHANNELS", "LABEL_SWAP_FRAMES", "VERDICT_CODES"]

LABEL_SWAP_FRAMES = 3
"""Frames in a row a pair must look swapped before its springs go off (one frame can be noise)."""
LABEL_SWAP_MIN_MM = Q.RESIDUAL_MEAN_MM[0]
"""A marker must be this far from its model point to be a swap candidate: the residual at which a
trial's mean residual is already a check (quality.RESIDUAL_MEAN_MM)."""
LABEL_SWAP_RATIO = 0.5
"""Swapped, the pair's residuals must sum to less than this fraction of the unswapped sum."""
VERDICT_CODES = {"ok": 0, "check": 1, "fail": 2}
DEFER_FRAMES = 16
"""Frames whose bookkeeping (rates, constraint residuals, noise gains, running figures, the record)
is done together, vectorised, after their angles went out (a fixed count: the same batches live and
offline)."""
PULL_EVERY_S = 0.005
"""The source's own buffer is drained at least this often while frames are processed, so a backlog
that waits there (an LSL inlet's) is seen and counted."""
BEHIND_REPORT_S = 0.05
"""A backlog longer than this (50 ms: a tenth of the skip limit) is reported as an event (once, until
caught up); every frame's output carries the backlog anyway."""

ISB_NAMES = tuple(c for cols in ISB_COLUMNS.values() for c in cols)
ISB_JOINT_OF = tuple(j for j, cols in ISB_COLUMNS.items() for _ in cols)


def OUTPUT_CHANNELS(marker_names: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """(label, unit) of every channel of the output stream, in order."""
    ch = [(f"{n}", "degrees") for n in ISB_NAMES]
    ch += [(f"{n}_rate", "degrees/s") for n in ISB_NAMES]
    ch += [(f"{n}_measured", "bool") for n in ISB_NAMES]
    ch += [(f"residual_{m}", "mm") for m in marker_names]
    ch += [("residual_mean", "mm"), ("verdict", "0 ok, 1 check, 2 fail"), ("tracking", "1 PF state, 0 none"),
           ("frames_behind", "frames"), ("frame", "index"), ("input_timestamp", "s")]
    return tuple(ch)


_ISB_AS_ANATOMICAL = {"GH_X_elevation": "GH_phadke_X_elevation", "GH_Z_flexion": "GH_phadke_Z_flexion",
                      "GH_Y_internal_rotation": "GH_phadke_Y_internal_rotation"}
"""The ISB table's GH columns (Phadke's sequence) under their anatomical-angle names."""


def angles_measured(model: Model, not_solved: Sequence[str], undetermined: Sequence[str] = (), /, *,
                    protocol: Protocol | None = None, unmeasurable: Sequence[str] = (),
                    structural: Mapping[str, str] | None = None) -> np.ndarray:
    """(15,) bool, per ISB angle (ISB_COLUMNS order): measured by the markers. The one place the
    live output decides it. With ``protocol``: an angle the marker set cannot measure in any
    reference posture (exubio.trust.assess.angle_status_of_protocol, the status the files give) is not
    measured; of the others, a joint's angles are not measured in a frame where one of its own
    coordinates is not solved (held, locked) or undetermined there (exubio.trust.observability's noise
    gain), ``unmeasurable`` coordinates (the set cannot determine them anyway) left aside.
    ``structural``: that status, computed once by a caller that asks frame after frame."""
    joints = set(measured_isb_joints(model, set(not_solved) | (set(undetermined) - set(unmeasurable))))
    out = np.array([j in joints for j in ISB_JOINT_OF], dtype=bool)
    if structural is None and protocol is not None:
        from exubio.trust.assess import angle_status_of_protocol

        structural = angle_status_of_protocol(model, protocol)
    if structural is not None:
        status = structural
        for i, name in enumerate(ISB_NAMES):
            if status.get(_ISB_AS_ANATOMICAL.get(name, name), "measured") != "measured":
                out[i] = False
            elif not any(c in set(not_solved) for c in _joint_coordinates(model, ISB_JOINT_OF[i])) and \
                    not any(c in set(undetermined) - set(unmeasurable) for c in _joint_coordinates(model, ISB_JOINT_OF[i])):
                out[i] = True  # the set measures it and nothing of this frame says otherwise
    return out


def _joint_coordinates(model: Model, joint: str) -> tuple[str, ...]:
    """The model coordinates of the segments an ISB angle set relates (exubio.model.frame_definitions)."""
    from exubio.model.frame_definitions import JOINT_SEGMENTS

    segs = set(JOINT_SEGMENTS[joint]) - {"thorax"}
    return tuple(c for s in model.segments if s.name in segs and s.joint for c in s.joint.coordinates)


@dataclass(frozen=True)
class LiveOptions:
    """Settings of the live loop (see the module docstring).

    causal: the causal preprocessing (filter, rates). pf: the PF settings; the live run takes one
        step per frame whatever ``pf.step_s`` says. The final projection on the constraints is off by
        default (it moves angles by < 1e-5 deg and costs ~0.6 ms per frame, a third of the latency
        budget): the recording's constraint residuals are Exudyn's own (|g| ~ 1e-7).
    max_coast_s: a stretch of frames with no active spring (a hole in the stream, every marker
        gone) longer than this ends the PF run; a new one starts from the LS pose.
    stall_s: no sample for this long is reported as a stall.
    end_after_s: no sample for this long ends the stream (None: wait for ever, end with Ctrl-C).
    max_behind_s: a backlog longer than this is skipped (see the module docstring), except during the
        first ``catch_up_s`` seconds of the session's first PF run, in which the start's backlog (the
        stream opened, the LS pose, the system built, the first solves) is worked off.
    verdict_every_s: the running verdict is re-evaluated this often.
    open_timeout_s: how long to wait for the stream to appear.
    """

    causal: CausalOptions = CausalOptions()
    pf: PFOptions = PFOptions(step_s=None, project_constraints=False)
    max_coast_s: float = 0.1
    stall_s: float = 0.1
    end_after_s: float | None = 5.0
    max_behind_s: float = 0.5
    catch_up_s: float = 2.0
    verdict_every_s: float = 0.5
    open_timeout_s: float = 10.0


@dataclass(frozen=True)
class Event:
    """Something the live loop saw and handled: ``kind`` (gap, gap_end, dropped, late, stall,
    resumed, restart, run_start, run_end, behind, caught_up, skip, label_swap, label_swap_end,
    diverged, verdict, end), at ``frame`` (stream frame index) and ``time_s`` (its time on the frame grid)."""

    kind: str
    frame: int
    time_s: float
    message: str
    markers: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "frame": self.frame, "time_s": round(self.time_s, 6), "message": self.message,
                "markers": list(self.markers)}


class _Growing:
    """A (n, ...) float array appended one row at a time (amortised doubling)."""

    def __init__(self, shape: tuple[int, ...], fill: float = np.nan, dtype=float):
        self.a = np.full((256,) + tuple(shape), fill, dtype=dtype)
        self.n, self.fill = 0, fill

    def set(self, i: int, row) -> None:
        if i >= self.a.shape[0]:
            new = np.full((max(2 * self.a.shape[0], i + 1),) + self.a.shape[1:], self.fill, dtype=self.a.dtype)
            new[:self.n] = self.a[:self.n]
            self.a = new
        self.a[i] = row
        self.n = max(self.n, i + 1)

    def grow_to(self, n: int) -> None:
        if n > self.n:
            self.set(n - 1, self.fill)
            self.n = n

    def view(self, n: int | None = None) -> np.ndarray:
        return self.a[: self.n if n is None else n]


@dataclass
class LiveRecording:
    """Everything a live session saw and computed, one row per stream frame (SI units).

    raw_m: (n, n_labels, 3) the samples as received (lab frame, NaN = missing or never came);
    timestamps_s: (n,) the sample timestamps (NaN for frames that never came); received_s,
    published_s: (n,) perf_counter when the sample was taken from the source and its result
    published; targets: the causal targets (thorax frame); active: (n, k) the springs used;
    q/qd/qdd, model points, residuals, constraints, status (FrameStatus; TOO_FEW_MARKERS where
    no PF run held the frame), run (n,) the PF run (segment) of each frame (-1: none)."""

    info: StreamInfo
    model: Model
    protocol: Protocol
    options: LiveOptions
    marker_names: tuple[str, ...]
    raw_m: np.ndarray
    timestamps_s: np.ndarray
    received_s: np.ndarray
    published_s: np.ndarray
    positions_m: np.ndarray
    velocities_m_s: np.ndarray
    accelerations_m_s2: np.ndarray
    active: np.ndarray
    q_rad: np.ndarray
    qd_rad_s: np.ndarray
    qdd_rad_s2: np.ndarray
    model_points_m: np.ndarray
    residuals_m: np.ndarray
    constraint: np.ndarray
    constraint_velocity: np.ndarray
    status: np.ndarray
    run: np.ndarray
    isb_rad: np.ndarray
    isb_rate_rad_s: np.ndarray
    measured: np.ndarray
    verdict: np.ndarray
    events: list[Event] = field(default_factory=list)
    live_quality: Q.Quality | None = None
    ended_by: str = ""
    calibration: Any = None
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.q_rad.shape[0])

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.info.rate_hz

    def trajectories(self) -> Trajectories:
        """The input markers as received (lab frame, m) as a trial."""
        return Trajectories(labels=self.info.labels, positions_m=self.raw_m, rate_hz=self.info.rate_hz,
                            time_s=self.time_s, source=self.info.name, units_in_file=self.info.units)

    def targets(self) -> MarkerTargets:
        """The causal targets the PF tracked, as MarkerTargets (gaps from the missing samples)."""
        from exubio.prep.filtering import detect_gaps

        return MarkerTargets(time_s=self.time_s, marker_names=self.marker_names, positions_m=self.positions_m,
                             velocities_m_s=self.velocities_m_s, accelerations_m_s2=self.accelerations_m_s2,
                             gaps=detect_gaps(self.positions_m, self.marker_names), source=self.info.name)

    def reconstruction(self) -> Reconstruction:
        t = self.targets()
        return Reconstruction(
            method="pf", time_s=self.time_s, coordinate_names=self.model.coordinate_names, q_rad=self.q_rad,
            qd_rad_s=self.qd_rad_s, qdd_rad_s2=self.qdd_rad_s2, marker_names=self.marker_names,
            model_points_m=self.model_points_m, measured_m=self.positions_m, residuals_m=self.residuals_m,
            constraint=self.constraint, constraint_velocity=self.constraint_velocity, status=self.status,
            timings_s={"total": float(np.nansum(self.published_s - self.received_s))},
            info={"live": True, "causal": self.options.causal.describe(), "runs": int(self.run.max() + 1) if self.n_frames else 0,
                  "options": dataclasses.asdict(self.options.pf)}, gaps=t.gaps)


class _Motion:
    """The segment rates of a batch of frames, as _Frames.rates reads them from a PFRun."""
    __slots__ = ("angular_velocities_rad_s", "angular_accelerations_rad_s2")

    def __init__(self, w, a):
        self.angular_velocities_rad_s, self.angular_accelerations_rad_s2 = w, a


class _Sample:
    __slots__ = ("index", "timestamp", "raw", "received")

    def __init__(self, index, timestamp, raw, received):
        self.index, self.timestamp, self.raw, self.received = index, timestamp, raw, received


class _EndRun(Exception):
    pass


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
    def _pull(self, timeout_s: float) -> bool:
        """Take what the source has into the queue; False at the end of the stream."""
        got = self.source.pull(timeout_s)
        now = self.last_pull = self.clock()
        if got is None:
            return False
        for ts, values in got:
            raw = np.asarray(values, dtype=float).reshape(self.n_labels, 3) * self.scale
            ts = float(ts)
            if self.t_first is None:
                self.t_first = ts
            idx = frame_index(ts, self.t_first, self.rate)
            last = self.queue[-1].index if self.queue else self.last_index
            if ts < self.last_ts - 0.5 / self.rate and idx < last - 1:  # timestamps went back: a restarted sender
                self.t_first = ts - (last + 1 + self.restart_pad) / self.rate
                idx = frame_index(ts, self.t_first, self.rate)
                self._restart_pending = idx
            if idx <= last:
                self.n_late += 1
                if self.n_late <= 3 or self.n_late % 100 == 0:
                    self._event("late", idx, f"a sample for frame {idx} came after frame {last} ({self.n_late} so far); dropped")
                continue
            self.last_ts = ts
            self.queue.append(_Sample(idx, ts, raw, now))
            self.last_arrival = now
        return True

    def _wait_for_sample(self, *, first: bool = False) -> bool:
        """Block until a sample is queued; False when the stream ended or the session stops (the
        first sample is waited for ``open_timeout_s``, later ones ``end_after_s``)."""
        limit = self.options.open_timeout_s if first else self.options.end_after_s
        while not self.queue:
            if self._stop.is_set():
                self.ended_by = "stopped"
                return False
            silent = self.clock() - self.last_arrival
            if limit is not None and silent > limit:
                self.ended_by = f"no sample for {limit:g} s"
                return False
            if silent > self.options.stall_s and not self.stalled:
                self.stalled = True
                self._event("stall", self.last_index + 1, f"no sample for {silent:.2f} s")
            if not self._pull(0.02):
                self.ended_by = "end of stream"
                return False
        return True

    def _next_raw(self, g: int) -> tuple[np.ndarray, _Sample | None]:
        """The raw frame g: its sample, or all-missing if it never came. Raises _EndRun where the
        current PF run must end (a hole longer than max_coast_s, a restart, a skipped backlog) and
        StopIteration at the end."""
        if not self.queue or self.clock() - self.last_pull > PULL_EVERY_S:  # what waits in the source's buffer
            self._pull(0.0)  # counts as backlog too
        if not self.queue and not self._wait_for_sample():
            raise StopIteration
        head = self.queue[0]
        if self.stalled:
            self.stalled = False
            self._event("resumed", head.index, f"samples again after {head.index - g} missing frame(s)")
        if self._restart_pending is not None and head.index >= self._restart_pending:
            self._restart_pending = None
            self._restarted = True
            self._event("restart", head.index, "the stream's timestamps went back (the sender restarted); "
                        f"frames {g}..{head.index - 1} missing, the PF run restarts from the LS pose")
            self.causal.restart()
            raise _EndRun
        behind = self.queue[-1].index - g
        if behind > self.max_behind and (self.run_id > 0 or self.clock() - self.run_started > self.options.catch_up_s):
            newest = self.queue[-1]
            self._event("skip", g, f"{behind} frames ({behind / self.rate:.2f} s) behind, more than "
                        f"{self.options.max_behind_s:g} s: frames {g}..{newest.index - 1} skipped, a new PF run "
                        f"starts at frame {newest.index}")
            self.queue.clear()
            self.queue.append(newest)
            self.n_skipped += newest.index - g
            raise _EndRun
        if head.index > g:
            if head.index - g > self.coast_frames:
                raise _EndRun
            return np.full((self.n_labels, 3), np.nan), None
        return self.queue.popleft().raw, head

    # ------------------------------------------------------------------ frames
    def _record_input(self, g: int, raw: np.ndarray, sample: _Sample | None, frame: CausalFrame, *,
                      blank: bool = False) -> None:
        r = self.rec
        self.last_index = max(self.last_index, g)
        r["raw"].set(g, raw)
        r["ts"].set(g, np.nan if sample is None else sample.timestamp)
        r["received"].set(g, np.nan if sample is None else sample.received)
        r["pos"].set(g, frame.positions_m)
        r["vel"].set(g, frame.velocities_m_s)
        r["acc"].set(g, frame.accelerations_m_s2)
        if blank:
            return
        if sample is None:
            self.n_dropped += 1
            self.dropped_run += 1
        elif self.dropped_run:
            self._event("dropped", g - self.dropped_run, f"{self.dropped_run} frame(s) never came "
                        f"(frames {g - self.dropped_run}..{g - 1}); springs off there")
            self.dropped_run = 0
        self._track_gaps(g, frame.present, sample is None)

    def _track_gaps(self, g: int, present: np.ndarray, dropped: bool) -> None:
        """Gaps of single markers (not whole missing frames) reported by marker name."""
        names = self.marker_names
        if dropped:
            return
        for j in np.flatnonzero(~present & ~self.in_gap & self.in_stream):
            self.in_gap[j] = True
            self.gap_start[j] = g
            self._event("gap", g, f"marker {names[j]} missing: its spring is off", (names[j],))
        for j in np.flatnonzero(present & self.in_gap):
            self.in_gap[j] = False
            self.gaps.append(Gap(names[j], int(self.gap_start[j]), g))
            self._event("gap_end", g, f"marker {names[j]} back after {(g - self.gap_start[j]) / self.rate:.2f} s "
                        f"({g - self.gap_start[j]} frames)", (names[j],))

    def _frame(self, g: int) -> tuple[CausalFrame, np.ndarray]:
        raw, sample = self._next_raw(g)
        frame = self.causal.push(raw)
        self._record_input(g, raw, sample, frame)
        self.current_sample = sample
        active = frame.present & ~self.quarantine
        self.rec["active"].set(g, active)
        return frame, active

    # ------------------------------------------------------------------ outputs
    def _empty(self, g: int, status: FrameStatus = FrameStatus.TOO_FEW_MARKERS) -> None:
        """A frame no PF run holds (before a run starts, a failed frame): published and recorded empty."""
        self._publish(g, None, None)
        self._record_output(g, None, status)

    def _publish(self, g: int, q: np.ndarray | None, measured_m: np.ndarray | None) -> tuple:
        """The frame's output row: the ISB angles of q, their rates (backward differences of the
        published angles), the measured flags, the residuals, the running verdict."""
        k = len(self.marker_names)
        if q is not None:
            isb = self._isb(q)
            rate = (isb - self.last_isb_row) * self.rate if self.last_isb_row is not None else np.zeros_like(isb)
            self.last_isb_row = isb
            pts = self.kin.points(q[None], self.points)[0]
            res = np.linalg.norm(pts - measured_m, axis=1)
        else:
            isb = rate = np.full(len(ISB_NAMES), np.nan)
            res = np.full(k, np.nan)
            pts = None
            self.last_isb_row = None
        self.out_isb = isb
        behind = (self.queue[-1].index - g) if self.queue else 0
        sample = self.current_sample
        ts = np.nan if sample is None else sample.timestamp
        ok = np.isfinite(res)
        mean_res = float(res[ok].mean()) * 1e3 if ok.any() else np.nan
        self.out_mean_res, self.out_behind = mean_res, behind
        if behind > self.behind_frames and not self.is_behind and not math.isinf(self.max_behind):  # (no clock offline)
            self.is_behind = True
            self._event("behind", g, f"{behind} frames ({behind / self.rate * 1e3:.0f} ms) behind the stream: "
                        f"catching up (every frame processed; skipped beyond {self.options.max_behind_s:g} s)")
        elif behind <= 1 and self.is_behind:
            self.is_behind = False
            self._event("caught_up", g, "caught up with the stream")
        if self.publish is not None:
            row = np.concatenate([np.degrees(isb), np.degrees(rate), self.measured.astype(float), res * 1e3,
                                  [mean_res, VERDICT_CODES[self.quality.verdict], float(q is not None), behind, g, ts]])
            self.publish(row, ts)
        now = self.clock()
        self.rec["published"].set(g, now)
        if sample is not None:
            self.latency.append(now - sample.received)
        self.rec["isb"].set(g, isb)
        self.rec["isb_rate"].set(g, rate)
        self.rec["measured"].set(g, self.measured)
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
            motion = _Motion(np.concatenate([b[2].angular_velocities_rad_s for b in batch]),
                             np.concatenate([b[2].angular_accelerations_rad_s2 for b in batch]))
            q, qd, qdd = frames.rates(q, motion)
        targets = MarkerTargets(time_s=np.array(gs) / self.rate, marker_names=self.marker_names,
                                positions_m=np.stack([b[3].positions_m for b in batch]),
                                velocities_m_s=np.stack([b[3].velocities_m_s for b in batch]),
                                accelerations_m_s2=np.stack([b[3].accelerations_m_s2 for b in batch]))
        recon = frames.finish(q, qd, qdd, targets)  # diverged frames never get here (checked at publishing)
        for i, g in enumerate(gs):
            self._record_output(g, (recon.q_rad[i], recon.qd_rad_s[i], recon.qdd_rad_s2[i], recon.model_points_m[i],
                                    recon.residuals_m[i], recon.constraint[i], recon.constraint_velocity[i]))

    def _diverged(self, g: int, q: np.ndarray, res: np.ndarray, present: np.ndarray) -> str:
        """Why the run diverged at this frame ("" if not): exubio.methods.pf's criterion, a spring
        longer than divergence_deflection_m or angles that are not finite."""
        if not np.isfinite(q).all():
            return f"the PF solution is not finite at t = {g / self.rate:.3f} s"
        limit = self.options.pf.divergence_deflection_m
        bad = present & ~(res <= limit)
        if bad.any():
            j = int(np.flatnonzero(bad)[np.argmax(res[bad])])
            return (f"the PF run diverged at t = {g / self.rate:.3f} s: spring '{self.marker_names[j]}' is "
                    f"{res[j] * 1e3:.0f} mm long (limit {limit * 1e3:.0f} mm)")
        return ""

    def _record_output(self, g: int, out: tuple | None,
                       status: FrameStatus = FrameStatus.TOO_FEW_MARKERS) -> None:
        r = self.rec
        if out is not None:
            q, qd, qdd, points, res, con, conv = out
            r["q"].set(g, q)
            r["qd"].set(g, qd)
            r["qdd"].set(g, qdd)
            r["points"].set(g, points)
            r["res"].set(g, res)
            r["g"].set(g, con)
            r["gv"].set(g, conv)
            r["status"].set(g, int(FrameStatus.CONVERGED))
            r["run"].set(g, self.run_id)
            self._determinacy(g, q)
            self._running(g, q, res)
        else:
            r["status"].set(g, int(status))
            r["run"].set(g, -1)
            if status == FrameStatus.NOT_CONVERGED:
                self.n_failed += 1
            else:
                self.n_no_state += 1
        self.n_frames = g + 1
        if self.verdict_due <= g:
            self._verdict(g)
        r["verdict"].set(g, VERDICT_CODES[self.quality.verdict])
        now = self.clock()
        if self.on_status is not None and now >= self.status_due:
            self.status_due = now + self.status_every_s
            self.on_status(self._status(g, self.out_isb, self.out_mean_res, self.out_behind))

    def _isb(self, q: np.ndarray) -> np.ndarray:
        """The ISB angles of q (15,), unwrapped against the previous frame."""
        _, table = isb_table(self.model, q, kinematics=self.kin, frames=self.anatomical)
        ang = table
        if self.last_isb is not None:
            ang = self.last_isb + (ang - self.last_isb + np.pi) % (2 * np.pi) - np.pi
        self.last_isb = ang
        return ang

    def _determinacy(self, g: int, q: np.ndarray) -> None:
        if g < self.det_due:
            return
        self.det_due = g + self.det_every
        present = self.rec["active"].a[g][None]
        det = determinacy(self.kin, self.points, q[None], present, self.protocol.weights, excluded=self.excluded)
        und = [n for n, u in zip(self.model.coordinate_names, det.undetermined[0] & ~det.near_gimbal_lock[0]) if u]
        self.measured = angles_measured(self.model, self.not_solved, und, unmeasurable=self.unmeasurable,
                                        structural=self.structural)
        self.undetermined_frames += det.undetermined[0]

    def _label_check(self, g: int, res: np.ndarray, pts: np.ndarray, meas: np.ndarray) -> None:
        """A swapped pair: both far from their own model points, each close to the other's (residuals
        res (k,), model points and measured positions (k, 3) of this frame)."""
        far = np.flatnonzero(res > LABEL_SWAP_MIN_MM * 1e-3)
        seen = set()
        for a_i, a in enumerate(far):
            for b in far[a_i + 1:]:
                swapped = np.linalg.norm(pts[a] - meas[b]) + np.linalg.norm(pts[b] - meas[a])
                if swapped < LABEL_SWAP_RATIO * (res[a] + res[b]):
                    seen.add((int(a), int(b)))
        for pair in list(self.swap_count):
            if pair not in seen and pair not in self.swapped:
                del self.swap_count[pair]
        names = self.marker_names
        for pair in seen:
            self.swap_count[pair] = self.swap_count.get(pair, 0) + 1
            if self.swap_count[pair] >= LABEL_SWAP_FRAMES and pair not in self.swapped:
                self.swapped[pair] = g
                self.quarantine[list(pair)] = True
                self._event("label_swap", g, f"markers {names[pair[0]]} and {names[pair[1]]} look swapped "
                            f"({res[pair[0]] * 1e3:.0f} and {res[pair[1]] * 1e3:.0f} mm from their model points, "
                            f"{LABEL_SWAP_FRAMES} frames in a row): both springs off", (names[pair[0]], names[pair[1]]))
        for pair, since in list(self.swapped.items()):
            a, b = pair
            if res[a] < LABEL_SWAP_MIN_MM * 1e-3 and res[b] < LABEL_SWAP_MIN_MM * 1e-3:
                del self.swapped[pair]
                self.swap_count.pop(pair, None)
                self.quarantine[[a, b]] = False
                self._event("label_swap_end", g, f"markers {names[a]} and {names[b]} fit their model points again "
                            f"(swapped for {(g - since) / self.rate:.2f} s): springs on", (names[a], names[b]))

    def _running(self, g: int, q: np.ndarray, res: np.ndarray) -> None:
        ok = np.isfinite(res)
        self.res_sum += np.where(ok, res, 0.0)
        self.res_sq += np.where(ok, res * res, 0.0)
        self.res_n += ok
        self.frame_means.append(float(res[ok].mean()) * 1e3 if ok.any() else np.nan)
        lo, hi = self.ranges[:, 0], self.ranges[:, 1]
        at = ((q >= hi - AT_LIMIT_TOLERANCE_RAD) | (q <= lo + AT_LIMIT_TOLERANCE_RAD)) & ~self.excluded
        if at.any():
            beyond = np.maximum(np.maximum(q - hi, lo - q), 0.0)
            for j in np.flatnonzero(at):
                if self.lim_count[j] == 0:
                    self.lim_first[j] = g
                self.lim_count[j] += 1
                self.lim_beyond[j] = max(self.lim_beyond[j], beyond[j])

    def _verdict(self, g: int) -> None:
        """The running verdict: the criteria of exubio.trust.quality on the frames so far, plus what the
        live loop saw (stalls, restarts, skips, label swaps)."""
        self.verdict_due = g + self.verdict_every
        n = g + 1
        reasons: list[Q.Reason] = list(self.calibration_reasons)
        if self.res_n.any():
            with np.errstate(all="ignore"):
                rmse = np.sqrt(self.res_sq / self.res_n) * 1e3
            stats = {"mean": float(self.res_sum.sum() / self.res_n.sum()) * 1e3,
                     "per_marker_rmse": {m: (None if self.res_n[j] == 0 else float(rmse[j]))
                                         for j, m in enumerate(self.marker_names)}}
            reasons += Q.residual_reasons(stats, np.asarray(self.frame_means))
        names = self.model.coordinate_names
        lims = [{"coordinate": names[j], "range_deg": [float(np.degrees(self.ranges[j, 0])), float(np.degrees(self.ranges[j, 1]))],
                 "frames_at_limit": int(self.lim_count[j]), "first_frame": int(self.lim_first[j]),
                 "max_beyond_deg": float(np.degrees(self.lim_beyond[j]))} for j in np.flatnonzero(self.lim_count)]
        reasons += Q.limit_reasons(lims, n, not_measured=self.unmeasurable)  # as the offline assessment
        open_gaps = [Gap(self.marker_names[j], int(self.gap_start[j]), n) for j in np.flatnonzero(self.in_gap)]
        reasons += Q.gap_reasons(self.gaps + open_gaps, n, self.rate)
        reasons += Q.convergence_reasons({"not_converged": self.n_failed, "too_few_markers": self.n_no_state}, n)
        names_m = self.marker_names
        for (a, b), since in self.swapped.items():
            reasons.append(Q.Reason("label", "fail", f"markers {names_m[a]} and {names_m[b]} look swapped since "
                                    f"t = {since / self.rate:.2f} s (springs off)"))
        if self.n_dropped:
            reasons.append(Q.Reason("live_dropped", "note", f"{self.n_dropped} frame(s) never came (springs off there; "
                                    "see the events)"))
        if self.n_late:
            reasons.append(Q.Reason("live_late", "note", f"{self.n_late} sample(s) came late and were dropped"))
        if self.n_skipped:
            reasons.append(Q.Reason("live_skip", "check", f"{self.n_skipped} frames skipped: the solver fell more than "
                                    f"{self.options.max_behind_s:g} s behind"))
        restarts = sum(1 for e in self.events if e.kind in ("restart", "diverged"))
        if restarts:
            reasons.append(Q.Reason("live_restart", "note", f"{restarts} PF run(s) restarted from the LS pose "
                                    "(stream restarted or diverged)"))
        quality = Q.Quality.of(reasons)
        if quality.verdict != self.quality.verdict:
            self._event("verdict", g, f"{quality.verdict}" + (f": {quality.reasons[0].message}" if quality.reasons else ""))
        self.quality = quality

    def _status(self, g: int, isb: np.ndarray, mean_res: float, behind: int) -> dict:
        lat = np.asarray(self.latency[-200:]) * 1e3
        key = {n: float(np.degrees(isb[ISB_NAMES.index(n)])) for n in ("HT_X_elevation", "GH_X_elevation",
                                                                      "ST_X_upward_rotation", "GH_Y_internal_rotation")}
        return {"frame": g, "time_s": g / self.rate, "latency_ms_p50": float(np.median(lat)) if lat.size else np.nan,
                "latency_ms_max": float(lat.max()) if lat.size else np.nan, "frames_behind": int(behind),
                "residual_mean_mm": mean_res, "verdict": self.quality.verdict,
                "reason": self.quality.reasons[0].message if self.quality.reasons else "",
                "angles_deg": key, "dropped": self.n_dropped, "late": self.n_late, "skipped": self.n_skipped,
                "tracking": self.tracking, "gaps": [self.marker_names[j] for j in np.flatnonzero(self.in_gap)]}

    # ------------------------------------------------------------------ PF runs
    def _start_run(self, g: int) -> int | None:
        """Find the first frame from g with a static equilibrium of the springs and start a PF run
        there; returns the frame it starts on (None at the end)."""
        while True:
            try:
                frame, active = self._frame(g)
            except _EndRun:
                g = self.queue[0].index if self.queue else g
                for i in range(self.n_frames, g):
                    self._blank(i)
                continue
            targets = MarkerTargets(time_s=np.array([0.0]), marker_names=self.marker_names,
                                    positions_m=np.where(active[:, None], frame.positions_m, np.nan)[None],
                                    velocities_m_s=frame.velocities_m_s[None],
                                    accelerations_m_s2=frame.accelerations_m_s2[None], source=self.info.name)
            if active.sum() >= self.min_markers:
                try:
                    self.setup = pf_setup(self.model, self.protocol, targets, self.options.pf, kin=self.kin)
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
        self.rec["active"].set(g, frame.present)
        self._empty(g)

    def _run_pf(self, g0: int) -> int:
        """One PF run from frame g0 until it must end; returns the next frame to start from."""
        setup = self.setup
        frames = _Frames(setup.kin, setup.points, None, setup.q0, setup.held, self.options.pf, None, 1.0 / self.rate)
        self.run_id += 1
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
                except _EndRun:
                    state["end"] = "hole"
                    return None
                except StopIteration:
                    state["end"] = "stream"
                    return None
            state["idle"] = 0 if active.any() else state["idle"] + 1
            if state["idle"] > self.coast_frames:
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
            q = frames.coordinates(part)
            rates = frames.rates(q, part) if projected else None  # the published angles are the projected ones
            if rates is not None:
                q = rates[0]
            res, pts = self._publish(g, q[0], frame.positions_m)
            why = self._diverged(g, q[0], res, frame.present)
            if why:
                self._flush(frames)
                self._event("diverged", g, f"{why}; the PF run restarts from the LS pose")
                state["end"] = "diverged"
                self._record_output(g, None, FrameStatus.NOT_CONVERGED)
                return
            self._label_check(g, res, pts, frame.positions_m)
            state["last"] = g
            self.deferred.append((g, q, part, frame, rates))
            if len(self.deferred) >= DEFER_FRAMES:
                self._flush(frames)

        projected = self.options.pf.project_constraints
        from exubio.backend.exudyn_system import IntegratorOptions

        pf = self.options.pf
        integ = IntegratorOptions(step_s=None, spectral_radius=pf.spectral_radius,
                                  newton_relative_tolerance=pf.newton_relative_tolerance,
                                  modified_newton=pf.modified_newton, timing_breakdown=False)
        self.frames_state = frames
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
        if state["end"] == "hole" and self.queue:
            nxt = self.queue[0].index
            if not self._restarted and nxt - (state["last"] + 1) > self.coast_frames:
                self._event("run_end", state["last"] + 1, f"{nxt - state['last'] - 1} frames "
                            f"({(nxt - state['last'] - 1) / self.rate:.2f} s) without samples, more than "
                            f"{self.options.max_coast_s:g} s: the PF run ends")
            self._restarted = False
            for i in range(self.n_frames, nxt):
                self._blank(i)
            return nxt
        return self.n_frames

    # ------------------------------------------------------------------ the session
    def _open(self) -> None:
        info = self.source.open(self.options.open_timeout_s)
        self.info, self.rate = info, float(info.rate_hz)
        self.labels, self.n_labels, self.scale = info.labels, len(info.labels), UNIT_SCALE[info.units]
        self.events: list[Event] = []
        self.queue: collections.deque[_Sample] = collections.deque()
        self.t_first: float | None = None
        self.last_ts = -math.inf
        self.last_index = -1
        self.restart_pad = int(math.ceil(self.options.max_coast_s * self.rate)) + 1
        self._restart_pending: int | None = None
        self._restarted = False
        self.last_arrival = self.last_pull = self.clock()
        self.stalled = False
        self.ended_by = ""
        self.n_late = self.n_dropped = self.n_skipped = self.n_failed = self.n_no_state = 0
        self.dropped_run = 0
        self.n_stepped = 0
        self.coast_frames = max(int(round(self.options.max_coast_s * self.rate)), 1)
        self.max_behind = (math.inf if math.isinf(self.options.max_behind_s)
                           else max(int(round(self.options.max_behind_s * self.rate)), 1))

    def _bind(self) -> None:
        from exubio.model.kinematics import Kinematics
        from exubio.methods.common import tracked_points

        self.causal = CausalTargets(self.protocol, self.labels, self.rate, options=self.options.causal,
                                    source=self.info.name)
        if self.causal.unused:
            log.info("%s: labels not used by protocol '%s': %s", self.info.name, self.protocol.name, list(self.causal.unused))
        self.marker_names = self.protocol.marker_names
        k, m = len(self.marker_names), self.model.n_coordinates
        self.kin = Kinematics(self.model)
        self.points = tracked_points(self.kin, self.protocol)
        self.excluded = not_solved_mask(self.model, self.protocol, self.kin)
        self.not_solved = tuple(n for n, e in zip(self.model.coordinate_names, self.excluded) if e)
        from exubio.trust.assess import angle_status_of_protocol, coordinates_not_measured_by_protocol

        self.unmeasurable = coordinates_not_measured_by_protocol(self.model, self.protocol, kin=self.kin)
        self.structural = angle_status_of_protocol(self.model, self.protocol, kin=self.kin)  # once, not per frame
        self.measured = angles_measured(self.model, self.not_solved, unmeasurable=self.unmeasurable,
                                        structural=self.structural)
        self.ranges = self.model.coordinate_ranges_rad
        self.min_markers = 3
        L = self.n_labels
        self.rec = {"raw": _Growing((L, 3)), "ts": _Growing(()), "received": _Growing(()), "published": _Growing(()),
                    "pos": _Growing((k, 3)), "vel": _Growing((k, 3), 0.0), "acc": _Growing((k, 3), 0.0),
                    "active": _Growing((k,), False, bool), "q": _Growing((m,)), "qd": _Growing((m,)),
                    "qdd": _Growing((m,)), "points": _Growing((k, 3)), "res": _Growing((k,)), "g": _Growing((2,)),
                    "gv": _Growing((2,)), "status": _Growing((), int(FrameStatus.TOO_FEW_MARKERS), int),
                    "run": _Growing((), -1, int), "isb": _Growing((len(ISB_NAMES),)),
                    "isb_rate": _Growing((len(ISB_NAMES),)), "measured": _Growing((len(ISB_NAMES),), False, bool),
                    "verdict": _Growing((), 0, int)}
        self.quarantine = np.zeros(k, dtype=bool)
        self.swap_count: dict = {}
        self.swapped: dict = {}
        self.in_gap = np.zeros(k, dtype=bool)
        self.in_stream = self.causal.columns >= 0  # optional markers the stream does not carry: no gap events
        self.gap_start = np.zeros(k, dtype=int)
        self.gaps: list[Gap] = []
        self.pending: dict[int, tuple] = {}  # frame -> (CausalFrame, its sample) taken, not yet solved
        self.deferred: list = []
        self.latency: list[float] = []
        self.res_sum, self.res_sq, self.res_n = np.zeros(k), np.zeros(k), np.zeros(k, dtype=int)
        self.frame_means: list[float] = []
        self.lim_count, self.lim_first, self.lim_beyond = np.zeros(m, dtype=int), np.zeros(m, dtype=int), np.zeros(m)
        self.undetermined_frames = np.zeros(m, dtype=int)
        self.quality = Q.Quality.of([])
        self.verdict_every = max(int(round(self.options.verdict_every_s * self.rate)), 1)
        self.verdict_due = self.verdict_every - 1
        self.det_every = max(int(round(DETERMINACY_PERIOD_S * self.rate)), 1)
        self.det_due = 0
        self.run_id = -1
        self.run_started = self.clock()
        self.is_behind = False
        self.behind_frames = max(int(round(BEHIND_REPORT_S * self.rate)), 2)
        self.n_frames = 0
        self.tracking = False
        self.last_isb = None
        self.last_isb_row = None
        from exubio.model.angles import anatomical_frames

        self.anatomical = anatomical_frames(self.model)
        self.current_sample = None
        self.status_due = 0.0

    def _calibrate_from_stream(self) -> Any:
        """Buffer the static frames, calibrate the model on them (their raw samples), and rebind."""
        sl = self.static_frames
        stop = sl.stop
        raws: list[np.ndarray] = []
        while len(raws) < stop:
            if not self.queue and not self._wait_for_sample():
                raise InputError(f"{self.info.name}: the stream ended after {len(raws)} frames, before the "
                                 f"{stop} static frames (--static-frames) were in")
            s = self.queue[0]
            while len(raws) < min(s.index, stop):
                raws.append(np.full((self.n_labels, 3), np.nan))
            if len(raws) < stop:
                raws.append(s.raw)
            if s.index < stop:
                self.queue.popleft()
                self._held_back.append(s)
        traj = Trajectories(labels=self.labels, positions_m=np.array(raws), rate_hz=self.rate,
                            time_s=np.arange(len(raws)) / self.rate, source=self.info.name, units_in_file=self.info.units)
        model, protocol, report = self.calibrate(traj, sl)
        self.model, self.protocol = model, protocol
        self.queue.extendleft(reversed(self._held_back))
        return report

    def _check_units(self) -> None:
        """The unit trap, on the first frames that have markers (exubio.prep.targets does it offline)."""
        got = [s.raw for s in list(self.queue)[:50]]
        if not got:
            return
        pos = np.array([self.causal.thorax_positions(r) for r in got])
        self.causal.restart()
        d = np.linalg.norm(pos, axis=2)
        d = d[np.isfinite(d)]
        lo, hi = PLAUSIBLE_MEDIAN_DISTANCE_M
        if d.size and not lo <= float(np.median(d)) <= hi:
            raise InputError(f"{self.info.name}: the median marker distance from the thorax origin is "
                             f"{float(np.median(d)):.4g} m, expected {lo}-{hi} m; the stream declares its positions "
                             f"in '{self.info.units}': check the units")

    def run(self) -> LiveRecording:
        """Run until the stream ends or ``stop()``; returns the recording (also after Ctrl-C)."""
        self._open()
        self._held_back: list[_Sample] = []
        self.calibration_reasons: list[Q.Reason] = []
        report = None
        if self.static_frames is None:
            self._bind()  # before the first sample: the stream's start is not kept waiting
            if self.on_ready is not None:
                self.on_ready(self)
        if not self._pull(1.0) or not self.queue:
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

            self.calibration_reasons = Q.calibration_reasons(  # as exubio.trust.assess does for the recording
                report, scale_bounds=SCALE_BOUNDS, off_segment=Q.off_segment_markers(self.model, self.protocol))
            if self.on_ready is not None:
                self.on_ready(self)
        self._check_units()
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
        if self.dropped_run:
            self._event("dropped", self.n_frames - self.dropped_run, f"{self.dropped_run} frame(s) never came")
        if self.n_frames:
            self._verdict(self.n_frames - 1)
        self._event("end", self.n_frames, f"{self.ended_by}: {self.n_frames} frames, verdict {self.quality.verdict}")
        return self._recording(report)

    def _recording(self, report: Any) -> LiveRecording:
        n = self.n_frames
        r = {key: arr.view() for key, arr in self.rec.items()}
        for arr in self.rec.values():
            arr.grow_to(n)
        r = {key: arr.view(n).copy() for key, arr in self.rec.items()}
        lat = np.asarray(self.latency) * 1e3
        stats = {"frames": n, "dropped": self.n_dropped, "late": self.n_late, "skipped": self.n_skipped,
                 "failed": self.n_failed, "no_pf_state": self.n_no_state, "runs": self.run_id + 1,
                 "cpu_ms_per_frame": 1e3 * self.cpu_s / max(self.n_stepped, 1),
                 "cpu_definition": "the process's CPU time (solver, bookkeeping, LSL threads; waiting excluded) per "
                                   "frame PF stepped through (skipped frames cost nothing)",
                 "loop_latency_ms": {"p50": float(np.percentile(lat, 50)) if lat.size else None,
                                     "p99": float(np.percentile(lat, 99)) if lat.size else None,
                                     "max": float(lat.max()) if lat.size else None,
                                     "definition": "from taking a sample off the source to publishing its angles"}}
        return LiveRecording(
            info=self.info, model=self.model, protocol=self.protocol, options=self.options,
            marker_names=self.marker_names, raw_m=r["raw"], timestamps_s=r["ts"], received_s=r["received"],
            published_s=r["published"], positions_m=r["pos"], velocities_m_s=r["vel"], accelerations_m_s2=r["acc"],
            active=r["active"], q_rad=r["q"], qd_rad_s=r["qd"], qdd_rad_s2=r["qdd"], model_points_m=r["points"],
            residuals_m=r["res"], constraint=r["g"], constraint_velocity=r["gv"], status=r["status"], run=r["run"],
            isb_rad=r["isb"], isb_rate_rad_s=r["isb_rate"], measured=r["measured"], verdict=r["verdict"],
            events=list(self.events), live_quality=self.quality, ended_by=self.ended_by, calibration=report,
            stats=stats)


def reconstruct_causal(trial: Trajectories, model: Model, protocol: Protocol, /, *,
                       options: LiveOptions = LiveOptions(), static_frames: slice | None = None,
                       calibrate: Callable | None = None, faults=None) -> LiveRecording:
    """The offline causal PF reconstruction of a trial: the live loop itself, fed by an in-process
    replay of the trial as fast as it goes (no network, no clock), so ``exubio live`` on a replay of
    the same trial gives the same angles (to round-off: the same operations on the same numbers)."""
    from exubio.run.live.sources import Faults

    source = ReplaySource(trial, speed=None, faults=faults or Faults())
    opts = dataclasses.replace(options, end_after_s=None, max_behind_s=math.inf, stall_s=math.inf)  # no clock
    return LiveSession(model, protocol, source, options=opts, static_frames=static_frames,
                       hooks=SessionHooks(calibrate=calibrate)).run()
