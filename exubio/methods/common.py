"""What every reconstruction method shares: the tracked model points of a protocol and the
assembly of a Reconstruction (model points, residuals, constraint residuals) from q, q̇, q̈."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from exubio.kinematics import Kinematics, PointSet
from exubio.types import Gap, MarkerTargets, Protocol, Reconstruction


def tracked_points(kin: Kinematics, protocol: Protocol, /) -> PointSet:
    """The segment-fixed model point R_i of every protocol marker, in protocol order."""
    return PointSet(
        segment_index=np.array([kin.model.segment_index(m.segment) for m in protocol.markers], dtype=int),
        local_m=np.array([np.asarray(m.local_position_m, dtype=float) for m in protocol.markers]).reshape(-1, 3),
        names=protocol.marker_names,
    )


BLOCK_FRAMES = 8192  # frames per block of the per-frame computations


def assemble(kin: Kinematics, points: PointSet, targets: MarkerTargets, /, *, method: str, q: np.ndarray,
             qd: np.ndarray, qdd: np.ndarray, status: np.ndarray, timings_s: Mapping[str, float],
             info: Mapping[str, Any], gaps: tuple[Gap, ...] = ()) -> Reconstruction:
    """Build the Reconstruction: model points at q, residuals |R_i - M_i| (NaN in gaps), g and G q̇."""
    n = q.shape[0]
    model_points = np.empty((n, len(points.names), 3))
    constraint, constraint_velocity = np.empty((n, 2)), np.empty((n, 2))
    for a in range(0, n, BLOCK_FRAMES):  # blocks bound the temporaries on long trials
        s = slice(a, min(a + BLOCK_FRAMES, n))
        fr = kin.frames(q[s])
        model_points[s] = kin.points(q[s], points, frames=fr)
        constraint[s] = kin.g(q[s], frames=fr)
        constraint_velocity[s] = np.einsum("nkm,nm->nk", kin.G(q[s], frames=fr), qd[s])
    residuals = np.linalg.norm(model_points - targets.positions_m, axis=2)  # NaN where missing
    return Reconstruction(
        method=method,
        time_s=np.asarray(targets.time_s, dtype=float),
        coordinate_names=kin.model.coordinate_names,
        q_rad=q,
        qd_rad_s=qd,
        qdd_rad_s2=qdd,
        marker_names=points.names,
        model_points_m=model_points,
        measured_m=targets.positions_m,
        residuals_m=residuals,
        constraint=constraint,
        constraint_velocity=constraint_velocity,
        status=np.asarray(status, dtype=int),
        timings_s=dict(timings_s),
        info=dict(info),
        gaps=tuple(gaps) if gaps else tuple(targets.gaps),
    )
