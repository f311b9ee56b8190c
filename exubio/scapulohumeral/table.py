"""A trial's scapulohumeral rhythm and its averages over trials and subjects (numpy only).

HT elevation is the positive angle between the humerus and the thorax's vertical axis (minus the
ISB HT Y-X'-Y'' middle angle, which is negative). A frame is *raising* when HT elevation rises
faster than RATE_MIN_DEG_S (its rate from the elevation smoothed over RATE_WINDOW_S) in a run that
covers at least SPAN_MIN_DEG, *lowering* likewise falling; each such run is a *cycle*.

Resampling on HT elevation: each cycle's measured values are interpolated at the HT_STEP_DEG grid
points its HT range covers; a grid point between two frames of which either is not measured (or
outside the cycle) stays NaN: a value not measured is never bridged. A trial's resampled curve is
the mean of its cycles of that phase; a subject's mean and SD are over its trials, the group's
over the subjects' means (each subject counts once), with the number of trials or subjects that
have a value at each grid point.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

__all__ = ["RHYTHM_ANGLES", "HT_COLUMN", "PLANE_COLUMN", "PHASES", "HT_GRID_DEG", "TrialRhythm", "Resampled",
           "Average", "phases", "trial_rhythm", "resample", "average"]

RHYTHM_ANGLES: tuple[tuple[str, str], ...] = (
    ("ST_X_upward_rotation", "ST upward rotation"), ("ST_Y_internal_rotation", "ST internal rotation"),
    ("ST_Z_posterior_tilt", "ST posterior tilt"), ("SC_X_elevation", "SC elevation"),
    ("SC_Y_protraction", "SC protraction"), ("GH_phadke_X_elevation", "GH elevation"),
    ("GH_phadke_Z_flexion", "GH flexion"), ("GH_phadke_Y_internal_rotation", "GH internal rotation"))
"""The angles of the rhythm (columns of the angles CSV, exubio.model.angles.ANATOMICAL_ANGLES) and
their names in the figure; GH in Phadke's X-Z'-Y'' sequence, Ludewig et al. 2009's."""
HT_COLUMN = "HT_X_elevation"
PLANE_COLUMN = "HT_Y_plane_of_elevation"
PHASES = ("raising", "lowering")
RATE_MIN_DEG_S = 5.0
SPAN_MIN_DEG = 20.0
RATE_WINDOW_S = 0.1
HT_STEP_DEG = 2.0
HT_GRID_DEG = np.arange(0.0, 180.0 + HT_STEP_DEG / 2, HT_STEP_DEG)


@dataclass(frozen=True)
class TrialRhythm:
    """One trial's rhythm per frame (degrees at this edge: the figure's and the table's unit).

    ``phase``: 0 neither, 1 raising, 2 lowering; ``cycle``: the run's number (from 0, over both
    phases in time order), -1 outside; ``values_deg``, ``u_deg`` (standard uncertainty, NaN where the
    result carries none), ``measured`` (False: modelled or not measured), each (n, len(names))."""

    time_s: np.ndarray
    ht_deg: np.ndarray
    plane_deg: np.ndarray
    phase: np.ndarray
    cycle: np.ndarray
    names: tuple[str, ...]
    values_deg: np.ndarray
    u_deg: np.ndarray
    measured: np.ndarray
    signs: str = "isb"
    labels: Mapping[str, str] = field(default_factory=dict)  # angle -> its name with its sign


@dataclass(frozen=True)
class Resampled:
    """A trial's curves on HT_GRID_DEG: (2 phases, g, k) mean over its cycles, NaN where none."""

    values_deg: np.ndarray
    u_deg: np.ndarray
    n_cycles: np.ndarray  # (2, g, k) cycles with a value


@dataclass(frozen=True)
class Average:
    """Mean, SD (ddof 1; NaN below two) and count of curves on HT_GRID_DEG, each (2, g, k)."""

    mean_deg: np.ndarray
    sd_deg: np.ndarray
    n: np.ndarray


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def phases(ht_deg: np.ndarray, time_s: np.ndarray, /) -> tuple[np.ndarray, np.ndarray]:
    """(phase, cycle) per frame (TrialRhythm); frames whose HT elevation is NaN are in no phase."""
    ht = np.asarray(ht_deg, dtype=float)
    t = np.asarray(time_s, dtype=float)
    n = ht.size
    phase = np.zeros(n, dtype=np.int8)
    cycle = np.full(n, -1, dtype=int)
    if n < 3:
        return phase, cycle
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(RATE_WINDOW_S / dt)) if dt > 0 else 1)
    finite = np.isfinite(ht)
    filled = np.interp(np.arange(n), np.flatnonzero(finite), ht[finite]) if finite.sum() >= 2 else ht
    smooth = np.convolve(np.pad(filled, (w // 2, w - 1 - w // 2), mode="edge"), np.ones(w) / w, mode="valid")
    rate = np.gradient(smooth, t)
    runs = []
    for code, mask in ((1, rate > RATE_MIN_DEG_S), (2, rate < -RATE_MIN_DEG_S)):
        for a, b in _runs(mask & finite):
            if np.ptp(ht[a:b]) >= SPAN_MIN_DEG:
                runs.append((a, b, code))
    for k, (a, b, code) in enumerate(sorted(runs)):
        phase[a:b] = code
        cycle[a:b] = k
    return phase, cycle


def trial_rhythm(time_s: np.ndarray, names: Sequence[str], values_deg: np.ndarray, u_deg: np.ndarray | None,
                 measured: np.ndarray, /, *, signs: str = "isb", labels: Mapping[str, str] | None = None
                 ) -> TrialRhythm:
    """The rhythm of a trial's anatomical angles (columns ``names``, degrees, raw ISB signs: the
    middle HT angle is negative; ``measured`` (n, a) bool). ``signs`` and ``labels`` are carried
    for the figure and the table (the values stay raw ISB here). HT elevation of a
    frame where it is not measured is NaN: such a frame is in no phase."""
    names = list(names)
    missing = [c for c in (HT_COLUMN, PLANE_COLUMN, *(a for a, _ in RHYTHM_ANGLES)) if c not in names]
    if missing:
        raise KeyError(f"the angles lack {missing}: not a shoulder result of exubio.model.angles.ANATOMICAL_ANGLES")
    values_deg = np.asarray(values_deg, dtype=float)
    measured = np.asarray(measured, dtype=bool)
    u = np.full(values_deg.shape, np.nan) if u_deg is None else np.asarray(u_deg, dtype=float)
    h = names.index(HT_COLUMN)
    ht = np.where(measured[:, h], -values_deg[:, h], np.nan)
    phase, cycle = phases(ht, time_s)
    cols = [names.index(a) for a, _ in RHYTHM_ANGLES]
    return TrialRhythm(np.asarray(time_s, dtype=float), ht, values_deg[:, names.index(PLANE_COLUMN)], phase, cycle,
                       tuple(a for a, _ in RHYTHM_ANGLES), values_deg[:, cols], u[:, cols], measured[:, cols],
                       signs=signs, labels=dict(labels or {}))


def _on_grid(ht: np.ndarray, y: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """y (NaN where not measured) of one cycle at the grid points within its HT range, NaN where a
    bracketing frame is NaN."""
    order = np.argsort(ht, kind="stable")
    x, v = ht[order], y[order]
    out = np.full(grid.size, np.nan)
    if x.size < 2:
        return out
    inside = (grid >= x[0]) & (grid <= x[-1])
    j = np.clip(np.searchsorted(x, grid[inside], side="right"), 1, x.size - 1)
    x0, x1, v0, v1 = x[j - 1], x[j], v[j - 1], v[j]
    f = np.where(x1 > x0, (grid[inside] - x0) / np.where(x1 > x0, x1 - x0, 1.0), 0.0)
    out[inside] = v0 + f * (v1 - v0)  # NaN when either bracketing frame is NaN
    return out


def resample(r: TrialRhythm, /, grid: np.ndarray = HT_GRID_DEG) -> Resampled:
    """The trial's curves on ``grid``, each phase the mean of its cycles (module docstring)."""
    k = len(r.names)
    vals = np.full((2, grid.size, k), np.nan)
    us = np.full((2, grid.size, k), np.nan)
    counts = np.zeros((2, grid.size, k), dtype=int)
    for p in (1, 2):
        per_v, per_u = [], []
        for c in np.unique(r.cycle[r.phase == p]):
            sel = (r.cycle == c) & np.isfinite(r.ht_deg)
            y = np.where(r.measured[sel], r.values_deg[sel], np.nan)
            uu = np.where(r.measured[sel], r.u_deg[sel], np.nan)
            per_v.append(np.column_stack([_on_grid(r.ht_deg[sel], y[:, i], grid) for i in range(k)]))
            per_u.append(np.column_stack([_on_grid(r.ht_deg[sel], uu[:, i], grid) for i in range(k)]))
        if per_v:
            sv, su = np.stack(per_v), np.stack(per_u)
            counts[p - 1] = np.isfinite(sv).sum(axis=0)
            with np.errstate(invalid="ignore"):
                vals[p - 1] = np.where(counts[p - 1] > 0, np.nansum(sv, axis=0) / np.maximum(counts[p - 1], 1), np.nan)
                nu = np.isfinite(su).sum(axis=0)
                us[p - 1] = np.where(nu > 0, np.nansum(su, axis=0) / np.maximum(nu, 1), np.nan)
    return Resampled(vals, us, counts)


def average(curves: Sequence[np.ndarray], /) -> Average:
    """Mean, SD and count over curves (each (2, g, k), NaN where absent)."""
    if not curves:
        raise ValueError("no curve to average")
    s = np.stack(curves)
    n = np.isfinite(s).sum(axis=0)
    total = np.nansum(s, axis=0)
    mean = np.where(n > 0, total / np.maximum(n, 1), np.nan)
    dev = np.where(np.isfinite(s), s - mean, 0.0)
    sd = np.where(n > 1, np.sqrt((dev ** 2).sum(axis=0) / np.maximum(n - 1, 1)), np.nan)
    return Average(mean, sd, n)
