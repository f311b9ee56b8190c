"""The kinematics of one frame at a time (the live loop's): ``FrameForward``, the segment rotations
and origins of one posture (Kinematics.frames' kernel, bitwise the same R and p), and
``FrameInverse``, the joint coordinates of one frame from its segment rotations
(Kinematics.coordinates_from_rotations' kernel, exubio.model.kernels). Both call the compiled
kernel directly with their tables and buffers set up once, so a frame costs a few microseconds; the
coordinates agree with the numpy reference coordinates_from_rotations_numpy to round-off
(tests/model/test_frame_angles.py)."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics

__all__ = ["FrameForward", "FrameInverse", "FramePoints"]


class FrameForward:
    """``forward(q)``: (R (n_seg, 3, 3), p (n_seg, 3)) of one posture q (m,), as Kinematics.frames
    (the same compiled kernel, exubio.model.kernels.forward, without the batch's reshaping)."""

    def __init__(self, kin: Kinematics, /):
        from exubio.model import kernels  # numba: imported where used

        self.forward = kernels.forward
        self.tables = kin.kernel_tables()
        self.n_seg, self.m = kin.n_segments, kin.n_coordinates

    def __call__(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, p = np.empty((1, self.n_seg, 3, 3)), np.empty((1, self.n_seg, 3))
        ax = np.empty((1, self.m, 3))
        self.forward(np.ascontiguousarray(q, dtype=float).reshape(1, -1), *self.tables, R, p, ax, np.empty_like(ax))
        return R[0], p[0]


class FramePoints:
    """``model_points(R, p)``: the global positions (k, 3) of the model points ``points`` for one
    frame's segment rotations R (n_seg, 3, 3) and origins p (n_seg, 3), as ``kin.points`` (the same
    compiled kernel, exubio.model.kernels.points, its index and local positions converted once)."""

    def __init__(self, kin: Kinematics, points, /):
        from exubio.model import kernels  # numba: imported where used

        self.kernel = kernels.points
        self.segment_index = np.asarray(points.segment_index, dtype=np.int64)
        self.local_m = np.ascontiguousarray(points.local_m, dtype=float)
        self.n_seg, self.k = kin.n_segments, len(points.segment_index)

    def __call__(self, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        out = np.empty((1, self.k, 3))
        self.kernel(np.ascontiguousarray(R, dtype=float).reshape(1, self.n_seg, 3, 3),
                    np.ascontiguousarray(p, dtype=float).reshape(1, self.n_seg, 3), self.segment_index, self.local_m, out)
        return out[0]


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
