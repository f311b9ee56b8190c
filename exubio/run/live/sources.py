"""Where live marker frames come from: a small source interface, and the in-process replay of a
trial (no network: most tests and the offline causal run use it).

A source is opened once (``open``: the stream's labels, rate and units) and then pulled
(``pull(timeout_s)``: the samples that have arrived, each a (timestamp_s, positions (n_labels, 3) m)
pair, NaN where a marker is missing; an empty list when none came within the timeout; None at the
end of the stream). Timestamps are on the sender's clock: the live loop places each sample on the
stream's uniform frame grid from them (exubio.run.live.loop), so dropped, late and out-of-order samples
and a restarted stream are seen there, whatever the transport.

Plugging in another system: a class with these four methods. The LSL source is
exubio.run.live.transport.LSLSource; a Qualisys source would wrap ``qtm_rt`` (``connect``,
``stream_frames(components=["3d"], on_packet=...)``: labels from ``get_parameters(["3d"])``, mm,
its frame number times 1/rate as the timestamp) and put packets on a queue that ``pull`` drains; a
Vicon DataStream source would call ``GetFrame`` / ``GetMarkerGlobalTranslation`` per subject marker
(mm, ``GetFrameNumber`` / ``GetFrameRate`` for the timestamp). Neither is shipped: their SDKs need
the vendor's server to test against.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Protocol as TypingProtocol

import numpy as np

from exubio.errors import InputError
from exubio.types import Trajectories

__all__ = ["StreamInfo", "MarkerSource", "ReplaySource", "Faults", "UNIT_SCALE"]

UNIT_SCALE = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}
"""Metres per unit of a stream's positions (the units a marker stream declares)."""


@dataclass(frozen=True)
class StreamInfo:
    """What a marker stream declares: its name, marker labels (one per x, y, z channel triple),
    nominal rate (Hz), the units of its positions, and a source id."""

    name: str
    labels: tuple[str, ...]
    rate_hz: float
    units: str = "m"
    source_id: str = ""

    def __post_init__(self) -> None:
        if not self.labels:
            raise InputError(f"stream '{self.name}': no marker labels")
        if len(set(self.labels)) != len(self.labels):
            dup = sorted({x for x in self.labels if self.labels.count(x) > 1})
            raise InputError(f"stream '{self.name}': duplicate marker labels {dup}")
        if not self.rate_hz > 0:
            raise InputError(f"stream '{self.name}': a marker stream needs a regular rate > 0 Hz, got {self.rate_hz}")
        if self.units not in UNIT_SCALE:
            raise InputError(f"stream '{self.name}': unknown position units '{self.units}'; "
                             f"allowed values are {sorted(UNIT_SCALE)}")


class MarkerSource(TypingProtocol):
    def open(self, timeout_s: float) -> StreamInfo: ...

    def pull(self, timeout_s: float) -> list[tuple[float, np.ndarray]] | None: ...

    def wake(self) -> None: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class Faults:
    """Faults a replay injects, for tests and demos (frame indices of the trial).

    drop: frames never sent; late: frames sent again after the next frame (a late duplicate);
    gaps: (marker label, first frame, stop frame): the marker is missing (NaN) there;
    stall: (frame, seconds): the sender goes silent for that long from the frame on; the frames of
        that time are lost (as from a camera system that stopped), the next one carries its own
        timestamp;
    restart: a frame at which the sender starts again from frame 0 (its timestamps go back to 0),
        after 0.5 s;
    swap: (label a, label b, first frame): from there on the two labels' data are exchanged.
    """

    drop: tuple[int, ...] = ()
    late: tuple[int, ...] = ()
    gaps: tuple[tuple[str, int, int], ...] = ()
    stall: tuple[int, float] | None = None
    restart: int | None = None
    swap: tuple[str, str, int] | None = None


class ReplaySource:
    """A trial replayed in process as a marker source: frame i carries timestamp t0 + i / rate.

    speed: None = as fast as the consumer pulls (the offline causal run); a number = that many
    times real time (1.0: the trial's own rate), the samples being released by the wall clock.
    ``faults`` are applied on the way (see Faults)."""

    def __init__(self, trajectories: Trajectories, /, *, speed: float | None = None, faults: Faults = Faults(),
                 chunk: int = 64, t0: float = 0.0):
        self.traj, self.speed, self.faults, self.chunk, self.t0 = trajectories, speed, faults, max(int(chunk), 1), t0
        self.labels = tuple(trajectories.labels)
        self.rate = float(trajectories.rate_hz)
        self._plan = self._schedule()
        self._next = 0
        self._start_wall: float | None = None
        self._wake = threading.Event()

    def _schedule(self) -> list[tuple[float, float, int, bool]]:
        """(release time s from the start, timestamp s, trial frame, after a restart) of every
        sample sent, in send order."""
        f, n, dt = self.faults, self.traj.n_frames, 1.0 / self.rate
        plan: list[tuple[float, float, int, bool]] = []
        stall_lost = set()
        if f.stall is not None:  # frames inside the stall are lost: their time had passed
            stall_lost = set(range(f.stall[0], min(f.stall[0] + int(round(f.stall[1] * self.rate)), n)))
        first = range(n if f.restart is None else f.restart)
        pending: list[int] = []
        for i in first:
            if i in stall_lost or i in f.drop:
                continue
            release = i * dt
            plan.append((release, i * dt, i, False))
            plan.extend((release, j * dt, j, False) for j in pending)
            pending = [i] if i in f.late else []
        if f.restart is not None:  # the sender starts again from frame 0 on its own clock (timestamps go back)
            base = f.restart * dt + 0.5
            plan.extend((base + i * dt, i * dt, i, True) for i in range(n))
        return plan

    def open(self, timeout_s: float = 0.0) -> StreamInfo:  # noqa: ARG002
        return StreamInfo(name=f"replay:{self.traj.source or 'trajectories'}", labels=self.labels, rate_hz=self.rate,
                          units="m", source_id=f"replay-{id(self)}")

    def _values(self, frame: int, again: bool) -> np.ndarray:
        p = self.traj.positions_m[frame].copy()
        f = self.faults
        for label, a, b in f.gaps:
            if a <= frame < b and label in self.labels:
                p[self.labels.index(label)] = np.nan
        if f.swap is not None and frame >= f.swap[2] and not again:
            ia, ib = self.labels.index(f.swap[0]), self.labels.index(f.swap[1])
            p[[ia, ib]] = p[[ib, ia]]
        return p

    def pull(self, timeout_s: float) -> list[tuple[float, np.ndarray]] | None:
        if self._next >= len(self._plan):
            return None
        if self.speed is None:
            out = []
            while self._next < len(self._plan) and len(out) < self.chunk:
                _, ts, i, again = self._plan[self._next]
                out.append((self.t0 + ts, self._values(i, again)))
                self._next += 1
            return out
        if self._start_wall is None:
            self._start_wall = time.perf_counter()
        release = self._plan[self._next][0] / self.speed
        wait = self._start_wall + release - time.perf_counter()
        if wait > 0:
            self._wake.wait(min(wait, timeout_s))
            self._wake.clear()
            if time.perf_counter() < self._start_wall + release:
                return []
        out = []
        now = time.perf_counter() - self._start_wall
        while self._next < len(self._plan) and self._plan[self._next][0] / self.speed <= now:
            _, ts, i, again = self._plan[self._next]
            out.append((self.t0 + ts, self._values(i, again)))
            self._next += 1
        return out

    def wake(self) -> None:
        self._wake.set()

    def close(self) -> None:
        self._next = len(self._plan)
