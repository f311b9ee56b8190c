"""The data of the potential-field backend (exubio.backend.exudyn_system): what goes in (the marker
springs, the integrator's settings) and what comes out (the segment motion at the frame times).
Plain numpy, frozen dataclasses and a named tuple; no exudyn."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, NamedTuple, Sequence

import numpy as np

from exubio.model.kinematics import PointSet

__all__ = ["FrameMotion", "IntegratorOptions", "PFRun", "SpringSet", "stack_motions"]


@dataclass(frozen=True)
class SpringSet:
    """The model points tied to measured markers, one spring-damper each.

    segment_index:     (k,) index into ``Model.segments`` (not 0: the thorax does not move).
    local_m:           (k, 3) model-point positions in their segment's frame (m).
    stiffness_n_per_m: (k,) spring constants c (N/m).
    damping_ns_per_m:  (k,) damping constants d (N s/m).
    """

    segment_index: np.ndarray
    local_m: np.ndarray
    stiffness_n_per_m: np.ndarray
    damping_ns_per_m: np.ndarray

    def __post_init__(self) -> None:
        idx = np.asarray(self.segment_index, dtype=int).reshape(-1)
        k = idx.shape[0]
        local = np.asarray(self.local_m, dtype=float)
        if local.shape != (k, 3):
            raise ValueError(f"SpringSet: local_m must have shape ({k}, 3), got {local.shape}")
        c = np.broadcast_to(np.asarray(self.stiffness_n_per_m, dtype=float), (k,)).copy()
        d = np.broadcast_to(np.asarray(self.damping_ns_per_m, dtype=float), (k,)).copy()
        if np.any(~np.isfinite(c)) or np.any(c < 0) or np.any(~np.isfinite(d)) or np.any(d < 0):
            raise ValueError("SpringSet: stiffness and damping must be finite and >= 0")
        for name, value in (("segment_index", idx), ("local_m", local), ("stiffness_n_per_m", c), ("damping_ns_per_m", d)):
            object.__setattr__(self, name, value)

    @classmethod
    def from_points(cls, points: PointSet, /, *, stiffness_n_per_m, damping_ns_per_m) -> "SpringSet":
        """Springs on a kinematics PointSet; constants are scalars or (k,) arrays."""
        return cls(points.segment_index, points.local_m, stiffness_n_per_m, damping_ns_per_m)

    @property
    def n_springs(self) -> int:
        return int(self.segment_index.shape[0])


@dataclass(frozen=True)
class IntegratorOptions:
    """Settings of Exudyn's generalized-alpha integration (the PF method passes its own, see
    exubio.methods.pf.PFOptions; these defaults are the ones for one step per frame).

    step_s: time step; None = one step per frame. Shorter than a frame: frame_dt_s / step_s must
        be an integer (targets between frames: cubic Hermite interpolation of positions and
        velocities). Longer: step_s / frame_dt_s must be an integer (see ``PFSystem.run``).
    spectral_radius, newton_relative_tolerance, modified_newton_contractivity: at one step per
        5 ms frame (0, 1e-5, 0.2) keep q̈ closest to the derivative of q̇ (studies/README.md).
        Exudyn's Newton stops when its residual (forces in N and constraint violations in m, one
        L2 norm) has dropped by newton_relative_tolerance, or is below
        newton_absolute_tolerance.
    modified_newton: Jacobian kept over steps and rebuilt when the contraction of the Newton
        residual is worse than ``modified_newton_contractivity`` (modified Newton measured 2-4x
        faster *and* more accurate than full Newton here; a Jacobian every step: +30 % time).
    sparse_solver: Eigen's SparseLU reusing its analysed pattern (~15 % faster than Exudyn's own
        dense LU, the 1.13 default); False = the dense LU.
    timing_breakdown: fill ``PFRun.solver_times_s`` with Exudyn's CPU timers (~1 % cost).
    """

    step_s: float | None = None
    spectral_radius: float = 0.0
    newton_relative_tolerance: float = 1e-5
    newton_absolute_tolerance: float = 1e-10
    modified_newton: bool = True
    modified_newton_contractivity: float = 0.2
    max_newton_iterations: int = 25
    adaptive_step: bool = True
    sparse_solver: bool = True
    timing_breakdown: bool = True


class FrameMotion(NamedTuple):
    """The segment motion of one frame (a live run's, PFSystem.run_live): PFRun's arrays without the
    frame axis, rotations (n_seg, 3, 3), the others (n_seg, 3), thorax frame."""

    rotations: np.ndarray
    origins_m: np.ndarray
    velocities_m_s: np.ndarray
    accelerations_m_s2: np.ndarray
    angular_velocities_rad_s: np.ndarray
    angular_accelerations_rad_s2: np.ndarray


def stack_motions(motions: Sequence[FrameMotion]) -> FrameMotion:
    """Frames' motions as one FrameMotion whose arrays have a first axis of frames, as a PFRun's."""
    return FrameMotion(*(np.stack(a) for a in zip(*motions)))


@dataclass(frozen=True)
class PFRun:
    """Segment motion at the input frame times (n frames, n_seg = all model segments incl. thorax).

    rotations:   (n, n_seg, 3, 3) segment orientations R (local -> thorax frame).
    origins_m:   (n, n_seg, 3) segment frame origins (joint centres).
    velocities_m_s, accelerations_m_s2: (n, n_seg, 3) of the origins.
    angular_velocities_rad_s, angular_accelerations_rad_s2: (n, n_seg, 3), thorax frame.
    completed_frames: frames the solver reached (rows from here on are NaN if it stopped early).
    success: the solver finished the whole trial; message: its error otherwise.
    wall_time_s: the solve alone; solver_times_s: Exudyn's CPU-time breakdown (s).
    newton_iterations, jacobian_updates, steps: solver statistics of the whole run; step_s: the
    step used. limit_active_s: per joint with a limit element, the time (s) it was switched on
    (near or beyond a limit).
    """

    time_s: np.ndarray
    rotations: np.ndarray
    origins_m: np.ndarray
    velocities_m_s: np.ndarray
    accelerations_m_s2: np.ndarray
    angular_velocities_rad_s: np.ndarray
    angular_accelerations_rad_s2: np.ndarray
    completed_frames: int
    success: bool
    message: str
    wall_time_s: float
    solver_times_s: Mapping[str, float] = field(default_factory=dict)
    newton_iterations: int = 0
    jacobian_updates: int = 0
    steps: int = 0
    step_s: float = float("nan")
    limit_active_s: Mapping[str, float] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])
