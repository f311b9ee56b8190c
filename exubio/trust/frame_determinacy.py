"""The noise-gain flags of one frame, as a live session asks for them every 50 ms
(exubio.run.live.monitor): exubio.trust.observability.determinacy's arithmetic on a single frame,
without the frame selection and copying a trial needs (which cost a live frame more than the gains)."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.trust.observability import GIMBAL_MARGIN_RAD, UNDETERMINED_DEG_PER_MM, _gains

__all__ = ["FrameDeterminacy"]


class FrameDeterminacy:
    """``determinacy(kin, points, q[None], present[None], weights, excluded=excluded)`` of one frame,
    bit for bit: call it with q (m,) rad and present (k,) bool; returns (undetermined, near_gimbal_lock),
    (m,) bool each (the first rows of Determinacy.undetermined and .near_gimbal_lock)."""

    def __init__(self, kin: Kinematics, points: PointSet, weights: np.ndarray, /, *, excluded: np.ndarray | None = None):
        self.kin, self.points, self.weights = kin, points, np.asarray(weights, dtype=float)
        self.m = m = kin.model.n_coordinates
        self.excluded = np.zeros(m, dtype=bool) if excluded is None else np.asarray(excluded, dtype=bool)
        self.free = np.flatnonzero(~self.excluded)
        self.locks = [(idx[0], idx[1], idx[2]) for _, _, idx, _ in kin.joint_frames() if len(idx) == 3]
        self.margin = np.sin(GIMBAL_MARGIN_RAD)

    def __call__(self, q: np.ndarray, present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = np.asarray(q, dtype=float)
        ok = np.array([np.isfinite(q).all()])
        gain = _gains(self.kin, self.points, q[None], ok, np.asarray(present, dtype=bool)[None], self.weights,
                      self.free, self.m)[0]
        with np.errstate(invalid="ignore"):
            und = gain > UNDETERMINED_DEG_PER_MM
        und[self.excluded] = False
        gimbal = np.zeros(self.m, dtype=bool)
        for first, middle, last in self.locks:
            if np.abs(np.cos(q[middle])) < self.margin:
                gimbal[first] = gimbal[last] = True
        return und, gimbal
