"""What every reconstruction method shares: the assembly of a Reconstruction (model points,
residuals, constraint residuals) from q, q̇, q̈, and the chunks a method works through a trial in.

Chunks: a method streams its result as consecutive Reconstructions of ``chunk`` frames to a
``sink`` (a callable), so that a trial of any length is reconstructed with the per-marker arrays
of one chunk in memory; PF keeps integrating across chunk boundaries, LS carries its warm start.
Every frame is computed exactly as in one pass (``Collector`` joins the chunks into the one-pass
Reconstruction)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.types import Gap, MarkerTargets, Reconstruction


BLOCK_FRAMES = 8192  # frames per block of the per-frame computations

CHUNK_FRAMES = 8000
"""Frames a method hands to its sink at a time (40 s at 200 Hz): the per-marker arrays of a chunk
take ~5 MB with 22 markers, and the per-chunk overhead is negligible beside its solve."""

ChunkSink = Callable[[Reconstruction], None]
"""Receives a method's result chunk by chunk, in frame order (frames [first, first + n) of the
trial, ``chunk.time_s`` telling which). A sink with a ``restart()`` method lets the method run the
trial again from its first frame (PF's fallback, exubio.methods.pf.PFOptions.fallback)."""


def target_chunk(targets: MarkerTargets, start: int, stop: int, /) -> MarkerTargets:
    """Frames [start, stop) of ``targets`` (views, no copy); gaps clipped to the chunk and
    renumbered from its first frame."""
    gaps = tuple(Gap(g.marker, max(g.start, start) - start, min(g.stop, stop) - start)
                 for g in targets.gaps if g.start < stop and g.stop > start)
    return dataclasses.replace(targets, time_s=targets.time_s[start:stop], positions_m=targets.positions_m[start:stop],
                               velocities_m_s=targets.velocities_m_s[start:stop],
                               accelerations_m_s2=targets.accelerations_m_s2[start:stop], gaps=gaps)


def chunk_bounds(n: int, size: int, /, *, first: int = 0) -> list[tuple[int, int]]:
    """[start, stop) of consecutive chunks covering n frames: the first ends at ``first`` + a multiple
    of ``size`` (a method whose first frame is special aligns the others on its blocks), the
    others hold ``size`` frames, the last the rest."""
    size = max(int(size), 1)
    edges = [0] + list(range(first + size, n, size)) + [n]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


@dataclass
class Collector:
    """A sink that keeps the chunks and joins them into the one-pass Reconstruction."""

    chunks: list = dataclasses.field(default_factory=list)

    def __call__(self, chunk: Reconstruction) -> None:
        self.chunks.append(chunk)

    def restart(self) -> None:
        """Forget the chunks: the method runs the trial again from its first frame."""
        self.chunks.clear()

    def reconstruction(self, targets: MarkerTargets, *, timings_s: Mapping[str, float],
                       info: Mapping[str, Any]) -> Reconstruction:
        c = self.chunks
        if len(c) == 1:
            return dataclasses.replace(c[0], time_s=targets.time_s, measured_m=targets.positions_m,
                                       timings_s=dict(timings_s), info=dict(info), gaps=tuple(targets.gaps))
        join = {name: np.concatenate([getattr(r, name) for r in c]) for name in
                ("q_rad", "qd_rad_s", "qdd_rad_s2", "model_points_m", "residuals_m", "constraint",
                 "constraint_velocity", "status")}
        return dataclasses.replace(c[0], time_s=targets.time_s, measured_m=targets.positions_m,
                                   timings_s=dict(timings_s), info=dict(info), gaps=tuple(targets.gaps), **join)


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
