"""One live frame's outputs from the segment rotations of its PF state, in two compiled calls
(exubio.model.live_kernels): the joint coordinates on the run's branch, then the ISB angles the
session publishes (unwrapped against the previous frame's) and their rates, the segment rotations
and origins, the model points and residuals, their mean and the GH elevation the verdict bounds.
Bit for bit what the numpy steps they replace gave (tests/run/test_live_frame.py)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from exubio.model.angles import anatomical_frames
from exubio.model.frame_angles import FrameAngles
from exubio.model.frame_kinematics import FrameInverse
from exubio.model.kinematics import Kinematics, PointSet
from exubio.types import Model

__all__ = ["LiveFrame", "FrameOutputs"]


class FrameOutputs(NamedTuple):
    """One frame's outputs: R (n_seg, 3, 3), p (n_seg, 3) the segments (forward kinematics of q);
    isb (15,) rad, rate (15,) rad/s; points (k, 3) m, residuals (k,) m; mean_residual_mm (NaN: no
    finite residual); gh_elevation (rad; NaN without a scapula and a humerus)."""

    R: np.ndarray
    p: np.ndarray
    isb: np.ndarray
    rate: np.ndarray
    points: np.ndarray
    residuals: np.ndarray
    mean_residual_mm: float
    gh_elevation: float


class LiveFrame:
    """A session's frames, one after the other: ``start_run(q0)`` as each PF run starts (its first
    frame's coordinates are put on the 2 pi branch nearest q0), ``coordinates(R)`` of each frame the
    run reaches, ``outputs(q, measured)`` for the frame's published row, ``none()`` for a frame
    without angles (the next frame's rates start again at zero). ``gh_axes``: ((scapula segment,
    its long axis), (humerus segment, its long axis)) or None."""

    def __init__(self, model: Model, kin: Kinematics, points: PointSet, rate_hz: float, gh_axes=None):
        from exubio.model import live_kernels  # numba: imported where used

        self.k_coords, self.k_outputs = live_kernels.frame_coordinates, live_kernels.frame_outputs
        inverse = FrameInverse(kin)
        self.inverse_tables, self.mid = inverse.tables, inverse.mid
        self.forward_tables = kin.kernel_tables()
        self.angle_tables = FrameAngles(model, anatomical_frames(model)).tables
        self.pt_seg = np.asarray(points.segment_index, dtype=np.int64)
        self.pt_local = np.ascontiguousarray(points.local_m, dtype=float)
        self.gh_seg = np.array([-1, -1], dtype=np.int64)
        self.gh_axes = np.zeros((2, 3))
        if gh_axes is not None:
            (s, ys), (h, yh) = gh_axes
            self.gh_seg[:] = s, h
            self.gh_axes[:] = ys, yh
        self.rate = float(rate_hz)
        self.m, self.n_seg, self.k = kin.n_coordinates, kin.n_segments, len(self.pt_seg)
        self.n_angles = 3 * len(self.angle_tables[2])
        self.angle_state = np.zeros((2, self.n_angles))  # the last angles unwrapped against, the last published
        self.has_angles = np.zeros(2, dtype=np.bool_)
        self.run_state = np.zeros((3, self.m))  # the run's last raw and unwrapped coordinates, its 2 pi shift
        self.has_last, self.q0 = False, np.zeros(self.m)
        self._warm()

    def _warm(self) -> None:
        """Compile the kernels (or load them from numba's cache) now, on scratch state, not in the first
        frame: compiling them takes seconds on a machine's first run."""
        state, has = self.angle_state.copy(), self.has_angles.copy()
        run = self.run_state.copy()
        R = np.broadcast_to(np.eye(3), (self.n_seg, 3, 3)).copy()
        q = np.empty(self.m)
        self.k_coords(R, self.mid, self.q0, *self.inverse_tables, run, False, q)
        self.k_outputs(q, *self.forward_tables, *self.angle_tables, self.pt_seg, self.pt_local, self.gh_seg,
                       self.gh_axes, np.zeros((self.k, 3)), state, has, self.rate, np.empty((self.n_seg, 3, 3)),
                       np.empty((self.n_seg, 3)), np.empty(self.n_angles), np.empty(self.n_angles),
                       np.empty((self.k, 3)), np.empty(self.k))

    def start_run(self, q0: np.ndarray) -> None:
        self.q0 = np.ascontiguousarray(q0, dtype=float)
        self.has_last = False

    def coordinates(self, R: np.ndarray) -> np.ndarray:
        """The coordinates (m,) of the segment rotations R (n_seg, 3, 3) (exubio.methods.pf._Frames.coordinates
        of one frame: the inverse map, unwrapped against the run's previous frame)."""
        q = np.empty(self.m)
        self.k_coords(np.ascontiguousarray(R, dtype=float), self.mid, self.q0, *self.inverse_tables, self.run_state,
                      self.has_last, q)
        self.has_last = True
        return q

    def outputs(self, q: np.ndarray, measured: np.ndarray) -> FrameOutputs:
        """The outputs of coordinates q (m,) against the measured positions (k, 3) (NaN: missing)."""
        R, p = np.empty((self.n_seg, 3, 3)), np.empty((self.n_seg, 3))
        isb, rate = np.empty(self.n_angles), np.empty(self.n_angles)
        pts, res = np.empty((self.k, 3)), np.empty(self.k)
        mean, gh = self.k_outputs(np.ascontiguousarray(q, dtype=float), *self.forward_tables, *self.angle_tables,
                                  self.pt_seg, self.pt_local, self.gh_seg, self.gh_axes,
                                  np.ascontiguousarray(measured, dtype=float), self.angle_state, self.has_angles,
                                  self.rate, R, p, isb, rate, pts, res)
        return FrameOutputs(R, p, isb, rate, pts, res, mean, gh)

    def none(self) -> tuple[np.ndarray, np.ndarray]:
        """A frame without angles: NaN angles and rates; the next frame's rates start again at zero."""
        self.has_angles[1] = False
        nan = np.full(self.n_angles, np.nan)
        return nan, nan
