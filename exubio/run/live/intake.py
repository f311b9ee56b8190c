"""The marker stream's samples taken in by a live session (SampleIntake): the source opened, its
samples pulled into a queue, each placed on the stream's uniform frame grid by its timestamp
(exubio.run.live.loop's docstring says how), late and duplicate samples dropped, frames that never
came counted, a restarted sender, a stall, a hole and a backlog to skip noticed, the static frames
of a calibration buffered, and the unit trap checked on the first frames."""
from __future__ import annotations

import collections
import math
import threading
from typing import TYPE_CHECKING, Callable

import numpy as np

from exubio.errors import InputError
from exubio.run.live.causal import CausalTargets, frame_index
from exubio.run.live.sources import UNIT_SCALE, MarkerSource
from exubio.prep.targets import PLAUSIBLE_MEDIAN_DISTANCE_M

if TYPE_CHECKING:
    from exubio.run.live.options import LiveOptions

__all__ = ["SampleIntake", "Sample", "EndRun", "PULL_EVERY_S", "BEHIND_REPORT_S"]

PULL_EVERY_S = 0.005
"""The source's own buffer is drained at least this often while frames are processed, so a backlog
that waits there (an LSL inlet's) is seen and counted."""
BEHIND_REPORT_S = 0.05
"""A backlog longer than this (50 ms: a tenth of the skip limit) is reported as an event (once, until
caught up); every frame's output carries the backlog anyway."""


class EndRun(Exception):
    """The current PF run must end at this frame (a hole, a restarted sender, a skipped backlog)."""


class Sample:
    __slots__ = ("index", "timestamp", "raw", "received")

    def __init__(self, index, timestamp, raw, received):
        self.index, self.timestamp, self.raw, self.received = index, timestamp, raw, received


class SampleIntake:
    """The samples of ``source`` (opened here, within ``options.open_timeout_s``) in ``queue``, in
    frame order: ``info``, ``rate``, ``labels`` and ``scale`` (to m) are the stream's; ``last_index``
    the last frame taken off the queue or recorded, ``n_late`` the samples dropped as late,
    ``n_dropped`` the frames that never came, ``n_skipped`` the frames skipped behind,
    ``stalled`` whether a stall was reported and not yet ended, ``restart_pending`` the frame where
    a restarted sender's samples begin (``restarted`` once the frame was reached, until the session
    starts the next PF run). ``coast_frames`` and ``max_behind``: ``max_coast_s`` and
    ``max_behind_s`` in frames. ``clock``: the session's; ``event(kind, frame, message)``: its event
    report."""

    def __init__(self, source: MarkerSource, options: "LiveOptions", clock: Callable[[], float],
                 event: Callable[..., None]):
        self.source, self.options, self.clock, self._event = source, options, clock, event
        info = source.open(options.open_timeout_s)
        self.info, self.rate = info, float(info.rate_hz)
        self.labels, self.n_labels, self.scale = info.labels, len(info.labels), UNIT_SCALE[info.units]
        self.queue: collections.deque[Sample] = collections.deque()
        self.t_first: float | None = None
        self.last_ts = -math.inf
        self.last_index = -1
        self.restart_pad = int(math.ceil(options.max_coast_s * self.rate)) + 1
        self.restart_pending: int | None = None
        self.restarted = False
        self.last_arrival = self.last_pull = self.clock()
        self.stalled = False
        self.n_late = self.n_dropped = self.n_skipped = 0
        self.dropped_run = 0
        self.coast_frames = max(int(round(options.max_coast_s * self.rate)), 1)
        self.max_behind = (math.inf if math.isinf(options.max_behind_s)
                           else max(int(round(options.max_behind_s * self.rate)), 1))
        self.is_behind = False
        self.behind_frames = max(int(round(BEHIND_REPORT_S * self.rate)), 2)
        self._held_back: list[Sample] = []

    def pull(self, timeout_s: float) -> bool:
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
                self.restart_pending = idx
            if idx <= last:
                self.n_late += 1
                if self.n_late <= 3 or self.n_late % 100 == 0:
                    self._event("late", idx, f"a sample for frame {idx} came after frame {last} ({self.n_late} so far); dropped")
                continue
            self.last_ts = ts
            self.queue.append(Sample(idx, ts, raw, now))
            self.last_arrival = now
        return True

    def wait(self, stop: threading.Event, *, first: bool = False) -> str:
        """Block until a sample is queued; "" then, else why not: the stream ended or the session
        stops (``stop`` set); the first sample is waited for ``open_timeout_s``, later ones
        ``end_after_s``."""
        limit = self.options.open_timeout_s if first else self.options.end_after_s
        while not self.queue:
            if stop.is_set():
                return "stopped"
            silent = self.clock() - self.last_arrival
            ended = limit is not None and silent > limit
            if ended or (silent > self.options.stall_s and not self.stalled):
                if not self.pull(0.0):  # what waits in the source's buffer is no silence
                    return "end of stream"
                if self.queue:
                    break
                if ended:
                    return f"no sample for {limit:g} s"
                self.stalled = True
                self._event("stall", self.last_index + 1, f"no sample for {silent:.2f} s")
            if not self.pull(0.02):
                return "end of stream"
        return ""

    def next_raw(self, g: int, *, wait: Callable[[], bool], restart: Callable[[], None],
                 may_skip: Callable[[], bool]) -> tuple[np.ndarray, Sample | None]:
        """The raw frame g: its sample, or all-missing if it never came. Raises EndRun where the
        current PF run must end (a hole longer than max_coast_s, a restart, a skipped backlog) and
        StopIteration at the end. ``wait()``: the session's wait for a sample (False at the end);
        ``restart()``: called at a restart (the causal filter starts again); ``may_skip()``: whether
        a backlog may be skipped now."""
        queue = self.queue
        if queue and self.clock() - self.last_pull > PULL_EVERY_S:  # what waits in the source's buffer
            self.pull(0.0)  # counts as backlog too (an empty queue: wait() pulls)
        if not queue and not wait():
            raise StopIteration
        head = queue[0]
        if self.stalled:
            self.stalled = False
            self._event("resumed", head.index, f"samples again after {head.index - g} missing frame(s)")
        if self.restart_pending is not None and head.index >= self.restart_pending:
            self.restart_pending = None
            self.restarted = True
            self._event("restart", head.index, "the stream's timestamps went back (the sender restarted); "
                        f"frames {g}..{head.index - 1} missing, the PF run restarts from the LS pose")
            restart()
            raise EndRun
        behind = queue[-1].index - g
        if behind > self.max_behind and may_skip():
            newest = queue[-1]
            self._event("skip", g, f"{behind} frames ({behind / self.rate:.2f} s) behind, more than "
                        f"{self.options.max_behind_s:g} s: frames {g}..{newest.index - 1} skipped, a new PF run "
                        f"starts at frame {newest.index}")
            queue.clear()
            queue.append(newest)
            self.n_skipped += newest.index - g
            raise EndRun
        if head.index > g:
            if head.index - g > self.coast_frames:
                raise EndRun
            return np.full((self.n_labels, 3), np.nan), None
        return queue.popleft().raw, head

    def backlog(self, g: int) -> int:
        """The frames queued beyond frame g (its output is published now); a backlog beyond
        BEHIND_REPORT_S is reported (once, until caught up)."""
        queue = self.queue
        behind = (queue[-1].index - g) if queue else 0
        if behind > self.behind_frames and not self.is_behind and not math.isinf(self.max_behind):  # (no clock offline)
            self.is_behind = True
            self._event("behind", g, f"{behind} frames ({behind / self.rate * 1e3:.0f} ms) behind the stream: "
                        f"catching up (every frame processed; skipped beyond {self.options.max_behind_s:g} s)")
        elif behind <= 1 and self.is_behind:
            self.is_behind = False
            self._event("caught_up", g, "caught up with the stream")
        return behind

    def taken(self, g: int, sample: Sample | None, *, blank: bool = False) -> None:
        """Frame g is recorded with its ``sample`` (None: it never came, counted as dropped unless
        ``blank``: no PF run holds it); a run of dropped frames is reported where it ends."""
        self.last_index = max(self.last_index, g)
        if blank:
            return
        if sample is None:
            self.n_dropped += 1
            self.dropped_run += 1
        elif self.dropped_run:
            self._event("dropped", g - self.dropped_run, f"{self.dropped_run} frame(s) never came "
                        f"(frames {g - self.dropped_run}..{g - 1}); springs off there")
            self.dropped_run = 0

    def static_frames(self, stop: int, wait: Callable[[], bool]) -> np.ndarray:
        """The raw frames 0..stop-1 (NaN where none came), for a calibration: the samples are held
        back until ``put_back()``; ``wait()``: the session's wait for a sample."""
        raws: list[np.ndarray] = []
        queue = self.queue
        while len(raws) < stop:
            if not queue and not wait():
                raise InputError(f"{self.info.name}: the stream ended after {len(raws)} frames, before the "
                                 f"{stop} static frames (--static-frames) were in")
            s = queue[0]
            while len(raws) < min(s.index, stop):
                raws.append(np.full((self.n_labels, 3), np.nan))
            if len(raws) < stop:
                raws.append(s.raw)
            if s.index < stop:
                queue.popleft()
                self._held_back.append(s)
        return np.array(raws)

    def put_back(self) -> None:
        """The samples static_frames held back, queued again (every frame is reconstructed)."""
        self.queue.extendleft(reversed(self._held_back))

    def check_units(self, causal: CausalTargets) -> None:
        """The unit trap, on the first frames that have markers (exubio.prep.targets does it offline)."""
        got = [s.raw for s in list(self.queue)[:50]]
        if not got:
            return
        pos = np.array([causal.thorax_positions(r) for r in got])
        causal.restart()
        d = np.linalg.norm(pos, axis=2)
        d = d[np.isfinite(d)]
        lo, hi = PLAUSIBLE_MEDIAN_DISTANCE_M
        if d.size and not lo <= float(np.median(d)) <= hi:
            raise InputError(f"{self.info.name}: the median marker distance from the thorax origin is "
                             f"{float(np.median(d)):.4g} m, expected {lo}-{hi} m; the stream declares its positions "
                             f"in '{self.info.units}': check the units")
