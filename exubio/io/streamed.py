"""A method's result kept as it streams in (exubio.methods.common: chunks to a sink), in bounded memory.

``StreamedReconstruction`` is the sink the pipeline gives a method: it keeps the per-frame arrays of
the size of the joint coordinates (q, q̇, q̈, the residual per marker, the constraint residuals, the
status: ~0.5 kB per frame with 13 coordinates and 22 markers) and writes the model points, the only
per-marker 3-D array a method makes, to a hidden part file in the output folder as the chunks come
(``ArrayFile``). Its ``reconstruction`` is the Reconstruction without the model points in memory
(``model_points_m`` None); ``write_npz(..., streamed={"model_points_m": ...})`` copies them from the
part file into the .npz. The part file is removed by ``discard`` (also on an error; a killed run
leaves a ``.*.tmp*`` file that the next study run removes).
"""
from __future__ import annotations

import dataclasses
import errno
import os
import secrets
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from exubio.errors import InputError
from exubio.io.heap import release_freed_heap
from exubio.io.results import done_with, in_progress
from exubio.types import MarkerTargets, Reconstruction

READ_BLOCK_BYTES = 1 << 24  # ArrayFile.blocks reads about this much at a time (16 MB)


class ArrayFile:
    """A float64 array of known shape (n, ...) written to a raw file row block by row block, in order,
    and read back in blocks."""

    def __init__(self, path: Path, shape: tuple[int, ...]):
        self.path, self.shape, self.rows = Path(path), tuple(int(s) for s in shape), 0
        self.dtype = np.dtype(np.float64)
        try:
            self._fh = open(self.path, "xb")
        except OSError as exc:
            raise InputError(f"{self.path}: cannot write ({exc})") from exc
        in_progress(self.path)

    def append(self, block: np.ndarray) -> None:
        block = np.ascontiguousarray(block, dtype=self.dtype)
        if block.shape[1:] != self.shape[1:] or self.rows + block.shape[0] > self.shape[0]:
            raise ValueError(f"ArrayFile {self.path.name}: block of shape {block.shape} does not continue "
                             f"rows {self.rows} of {self.shape}")
        try:
            block.tofile(self._fh)
        except OSError as exc:  # a full disk: numpy says only "N requested and M written"
            reason = exc.strerror or (f"{os.strerror(errno.ENOSPC)}: {exc}" if _disk_full(self.path.parent, block.nbytes)
                                      else str(exc))
            raise InputError(f"{self.path.parent}: cannot write ({reason}); the result of this method was not "
                             f"written") from None
        self.rows += block.shape[0]

    def restart(self) -> None:
        """Empty the file: the rows are written again from the first."""
        try:
            self._fh.seek(0)
            self._fh.truncate()
        except OSError as exc:
            raise InputError(f"{self.path.parent}: cannot write ({exc.strerror or exc})") from None
        self.rows = 0

    def blocks(self) -> Iterator[np.ndarray]:
        """The rows written, in blocks of about READ_BLOCK_BYTES."""
        try:
            self._fh.flush()
        except OSError as exc:
            raise InputError(f"{self.path.parent}: cannot write ({exc.strerror or exc})") from None
        row_bytes = int(np.prod(self.shape[1:], dtype=np.int64)) * self.dtype.itemsize
        per = max(READ_BLOCK_BYTES // max(row_bytes, 1), 1)
        with open(self.path, "rb") as fh:
            for a in range(0, self.rows, per):
                count = min(per, self.rows - a)
                yield np.fromfile(fh, dtype=self.dtype, count=count * row_bytes // self.dtype.itemsize
                                  ).reshape((count,) + self.shape[1:])

    @property
    def complete(self) -> bool:
        return self.rows == self.shape[0]

    def remove(self) -> None:
        try:
            self._fh.close()
        except OSError:  # a full disk: the file goes anyway
            pass
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
        done_with(self.path)


def _disk_full(folder: Path, wanted: int) -> bool:
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):  # not POSIX
        return False
    return st.f_bavail * st.f_frsize < wanted


def without_rates(targets: MarkerTargets, /) -> MarkerTargets:
    """``targets`` without their velocities and accelerations (read-only NaN views of the positions'
    shape, no memory): what the assessment and the files read once the methods are done. A long
    trial's rates are two thirds of its targets (207 of 311 MB on the 20-minute trial at 200 Hz)."""
    nan = np.broadcast_to(np.float64(np.nan), targets.positions_m.shape)
    return dataclasses.replace(targets, velocities_m_s=nan, accelerations_m_s2=nan)


class StreamedReconstruction:
    """The sink of one method's run on ``targets``: see the module docstring. Use as a context
    manager (the part file goes on exit) or call ``discard``."""

    def __init__(self, out_dir: str | os.PathLike, stem: str, targets: MarkerTargets, coordinate_names, /):
        n, k, m = targets.n_frames, len(targets.marker_names), len(coordinate_names)
        self.targets, self.filled = without_rates(targets), 0  # what reconstruction() reads: not the rates
        self.q, self.qd, self.qdd = (np.empty((n, m)) for _ in range(3))
        self.residuals = np.empty((n, k))
        self.constraint, self.constraint_velocity = np.empty((n, 2)), np.empty((n, 2))
        self.status = np.empty(n, dtype=int)
        self.first: Reconstruction | None = None
        part = Path(out_dir) / f".{stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp.model_points"
        self.model_points = ArrayFile(part, (n, k, 3))

    def __call__(self, chunk: Reconstruction) -> None:
        a, b = self.filled, self.filled + chunk.n_frames
        if self.first is None:
            self.first = chunk
        self.q[a:b], self.qd[a:b], self.qdd[a:b] = chunk.q_rad, chunk.qd_rad_s, chunk.qdd_rad_s2
        self.residuals[a:b], self.status[a:b] = chunk.residuals_m, chunk.status
        self.constraint[a:b], self.constraint_velocity[a:b] = chunk.constraint, chunk.constraint_velocity
        self.model_points.append(chunk.model_points_m)
        self.filled = b

    def reconstruction(self, *, timings_s: Mapping[str, float], info: Mapping[str, Any]) -> Reconstruction:
        """The whole run, its model points left in the part file (``model_points_m`` None)."""
        release_freed_heap()  # the method's run is over: its working arrays go back to the system
        t = self.targets
        if self.first is None or self.filled != t.n_frames:
            raise ValueError(f"{t.source or 'trial'}: the method handed on {self.filled} of {t.n_frames} frames")
        return Reconstruction(
            method=self.first.method, time_s=t.time_s, coordinate_names=self.first.coordinate_names, q_rad=self.q,
            qd_rad_s=self.qd, qdd_rad_s2=self.qdd, marker_names=self.first.marker_names, model_points_m=None,
            measured_m=t.positions_m, residuals_m=self.residuals, constraint=self.constraint,
            constraint_velocity=self.constraint_velocity, status=self.status, timings_s=dict(timings_s),
            info=dict(info), gaps=tuple(t.gaps))

    def restart(self) -> None:
        """Forget what was handed on: the method runs the trial again from its first frame."""
        self.filled, self.first = 0, None
        self.model_points.restart()

    def discard(self) -> None:
        self.model_points.remove()

    def __enter__(self) -> "StreamedReconstruction":
        return self

    def __exit__(self, *exc: object) -> None:
        self.discard()
