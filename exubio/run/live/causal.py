"""Causal processing of a marker stream: each frame from the frames before it only.

The offline preprocessing (exubio.prep.targets) filters forward and backward (zero lag) and fits
cubic splines through the whole trial; both look into the future. Here, frame by frame:

1. the stream's labels are matched to the protocol once (exubio.protocol.load.resolve_labels, the
   protocol's ``relabel`` included);
2. the thorax frame is built from the landmarks of this frame (a landmark missing for up to
   ``max_thorax_gap_s`` is held at its last value: the causal counterpart of the offline bridge;
   longer, every marker is missing in that frame); a left arm is mirrored as offline;
3. an optional causal low-pass: a Butterworth filter of ``order`` run forward only (scipy's
   second-order sections, state kept per marker and axis), restarted at the marker's position
   where it reappears after a gap; ``cutoff_hz`` None = no filter (the PF springs and dampers
   filter by themselves);
4. the target velocity is the backward difference of the (filtered) positions,
   v_i = (p_i - p_{i-1}) / dt, and the acceleration that of the velocities. The first sample after
   a gap has no velocity: its spring stays off for the step into it (``PFSystem.run_live`` uses a
   spring in a step only if its marker is active at both ends) and comes on from the next one.

Without a filter, steps 2 to 4 are one compiled call per frame (exubio.model.batch_kernels.causal_frame:
the same arithmetic in the same order, bit for bit), but in a frame with a thorax landmark missing, which this module's Python holds.
What each choice costs in lag is measured in studies/README.md ("Live: causal processing").
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.signal import butter, sosfilt_zi

from exubio.errors import InputError
from exubio.prep.thorax import MAX_THORAX_GAP_S, isb_landmarks
from exubio.protocol.labels import resolve_labels
from exubio.types import Protocol

__all__ = ["CausalOptions", "CausalTargets", "CausalFrame"]


@dataclass(frozen=True)
class CausalOptions:
    """Settings of the causal preprocessing (see the module docstring).

    cutoff_hz: causal Butterworth low-pass cut-off (Hz), or None for no filter.
    order: the filter's order (2: a second-order section).
    max_thorax_gap_s: a thorax landmark missing this long at most is held at its last value.
    """

    cutoff_hz: float | None = None
    order: int = 2
    max_thorax_gap_s: float = MAX_THORAX_GAP_S

    def check(self, rate_hz: float) -> None:
        if self.cutoff_hz is not None and not (0 < self.cutoff_hz < rate_hz / 2):
            raise InputError(f"causal filter: cutoff {self.cutoff_hz} Hz must lie in (0, {rate_hz / 2:g}) Hz "
                             f"(half the stream's rate {rate_hz:g} Hz)")
        if int(self.order) < 1:
            raise InputError(f"causal filter: order must be >= 1, got {self.order}")

    def describe(self) -> str:
        f = "none" if self.cutoff_hz is None else f"causal Butterworth order {self.order}, {self.cutoff_hz:g} Hz"
        return f"filter: {f}; rates: backward differences"


@dataclass(frozen=True)
class CausalFrame:
    """One frame's targets in protocol order (thorax frame, m): positions (k, 3), NaN where missing;
    velocities and accelerations (k, 3), 0 where not defined; present (k,) bool."""

    positions_m: np.ndarray
    velocities_m_s: np.ndarray
    accelerations_m_s2: np.ndarray
    present: np.ndarray


class CausalTargets:
    """Turns raw lab-frame frames (n_labels, 3) m (NaN = missing) of a stream with ``labels`` into
    the protocol's targets, one frame at a time (``push``), in order, with no look-ahead."""

    def __init__(self, protocol: Protocol, labels: Sequence[str], rate_hz: float, /, *,
                 options: CausalOptions = CausalOptions(), source: str = ""):
        options.check(rate_hz)
        self.protocol, self.options, self.rate_hz, self.dt = protocol, options, float(rate_hz), 1.0 / float(rate_hz)
        self.labels = tuple(labels)
        match = resolve_labels(protocol, self.labels, source=source)
        names = protocol.marker_names
        self.k = len(names)
        self.columns = np.array([-1 if match.columns[n] is None else match.columns[n] for n in names], dtype=int)
        self.thorax = {key: int(col) for key, col in match.thorax_columns.items()}
        self.unused = match.unused
        self.mirror = protocol.side == "left"
        self.max_thorax_gap = int(round(options.max_thorax_gap_s * rate_hz))
        self._held = {key: (None, 0) for key in self.thorax}  # last valid landmark and frames since
        self._have = self.columns >= 0
        self._have_columns = self.columns[self._have]
        self._have_all = bool(self._have.all())
        self._thorax_keys = tuple(self.thorax)
        self._thorax_columns = np.array([self.thorax[key] for key in self._thorax_keys], dtype=int)
        if options.cutoff_hz is not None:
            self.sos = butter(int(options.order), float(options.cutoff_hz), fs=rate_hz, output="sos")
            self.zi_unit = sosfilt_zi(self.sos)  # (sections, 2): steady state for a unit input
            self.z = np.zeros((self.k, self.sos.shape[0], 2, 3))
        else:
            self.sos = None
        self._kernel = None  # without a filter: one compiled call per frame (exubio.model.batch_kernels.causal_frame)
        if self.sos is None:
            from exubio.model.batch_kernels import FRAME_LANDMARK_MISSING, causal_frame

            self._kernel, self._landmark_missing = causal_frame, FRAME_LANDMARK_MISSING
            keys = (("ij", "px", "c7", "t8") if "c7" in self.thorax else
                    ("ij", "ij_c7_midpoint", "px_t8_midpoint") if self.thorax else ())
            self._kernel_keys = keys
            self._kernel_columns = np.array([self.thorax[key] for key in keys], dtype=np.int64)
            self._kernel_midpoints = bool(self.thorax) and "c7" not in self.thorax
            self._columns64 = self.columns.astype(np.int64)
            self._warm_kernel(len(self.labels))
        self.prev_p = np.full((self.k, 3), np.nan)
        self.prev_v = np.zeros((self.k, 3))
        self.prev_present = np.zeros(self.k, dtype=bool)
        self.prev_has_v = np.zeros(self.k, dtype=bool)

    def restart(self) -> None:
        """Forget the history (a stream that restarted): the next frame starts like the first."""
        self.prev_present[:] = False
        self.prev_has_v[:] = False
        self._held = {key: (None, 0) for key in self.thorax}

    def _landmark(self, key: str, raw: np.ndarray) -> np.ndarray | None:
        value = raw[self.thorax[key]]
        last, since = self._held[key]
        if np.isfinite(value).all():
            self._held[key] = (value.copy(), 0)
            return value
        if last is not None and since < self.max_thorax_gap:
            self._held[key] = (last, since + 1)
            return last
        self._held[key] = (last, since + 1)
        return None

    def thorax_positions(self, raw: np.ndarray) -> np.ndarray:
        """The protocol markers of one raw frame in the thorax frame (k, 3), NaN where missing."""
        raw = np.asarray(raw, dtype=float)
        if self._have_all:  # (the usual stream: one indexing, no NaN-filled copy)
            pos = raw[self.columns]
        else:
            pos = np.full((self.k, 3), np.nan)
            pos[self._have] = raw[self._have_columns]
        pos[~np.isfinite(pos).all(axis=1)] = np.nan
        if self.thorax:
            found = raw[self._thorax_columns]  # every landmark at once; held ones only where one is missing
            if np.isfinite(found).all():
                lm = dict(zip(self._thorax_keys, found))
                for key, value in lm.items():
                    self._held[key] = (value, 0)
            else:
                lm = {key: self._landmark(key, raw) for key in self.thorax}
            if any(v is None for v in lm.values()):
                return np.full((self.k, 3), np.nan)
            frame = thorax_frame_one(*isb_landmarks(lm))
            if frame is None:  # landmarks collinear in this frame: no frame, no markers
                return np.full((self.k, 3), np.nan)
            rot, origin = frame
            d = pos - origin  # R^T (p - origin), term by term: the compiled frame's order of operations
            pos = d[:, 0:1] * rot[0] + d[:, 1:2] * rot[1] + d[:, 2:3] * rot[2]
        if self.mirror:
            pos = pos * np.array([1.0, 1.0, -1.0])
        return pos

    def push(self, raw: np.ndarray, /) -> CausalFrame:
        """The targets of the next frame from its raw lab positions (n_labels, 3) m."""
        if self._kernel is not None:
            frame = self._push_compiled(raw)
            if frame is not None:
                return frame
        p = self.thorax_positions(raw)
        present = np.isfinite(p).all(axis=1)
        if self.sos is not None:
            p = self._filter(p, present)
        cont = present & self.prev_present
        # the backward differences on whole arrays, zero where not defined (the rows a marker is missing in
        # are NaN in p: what they give is replaced)
        v = (p - self.prev_p) / self.dt
        v[~cont] = 0.0
        acc = cont & self.prev_has_v
        a = (v - self.prev_v) / self.dt
        a[~acc] = 0.0
        self.prev_p = p  # (NaN where a marker is missing: p's rows)
        self.prev_v = v
        self.prev_present = present
        self.prev_has_v = cont
        return CausalFrame(p, v, a, present)

    def _warm_kernel(self, n_labels: int) -> None:
        """Compile (or load from numba's cache) the kernel now, on scratch arrays, not in the first frame."""
        k, nt = self.k, len(self._kernel_keys)
        self._kernel(np.zeros((n_labels, 3)), self._columns64, self._kernel_columns, self._kernel_midpoints,
                     self.mirror, self.dt, np.zeros((k, 3)), np.zeros((k, 3)), np.zeros(k, dtype=bool),
                     np.zeros(k, dtype=bool), np.empty((k, 3)), np.empty((k, 3)), np.empty((k, 3)),
                     np.empty(k, dtype=bool), np.empty(k, dtype=bool), np.empty((nt, 3)))

    def _push_compiled(self, raw: np.ndarray) -> CausalFrame | None:
        """``push`` without a filter in one compiled call (the same formulas); None where a thorax
        landmark is missing (the Python path holds it)."""
        raw = np.ascontiguousarray(raw, dtype=float)
        k = self.k
        p, v, a = np.empty((k, 3)), np.empty((k, 3)), np.empty((k, 3))
        present, cont = np.empty(k, dtype=bool), np.empty(k, dtype=bool)
        found = np.empty((len(self._kernel_keys), 3))
        if self._kernel(raw, self._columns64, self._kernel_columns, self._kernel_midpoints, self.mirror, self.dt,
                        self.prev_p, self.prev_v, self.prev_present, self.prev_has_v,
                        p, v, a, present, cont, found) == self._landmark_missing:
            return None
        held = self._held
        for key, row in zip(self._kernel_keys, found):
            held[key] = (row, 0)
        self.prev_p, self.prev_v, self.prev_present, self.prev_has_v = p, v, present, cont
        return CausalFrame(p, v, a, present)

    def _filter(self, p: np.ndarray, present: np.ndarray) -> np.ndarray:
        """One step of the causal Butterworth filter (direct form II transposed, per section) for
        every present marker; a marker that reappears starts at the steady state of its position."""
        out = np.full_like(p, np.nan)
        fresh = present & ~self.prev_present
        if fresh.any():
            self.z[fresh] = self.zi_unit[None, :, :, None] * p[fresh][:, None, None, :]
        idx = np.flatnonzero(present)
        if idx.size == 0:
            return out
        x = p[idx]
        z = self.z[idx]
        for s, (b0, b1, b2, _a0, a1, a2) in enumerate(self.sos):
            y = b0 * x + z[:, s, 0]
            z[:, s, 0] = b1 * x - a1 * y + z[:, s, 1]
            z[:, s, 1] = b2 * x - a2 * y
            x = y
        self.z[idx] = z
        out[idx] = x
        return out


def thorax_frame_one(ij: np.ndarray, px: np.ndarray, c7: np.ndarray, t8: np.ndarray, /
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """exubio.prep.thorax.thorax_frame of one frame's four landmarks (3,): (R (3, 3), origin (3,)), or
    None where the landmarks are coincident or collinear (thorax_frame's test). The compiled kernel's
    (exubio.model.batch_kernels.thorax_frame_into: a frame at a time, numpy's per-call cost would be
    most of it), the one the compiled causal frame uses; R may differ from thorax_frame's in the last
    bit (tests/model/test_frame_angles.py)."""
    from exubio.model.batch_kernels import thorax_frame_into

    R, o = np.empty((3, 3)), np.empty(3)
    if not thorax_frame_into(np.array([ij, px, c7, t8], dtype=float), R, o):
        return None
    return R, o


def frame_index(timestamp_s: float, first_timestamp_s: float, rate_hz: float, /) -> int:
    """The frame a sample belongs to on the stream's uniform grid (nearest frame)."""
    return int(math.floor((timestamp_s - first_timestamp_s) * rate_hz + 0.5))
