"""What a live session puts out, the types the rest of the live package reads: the output
stream's channels (OUTPUT_CHANNELS, VERDICT_CODES), which angles the markers measure
(angles_measured), the events (Event) and the recording of every frame (LiveRecording, filled row
by row in _Growing arrays). The files of a recording are written by exubio.run.live.record."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from exubio.io.records import converted
from exubio.trust import quality as Q
from exubio.model.angles import ISB_COLUMNS, measured_isb_joints
from exubio.protocol.bind import Binding
from exubio.run.live.sources import StreamInfo
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Reconstruction, Trajectories

if TYPE_CHECKING:
    from exubio.run.live.options import LiveOptions

__all__ = ["OUTPUT_CHANNELS", "VERDICT_CODES", "ISB_NAMES", "angles_measured", "Event", "LiveRecording",
           "FrameRecord"]

VERDICT_CODES = {"ok": 0, "check": 1, "fail": 2}

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
                    binding: Binding | None = None, unmeasurable: Sequence[str] = (),
                    structural: Mapping[str, str] | None = None) -> np.ndarray:
    """(15,) bool, per ISB angle (ISB_COLUMNS order): measured by the markers. The one place the
    live output decides it. With ``binding`` (the model and protocol): an angle the marker set cannot measure in any
    reference posture (exubio.trust.assess.angle_status_of_protocol, the status the files give) is not
    measured (one it measures in some postures only is judged frame by frame: live applies neither
    the gimbal margin nor the uncertainty bound, which the files do); of the others, a joint's angles are not measured in a frame where one of its own
    coordinates is not solved (held, locked) or undetermined there (exubio.trust.observability's noise
    gain), ``unmeasurable`` coordinates (the set cannot determine them anyway) left aside.
    ``structural``: that status, computed once by a caller that asks frame after frame."""
    joints = set(measured_isb_joints(model, set(not_solved) | (set(undetermined) - set(unmeasurable))))
    out = np.array([j in joints for j in ISB_JOINT_OF], dtype=bool)
    if structural is None and binding is not None:
        from exubio.trust.assess import angle_status_of_protocol

        structural = angle_status_of_protocol(binding)
    if structural is not None:
        status = structural
        for i, name in enumerate(ISB_NAMES):
            if status.get(_ISB_AS_ANATOMICAL.get(name, name), "measured") in ("not measured", "modelled"):
                out[i] = False  # "partly ...": measured in some postures (the gimbal margin, the
                # uncertainty bound of exubio.trust.angle_uncertainty): live, the frame decides
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
class Event:
    """Something the live loop saw and handled: ``kind`` (gap, gap_end, dropped, late, stall,
    resumed, restart, run_start, run_end, behind, caught_up, skip, label_swap, label_swap_end,
    diverged, verdict, end), at ``frame`` (stream frame index) and ``time_s`` (its time on the frame grid)."""

    kind: str
    frame: int
    time_s: float = converted(digits=6)  # written (exubio.io.records) to the µs
    message: str
    markers: tuple[str, ...] = ()


class _Growing:
    """A (n, ...) array appended one row at a time, kept in blocks of BLOCK_ROWS rows: growing never
    copies what is already there (a doubling array's copy held a 1000 Hz session up to 12 ms at
    32768 frames, benchmarks/README.md). Rows never set hold ``fill``."""

    BLOCK_ROWS = 512

    def __init__(self, shape: tuple[int, ...], fill: float = np.nan, dtype=float):
        self.shape, self.fill, self.dtype = tuple(shape), fill, dtype
        self.blocks: list[np.ndarray] = []
        self.n = 0

    def _row_block(self, i: int) -> np.ndarray:
        b = i // self.BLOCK_ROWS
        blocks = self.blocks
        while len(blocks) <= b:
            blocks.append(np.full((self.BLOCK_ROWS,) + self.shape, self.fill, dtype=self.dtype))
        return blocks[b]

    def set(self, i: int, row) -> None:
        b, r = divmod(i, self.BLOCK_ROWS)
        blocks = self.blocks
        (blocks[b] if b < len(blocks) else self._row_block(i))[r] = row
        if i >= self.n:
            self.n = i + 1

    def set_rows(self, i: int, rows: np.ndarray) -> None:
        """Rows i ... i + n - 1 set to ``rows`` (n, ...), a block's slice at a time."""
        n, done, B = len(rows), 0, self.BLOCK_ROWS
        while done < n:
            b, r = divmod(i + done, B)
            take = min(B - r, n - done)
            self._row_block(i + done)[r:r + take] = rows[done:done + take]
            done += take
        if i + n > self.n:
            self.n = i + n

    def get(self, i: int) -> np.ndarray:
        """Row i (a view)."""
        return self.blocks[i // self.BLOCK_ROWS][i % self.BLOCK_ROWS]

    def grow_to(self, n: int) -> None:
        if n > self.n:
            self._row_block(n - 1)
            self.n = n

    def view(self, n: int | None = None) -> np.ndarray:
        """The first n rows (all set so far if None), as one new array."""
        n = self.n if n is None else n
        if n == 0:
            return np.full((0,) + self.shape, self.fill, dtype=self.dtype)
        self._row_block(n - 1)
        return np.concatenate(self.blocks[:(n - 1) // self.BLOCK_ROWS + 1])[:n]


STAGED_FRAMES = 16
"""A frame's inputs and published outputs are written this many frames at a time (FrameRecord)."""
INPUT_ROWS = ("raw_m", "timestamps_s", "received_s", "positions_m", "velocities_m_s", "accelerations_m_s2")
PUBLISHED_ROWS = ("published_s", "isb_rad", "isb_rate_rad_s", "measured")


class FrameRecord:
    """A session's LiveRecording as it fills, frame by frame (each array in a _Growing, under its
    LiveRecording field name, for ``n_labels`` stream labels, ``k`` markers, ``m`` coordinates), and
    ``latency``: from taking each sample off the source to publishing its angles (s)."""

    def __init__(self, n_labels: int, k: int, m: int):
        L, a = n_labels, len(ISB_NAMES)
        self.rows = {"raw_m": _Growing((L, 3)), "timestamps_s": _Growing(()), "received_s": _Growing(()),
                     "published_s": _Growing(()), "positions_m": _Growing((k, 3)),
                     "velocities_m_s": _Growing((k, 3), 0.0), "accelerations_m_s2": _Growing((k, 3), 0.0),
                     "active": _Growing((k,), False, bool), "q_rad": _Growing((m,)), "qd_rad_s": _Growing((m,)),
                     "qdd_rad_s2": _Growing((m,)), "model_points_m": _Growing((k, 3)), "residuals_m": _Growing((k,)),
                     "constraint": _Growing((2,)), "constraint_velocity": _Growing((2,)),
                     "status": _Growing((), int(FrameStatus.TOO_FEW_MARKERS), int), "run": _Growing((), -1, int),
                     "isb_rad": _Growing((a,)), "isb_rate_rad_s": _Growing((a,)), "measured": _Growing((a,), False, bool),
                     "verdict": _Growing((), 0, int)}
        self.latency: list[float] = []
        self.staged: dict[tuple[str, ...], list] = {INPUT_ROWS: [], PUBLISHED_ROWS: []}  # rows not yet written

    def input(self, g: int, raw: np.ndarray, sample, frame) -> None:
        """Frame g's raw samples, its ``sample`` (timestamp, time received; None: never came) and
        its causal targets (``frame``, a CausalFrame). Written STAGED_FRAMES at a time: the arrays must
        not change afterwards (each frame's are new)."""
        self._stage(INPUT_ROWS, (g, raw, np.nan if sample is None else sample.timestamp,
                                 np.nan if sample is None else sample.received, frame.positions_m,
                                 frame.velocities_m_s, frame.accelerations_m_s2))

    def published(self, g: int, now: float, sample, isb: np.ndarray, rate: np.ndarray, measured: np.ndarray) -> None:
        """Frame g's output went out at ``now``: its angles, their rates, the measured flags (written as
        ``input``'s)."""
        if sample is not None:
            self.latency.append(now - sample.received)
        self._stage(PUBLISHED_ROWS, (g, now, isb, rate, measured))

    def _stage(self, keys: tuple[str, ...], row: tuple) -> None:
        staged = self.staged[keys]
        staged.append(row)
        if len(staged) >= STAGED_FRAMES:
            self._write(keys)

    def _write(self, keys: tuple[str, ...]) -> None:
        """The staged rows of ``keys`` written, each run of consecutive frames a block at a time."""
        staged, self.staged[keys] = self.staged[keys], []
        start = 0
        while start < len(staged):
            stop = start + 1
            while stop < len(staged) and staged[stop][0] == staged[stop - 1][0] + 1:
                stop += 1
            part = staged[start:stop]
            for c, key in enumerate(keys, start=1):
                self.rows[key].set_rows(part[0][0], np.array([row[c] for row in part]))
            start = stop

    def output(self, g: int, status: FrameStatus) -> None:
        """Frame g without a PF result (``status`` says why)."""
        self.rows["status"].set(g, int(status))
        self.rows["run"].set(g, -1)

    def outputs(self, g0: int, recon: Reconstruction, run: int) -> None:
        """The PF results of frames g0 ... g0 + n - 1 (``recon``, n frames) of PF run ``run``: ``output``'s
        arrays a block at a time."""
        r = self.rows
        for key in ("q_rad", "qd_rad_s", "qdd_rad_s2", "model_points_m", "residuals_m", "constraint",
                    "constraint_velocity"):
            r[key].set_rows(g0, getattr(recon, key))
        r["status"].set_rows(g0, np.full(recon.n_frames, int(FrameStatus.CONVERGED)))
        r["run"].set_rows(g0, np.full(recon.n_frames, run))

    def arrays(self, n: int) -> dict[str, np.ndarray]:
        """The n frames' arrays (copies), by LiveRecording field name."""
        for keys in self.staged:
            self._write(keys)
        for arr in self.rows.values():
            arr.grow_to(n)
        return {key: arr.view(n) for key, arr in self.rows.items()}

    def latency_ms(self) -> dict[str, Any]:
        """The loop latency's median, 99th percentile and maximum (ms; None without a sample)."""
        lat = np.asarray(self.latency) * 1e3
        return {"p50": float(np.percentile(lat, 50)) if lat.size else None,
                "p99": float(np.percentile(lat, 99)) if lat.size else None,
                "max": float(lat.max()) if lat.size else None,
                "definition": "from taking a sample off the source to publishing its angles"}


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
