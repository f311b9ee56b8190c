"""Pair distances of a trial's markers, the evidence of the label checks (exubio.trust.labels): the
median and spread of every pairwise distance over a trial, the same-segment distances of a
calibrated model as a reference, and a trial's positions in protocol order."""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from exubio.errors import InputError
from exubio.types import MarkerTargets, Model, Protocol

__all__ = ["PAIR_BLOCK_VALUES", "PairDistances", "in_protocol_order", "mm_text", "model_pair_distances", "pair_distances",
           "reference_matrix"]


@dataclass(frozen=True)
class PairDistances:
    """Median distance of every pair of markers over a trial.

    names:     marker names (rows and columns).
    median_m:  (k, k) median over the frames where both are present (NaN: never together).
    spread_m:  (k, k) standard deviation over those frames.
    n_frames:  (k, k) number of those frames.
    source:    the trial (or model) they come from.
    step_m:    (k, k) the largest change of the distance from one sample where both are present to
               the next (across a gap too): a label that jumps to another marker changes it at once,
               skin motion and noise a little at a time. None where not computed.
    """

    names: tuple[str, ...]
    median_m: np.ndarray
    spread_m: np.ndarray
    n_frames: np.ndarray
    source: str = ""
    step_m: np.ndarray | None = None

    def get(self, a: str, b: str) -> float:
        """Median distance (m) of markers a and b; NaN if either is unknown or never seen."""
        if a not in self.names or b not in self.names:
            return float("nan")
        return float(self.median_m[self.names.index(a), self.names.index(b)])


def _as_positions(positions_m: np.ndarray, names: Sequence[str]) -> np.ndarray:
    pos = np.asarray(positions_m, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3 or pos.shape[1] != len(names):
        raise InputError(f"positions must have shape (n_frames, {len(names)}, 3), got {pos.shape}")
    if len(set(names)) != len(names):
        raise InputError(f"duplicate marker names in {list(names)}")
    bad = ~np.isfinite(pos).all(axis=2)  # a sample with a non-finite coordinate is missing: all NaN
    if (bad & ~np.isnan(pos).all(axis=2)).any():  # copied only when that changes something (long trials)
        pos = pos.copy()
        pos[bad] = np.nan
    return pos


PAIR_BLOCK_VALUES = 2_000_000
"""pair_distances takes the distances of this many values' worth of marker pairs at a time (16 MB,
~50 MB of working copies; a 25 s trial at 200 Hz: 133 of the 231 pairs of 22 markers at once, a
20-minute one: 2)."""


def pair_distances(positions_m: np.ndarray, names: Sequence[str], /, *, source: str = "") -> PairDistances:
    """Median and standard deviation of every pairwise marker distance over the frames of
    ``positions_m`` (n_frames, k, 3) where both markers are present (NaN = gap)."""
    names = tuple(names)
    pos = _as_positions(positions_m, names)
    k = len(names)
    med = np.full((k, k), np.nan)
    sd = np.full((k, k), np.nan)
    cnt = np.zeros((k, k), dtype=int)
    step = np.full((k, k), np.nan)
    # each pair once (|A-B| and |B-A| are the same numbers, (a - b)^2 = (b - a)^2 exactly), all
    # pairs in one array: the median and SD of every column are those of the pair's own series
    iu_all, ju_all = np.triu_indices(k, 1)
    cnt[np.arange(k), np.arange(k)] = np.isfinite(pos).all(axis=2).sum(axis=0)
    per = max(PAIR_BLOCK_VALUES // max(3 * pos.shape[0], 1), 1)  # pairs at a time: bounded memory on long trials
    for a in range(0, len(iu_all), per):
        iu, ju = iu_all[a:a + per], ju_all[a:a + per]
        d = _distances(pos, iu, ju)  # (n, pairs of the block), laid out pair by pair
        c = np.isfinite(d).sum(axis=0)
        cnt[iu, ju] = cnt[ju, iu] = c
        seen = c > 0
        if seen.any():
            # d[:, seen] is laid out column by column (as the rows of partners were): numpy sums each
            # column as one contiguous series, whatever the number of columns (bit-identical results)
            dm = d[:, seen]
            clean = bool(np.isfinite(dm).all())
            m = np.median(dm, axis=0) if clean else np.nanmedian(dm, axis=0)
            v = np.std(dm, axis=0) if clean else np.nanstd(dm, axis=0)
            med[iu[seen], ju[seen]] = med[ju[seen], iu[seen]] = m
            sd[iu[seen], ju[seen]] = sd[ju[seen], iu[seen]] = v
            st = _largest_step(dm)
            step[iu[seen], ju[seen]] = step[ju[seen], iu[seen]] = st
    np.fill_diagonal(med, 0.0)
    np.fill_diagonal(sd, 0.0)
    np.fill_diagonal(step, 0.0)
    return PairDistances(names=names, median_m=med, spread_m=sd, n_frames=cnt, source=source, step_m=step)


def _distances(pos: np.ndarray, iu: np.ndarray, ju: np.ndarray, /) -> np.ndarray:
    """(n, pairs) distances |pos[:, iu] - pos[:, ju]| (NaN where either marker is missing), each
    pair's series contiguous (Fortran order: the layout np.linalg.norm(pos[:, iu] - pos[:, ju],
    axis=2) gives, which the medians and SDs above are taken over): the compiled kernel
    exubio.model.batch_kernels.pair_distance_series, bit for bit that numpy expression, without its
    whole-trial (n, pairs, 3) differences."""
    from exubio.model import batch_kernels as kernels  # numba: imported where used

    out = np.empty((len(iu), pos.shape[0]))
    kernels.pair_distance_series(np.ascontiguousarray(pos, dtype=float), iu.astype(np.int64), ju.astype(np.int64), out)
    return out.T


def _largest_step(d: np.ndarray) -> np.ndarray:
    """(p,): per column of d (n, p), the largest |change| from one finite sample to the next finite
    one (a gap between them bridged)."""
    n, p = d.shape
    finite = np.isfinite(d)
    if finite.all():
        return np.abs(np.diff(d, axis=0)).max(axis=0) if n > 1 else np.zeros(p)
    last = np.maximum.accumulate(np.where(finite, np.arange(n)[:, None], -1), axis=0)
    before = np.vstack([np.full((1, p), -1), last[:-1]])  # the last finite sample strictly before
    valid = finite & (before >= 0)
    prev = d[np.clip(before, 0, None), np.arange(p)[None, :]]
    out = np.where(valid, np.abs(d - prev), 0.0).max(axis=0) if n else np.zeros(p)
    return out


def model_pair_distances(model: Model, protocol: Protocol, /) -> PairDistances:
    """Distances between the protocol markers that lie on the same segment, from their local
    positions (m): a reference for the rigid-pair check when no static trial is at hand. Pairs on
    different segments are NaN (they depend on the posture). Meant for a calibrated model, whose
    marker points are where the subject's markers are."""
    names = protocol.marker_names
    k = len(names)
    med = np.full((k, k), np.nan)
    for i, j in itertools.product(range(k), repeat=2):
        mi, mj = protocol.markers[i], protocol.markers[j]
        if mi.segment == mj.segment:
            med[i, j] = float(np.linalg.norm(mi.local_position_m - mj.local_position_m))
    seen = np.isfinite(med)
    return PairDistances(names=names, median_m=med, spread_m=np.where(seen, 0.0, np.nan),
                         n_frames=seen.astype(int), source=model.source or model.name)


def reference_matrix(reference: PairDistances | None, names: Sequence[str]) -> np.ndarray | None:
    if reference is None:
        return None
    k = len(names)
    out = np.full((k, k), np.nan)
    idx = [reference.names.index(n) if n in reference.names else -1 for n in names]
    for a, ia in enumerate(idx):
        for b, ib in enumerate(idx):
            if ia >= 0 and ib >= 0:
                out[a, b] = reference.median_m[ia, ib]
    return out


def in_protocol_order(trial: MarkerTargets | np.ndarray, marker_names: Sequence[str] | None,
                       protocol: Protocol) -> np.ndarray:
    if isinstance(trial, MarkerTargets):
        pos, names = trial.positions_m, trial.marker_names
    else:
        if marker_names is None:
            raise InputError("check_trial: give marker_names with a positions array")
        pos, names = trial, tuple(marker_names)
    pos = _as_positions(pos, tuple(names))
    if tuple(names) == protocol.marker_names:  # already in protocol order: no copy
        return pos
    out = np.full((pos.shape[0], len(protocol.markers), 3), np.nan)
    for j, name in enumerate(protocol.marker_names):
        if name in names:
            out[:, j] = pos[:, list(names).index(name)]
    return out


def mm_text(x: float) -> str:
    return f"{x * 1000:.0f} mm"
