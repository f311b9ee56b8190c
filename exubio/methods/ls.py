"""Constrained least-squares (LS) reconstruction, the paper's reference method (Eq. 9): the pose of
every frame solved from its markers (exubio.methods.poses: Gauss-Newton SQP with the ellipsoid
constraints, warm-started block by block) and its consistent rates, streamed in chunks
(exubio.methods.common). A frame's status says whether it converged, and the info of ``stream_ls``
counts the stop reasons (exubio.types.StopReason)."""
from __future__ import annotations

import logging
import time
from typing import Callable

import numpy as np

from exubio.methods.lsq import stop_counts
from exubio.protocol.bind import Binding, bind
from exubio.types import StopReason
from exubio.methods.common import CHUNK_FRAMES, ChunkSink, Collector, assemble, chunk_bounds, target_chunk
from exubio.methods.poses import MIN_MARKERS, RATES_REGULARISATION, Limits, LSOptions, solve_positions, solve_rates
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Reconstruction

__all__ = ["LSOptions", "reconstruct_ls", "stream_ls"]

log = logging.getLogger(__name__)


def reconstruct_ls(model: Model, protocol: Protocol, targets: MarkerTargets, /, *,
                   options: LSOptions = LSOptions(), q_start: np.ndarray | None = None,
                   progress: Callable[[int], None] | None = None) -> Reconstruction:
    """Reconstruct a trial with the constrained least-squares method (``model`` and ``protocol``
    bound here: a run takes its session's binding, stream_ls)."""
    chunks = Collector()
    timings, info = stream_ls(bind(model, protocol), targets, chunks, options=options, q_start=q_start, progress=progress,
                              chunk_frames=max(targets.n_frames, 1))
    return chunks.reconstruction(targets, timings_s=timings, info=info)


def stream_ls(binding: Binding, targets: MarkerTargets, sink: ChunkSink, /, *,
              options: LSOptions = LSOptions(), q_start: np.ndarray | None = None,
              progress: Callable[[int], None] | None = None,
              chunk_frames: int = CHUNK_FRAMES) -> tuple[dict[str, float], dict]:
    """Reconstruct a trial with the constrained least-squares method, handing the result to ``sink``
    in chunks of about ``chunk_frames`` frames (exubio.methods.common); each chunk starts from the
    last solution of the one before (the warm start of one pass). Returns (timings_s, info)."""
    t0 = time.perf_counter()
    model, protocol, kin, points = binding.model, binding.protocol, binding.kin, binding.points
    weights = protocol.weights
    dt = float(np.median(np.diff(targets.time_s))) if targets.n_frames > 1 else 1.0
    q0 = np.zeros(kin.n_coordinates) if q_start is None else np.asarray(q_start, dtype=float)
    held = binding.held
    q0[held] = 0.0
    limits = Limits.of(model, protocol, options.limit_stiffness_nm_per_rad)
    block = max(1, int(round(options.block_s / dt)))
    size = max(block, int(chunk_frames) // block * block)  # chunks end where one pass's blocks end
    t_pos = t_rates = t_sink = 0.0
    iters_sum, iters_max, not_converged, prev = 0, 0, 0, None
    stops = stop_counts(np.zeros(0, dtype=np.int8))
    t1 = time.perf_counter()
    for a, b in chunk_bounds(targets.n_frames, size, first=1):
        part = target_chunk(targets, a, b)
        ta = time.perf_counter()
        q, iters, converged, why = solve_positions(kin, points, part.positions_m, weights, q_start=q0,
                                                   options=options, frame_dt=dt, progress=progress, held=held,
                                                   limits=limits, q_previous=prev)
        tb = time.perf_counter()
        qd, qdd = solve_rates(kin, points, q, part.velocities_m_s, part.accelerations_m_s2, weights,
                              RATES_REGULARISATION, held, limits)
        t_pos, t_rates = t_pos + tb - ta, t_rates + time.perf_counter() - tb
        n_present = part.present.sum(axis=1)
        status = np.where(converged, FrameStatus.CONVERGED, FrameStatus.NOT_CONVERGED)
        status = np.where(n_present < MIN_MARKERS, FrameStatus.TOO_FEW_MARKERS, status)
        iters_sum, iters_max = iters_sum + int(iters.sum()), max(iters_max, int(iters.max()))
        not_converged += int((~converged).sum())
        stops = {k: v + stops[k] for k, v in stop_counts(why).items()}
        prev = q[-1]
        chunk = assemble(kin, points, part, method="ls", q=q, qd=qd, qdd=qdd, status=status, timings_s={}, info={})
        tc = time.perf_counter()
        sink(chunk)
        t_sink += time.perf_counter() - tc
    if not_converged:
        log.warning("LS: %d of %d frames did not converge (stopped by %s)", not_converged, targets.n_frames,
                    ", ".join(f"{k} in {v}" for k, v in stops.items() if v and not StopReason[k.upper()].converged))
    total = time.perf_counter() - t0 - t_sink  # the method's own time: what the sink does with the chunks is not
    timings = {"setup": t1 - t0, "positions": t_pos, "rates": t_rates, "total": total}
    info = {"iterations_mean": iters_sum / max(targets.n_frames, 1), "iterations_max": iters_max,
            "frames_not_converged": not_converged, "stop_reasons": stops, "options": options.__dict__}
    return timings, info
