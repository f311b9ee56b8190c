"""The noise-gain flags of one frame, as a live session asks for them every 50 ms
(exubio.run.live.monitor): exubio.trust.observability.determinacy's formulas on a single frame in one
compiled call (exubio.model.live_kernels.frame_noise_gains; some fifty numpy calls on small arrays
before, 0.35-0.65 ms a call), the gains to round-off and so the flags a threshold draws on them."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.trust.observability import GIMBAL_MARGIN_RAD, UNDETERMINED_DEG_PER_MM

__all__ = ["FrameDeterminacy"]


class FrameDeterminacy:
    """``determinacy(kin, points, q[None], present[None], weights, excluded=excluded)`` of one frame: call
    it with q (m,) rad and present (k,) bool; returns (undetermined, near_gimbal_lock), (m,) bool each
    (the first rows of Determinacy.undetermined and .near_gimbal_lock)."""

    def __init__(self, kin: Kinematics, points: PointSet, weights: np.ndarray, /, *, excluded: np.ndarray | None = None):
        self.kin, self.points, self.weights = kin, points, np.asarray(weights, dtype=float)
        self.m = m = kin.model.n_coordinates
        self.excluded = np.zeros(m, dtype=bool) if excluded is None else np.asarray(excluded, dtype=bool)
        self.free = np.flatnonzero(~self.excluded)
        self.locks = [(idx[0], idx[1], idx[2]) for _, _, idx, _ in kin.joint_frames() if len(idx) == 3]
        self.margin = np.sin(GIMBAL_MARGIN_RAD)
        from exubio.model import live_kernels  # numba: imported where used

        self.kernel = live_kernels.frame_noise_gains
        contacts = kin.contacts
        self.tables = (*kin.kernel_tables(), np.ascontiguousarray(kin._affects_f),
                       np.asarray(points.segment_index, dtype=np.int64), np.ascontiguousarray(points.local_m, dtype=float),
                       np.asarray(contacts.segment_index, dtype=np.int64), np.ascontiguousarray(contacts.local_m, dtype=float),
                       np.asarray(kin.centre, dtype=float), np.asarray(kin.a_diag, dtype=float),
                       np.ascontiguousarray(self.weights))
        self.free64 = self.free.astype(np.int64)
        self.kernel(np.zeros(m), *self.tables, np.ones(len(self.weights), dtype=np.bool_), self.free64, np.empty(m))
        # (compiled, or loaded from numba's cache, now: compiling takes seconds on a machine's first run)

    def __call__(self, q: np.ndarray, present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = np.ascontiguousarray(q, dtype=float)
        gain = np.empty(self.m)
        self.kernel(q, *self.tables, np.asarray(present, dtype=np.bool_), self.free64, gain)
        with np.errstate(invalid="ignore"):
            und = gain > UNDETERMINED_DEG_PER_MM
        und[self.excluded] = False
        gimbal = np.zeros(self.m, dtype=bool)
        for first, middle, last in self.locks:
            if np.abs(np.cos(q[middle])) < self.margin:
                gimbal[first] = gimbal[last] = True
        return und, gimbal
