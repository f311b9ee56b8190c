"""The inverse map of one frame at a time: ``FrameInverse``, the joint coordinates of one frame from its
segment rotations (Kinematics.coordinates_from_rotations' kernel, exubio.model.kernels), called directly
with its tables set up once; the live frame (exubio.run.live.frame) takes its tables. The coordinates
agree with the numpy reference coordinates_from_rotations_numpy to round-off
(tests/model/test_frame_angles.py)."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics

__all__ = ["FrameInverse"]


class FrameInverse:
    """``inverse(R, q_previous)``: the coordinates (m,) of segment rotations R (n_seg, 3, 3), as
    ``kin.coordinates_from_rotations(R, q_previous=q_previous)``."""

    def __init__(self, kin: Kinematics, /):
        from exubio.model import kernels  # numba: imported where used

        self.m = kin.n_coordinates
        ranges = kin.model.coordinate_ranges_rad
        lo, hi = ranges[:, 0], ranges[:, 1]
        bounded = np.isfinite(lo) & np.isfinite(hi)
        self.mid = np.where(bounded, 0.5 * (np.where(bounded, lo, 0.0) + np.where(bounded, hi, 0.0)), 0.0)
        self.kernel = kernels.coordinates_from_rotations  # compiled
        self.tables = kin._inverse.kernel_tables(ranges)

    def __call__(self, R: np.ndarray, q_previous: np.ndarray | None = None) -> np.ndarray:
        out = np.empty((1, self.m))
        ref = self.mid if q_previous is None else np.asarray(q_previous, dtype=float)
        self.kernel(np.ascontiguousarray(R, dtype=float)[None], ref[None], q_previous is not None, *self.tables, out)
        return out[0]
