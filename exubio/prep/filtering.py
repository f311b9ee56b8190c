"""Gaps and the low-pass filter of marker trajectories: runs of valid samples, gaps found and short
ones bridged, the zero-lag Butterworth filter of each run (its ends extended by a cubic fit), the
automatic cut-off of Winter's residual analysis, and the protocol's filter applied to a trial's
markers (:func:`filter_markers`). Numpy float64, time first, gaps kept as NaN."""
from __future__ import annotations

import functools
import logging
from typing import Sequence

import numpy as np
from scipy.signal import butter, lfilter_zi

from exubio.errors import InputError
from exubio.types import Gap, Protocol

__all__ = [
    "AUTO_CUTOFF_BOUNDS_HZ",
    "AUTO_CUTOFF_STEP_HZ",
    "FIT_PERIODS",
    "PAD_PERIODS",
    "RESIDUAL_NOISE_BAND",
    "as_series",
    "detect_gaps",
    "fill_short_gaps",
    "filter_markers",
    "lowpass",
    "residual_cutoffs",
    "valid_runs",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# Gaps
# --------------------------------------------------------------------------------------------
def as_series(positions: np.ndarray) -> np.ndarray:
    """View (n, ...) as (n, m, d): m series of d-vectors (the last axis is one sample)."""
    p = np.asarray(positions, dtype=float)
    if p.ndim == 1:
        return p.reshape(-1, 1, 1)
    return p.reshape(p.shape[0], -1, p.shape[-1])


def valid_runs(valid: np.ndarray, /) -> list[tuple[int, int]]:
    """Contiguous runs [start, stop) of True in a 1-D boolean array."""
    v = np.concatenate([[False], np.asarray(valid, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(v.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def detect_gaps(positions: np.ndarray, names: Sequence[str], /) -> tuple[Gap, ...]:
    """Runs of missing samples (any coordinate NaN or infinite) of each marker of
    ``positions`` (n, k, 3), as Gaps [start, stop), in marker then time order."""
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[1] != len(names):
        raise ValueError(f"positions {p.shape} do not match {len(names)} marker names")
    missing = ~np.isfinite(p).all(axis=2)
    gaps = []
    for j, name in enumerate(names):
        gaps.extend(Gap(name, a, b) for a, b in valid_runs(missing[:, j]))
    return tuple(gaps)


def fill_short_gaps(positions: np.ndarray, /, *, max_gap_frames: int) -> np.ndarray:
    """Bridge gaps of at most ``max_gap_frames`` samples: linear interpolation inside the
    trial, the nearest sample held at its start or end. Longer gaps stay NaN. Works on
    (n, ...) arrays whose last axis is one sample; returns a new array."""
    p = np.asarray(positions, dtype=float)
    s = as_series(p).copy()
    n = s.shape[0]
    t = np.arange(n)
    for j in range(s.shape[1]):
        valid = np.isfinite(s[:, j]).all(axis=1)
        if valid.all() or not valid.any():
            continue
        for a, b in valid_runs(~valid):
            if b - a > max_gap_frames:
                continue
            if a == 0:
                s[a:b, j] = s[b, j]
            elif b == n:
                s[a:b, j] = s[a - 1, j]
            else:
                for d in range(s.shape[2]):
                    s[a:b, j, d] = np.interp(t[a:b], [a - 1, b], [s[a - 1, j, d], s[b, j, d]])
    return s.reshape(p.shape)


# --------------------------------------------------------------------------------------------
# Filtering
# --------------------------------------------------------------------------------------------
def lowpass(
    positions: np.ndarray, /, *, rate_hz: float, cutoff_hz: float | Sequence[float] | np.ndarray, order: int = 2
) -> np.ndarray:
    """Zero-lag Butterworth low-pass (scipy ``butter`` + ``filtfilt``), time along axis 0.

    The filter of the given ``order`` is designed at ``cutoff_hz`` and run forward and backward,
    so there is no phase lag and the effective order doubles (a 2nd-order design gives a
    4th-order response, attenuated to 1/2 rather than 1/sqrt(2) at the cutoff; no cutoff
    correction is applied, as in the paper's "2nd-order zero-lag Butterworth at 2 Hz").
    ``cutoff_hz`` is one number, or one per series (per marker of an (n, k, 3) array).

    Each contiguous run of valid samples of each marker is filtered separately: gaps stay NaN
    and are never filled. Ends: each run is extended at both ends by :data:`PAD_PERIODS` cut-off
    periods of a cubic polynomial least-squares fitted to the run's first (last)
    :data:`FIT_PERIODS` cut-off period of samples (at least 8 samples; the whole run when it is
    shorter, so a run shorter than the window is continued at both ends by the one cubic fitted to
    all of it), then filtered and cut back. Why a cubic: a zero-lag Butterworth of order >= 2
    passes polynomials up to degree 3 unchanged (its squared gain is 1 - O(f^4); order 1:
    1 - O(f^2), which passes lines and treats curvature at the ends as in the middle), so the
    extension of a smooth trajectory starts no transient and the ends are filtered like the
    middle. The odd reflection used before (scipy's ``padtype="odd"``: position and slope
    continuous) flips the curvature at the end and bent the ends of noise-free simulated trials by
    up to 0.6 deg at 2 Hz (RMSE over the first and last 10 frames; cubic: at most 0.1 deg). A
    quadratic, or a cubic on two periods, bent the ends more; a cubic on half a period follows
    the noise (0.72 deg on the 1.5 mm benchmark against 0.65); measurements: studies/README.md,
    "Filter cut-off and end padding".
    The fit is a regression over the end window, so a noisy end sample is not amplified. Runs of
    at most 3 (order + 1) samples are left unfiltered (logged). The last axis is one sample
    (e.g. (n, k, 3)); a 1-D input is one scalar series. Returns a new array.
    """
    p = np.asarray(positions, dtype=float)
    s = as_series(p)
    out, n_short, min_len = _lowpass_series(s, rate_hz=rate_hz, cutoff_hz=cutoff_hz, order=order)
    if n_short:
        log.info(
            "low-pass: %d run(s) of valid samples no longer than %d samples left unfiltered",
            n_short, min_len,
        )
    return out.reshape(p.shape)


PAD_PERIODS = 4.0
"""Length of the polynomial extension of each end of a run before filtering, in cut-off periods.
filtfilt starts the filter at the outer end of the extension in the steady state of a constant;
the start-up transient of a sloped extension decays by ~exp(-4.4) per period (2nd order) before
it reaches the data: 4 periods keep it below 1 micrometre even for a 12-sample run continued by a
steep cubic (2 periods: 1.8 mm there; no difference on the simulated trials)."""

FIT_PERIODS = 1.0
"""Length of the end window the cubic extension is fitted to, in cut-off periods."""

_PAD_DEGREE = 3
_MIN_FIT_SAMPLES = 8


def _min_run(order: int) -> int:
    """Runs of at most this many samples are not filtered (scipy's default filtfilt padding)."""
    return 3 * (int(order) + 1)


def _runs(s: np.ndarray, /) -> dict[tuple[int, int], list[int]]:
    """Runs [start, stop) of valid samples of (n, m, d) series -> the series that have that run."""
    valid = np.isfinite(s).all(axis=2)
    runs: dict[tuple[int, int], list[int]] = {}
    for j in range(s.shape[1]):
        for run in valid_runs(valid[:, j]):
            runs.setdefault(run, []).append(j)
    return runs


def _lowpass_series(
    s: np.ndarray, /, *, rate_hz: float, cutoff_hz, order: int,
    runs: dict[tuple[int, int], list[int]] | None = None,
) -> tuple[np.ndarray, int, int]:
    """:func:`lowpass` on (n, m, d) series (``runs``: :func:`_runs` of them, if known); returns
    (filtered, runs left unfiltered, min run length)."""
    if int(order) != order or order < 1:
        raise ValueError(f"filter order must be a whole number >= 1, got {order!r}")
    cut = np.asarray(cutoff_hz, dtype=float)
    if cut.ndim > 1 or (cut.ndim == 1 and cut.shape[0] != s.shape[1]):
        raise ValueError(f"cutoff_hz must be one number or one per series ({s.shape[1]}), got shape {cut.shape}")
    cut = np.broadcast_to(cut, (s.shape[1],))
    nyquist = 0.5 * rate_hz
    for c in np.unique(cut):
        if not 0 < c < nyquist:
            raise InputError(
                f"low-pass cutoff {c:g} Hz must be > 0 and below the Nyquist frequency "
                f"{nyquist:g} Hz of data sampled at {rate_hz:g} Hz"
            )
    min_len = _min_run(order)
    out = np.full_like(s, np.nan)
    groups: dict[tuple[float, int, int], list[int]] = {}  # equal runs and cutoffs: filtered together
    for (start, stop), cols in (_runs(s) if runs is None else runs).items():
        for j in cols:
            groups.setdefault((float(cut[j]), start, stop), []).append(j)
    n_short = 0
    for (c, start, stop), all_cols in groups.items():
        for cols in _column_blocks(all_cols, (stop - start) * s.shape[2]):
            n_short += _filter_group(s, out, cols, c, start, stop, order, rate_hz, min_len)
    return out, n_short, min_len


FILTER_BLOCK_VALUES = 4_000_000
"""A group of series filtered together holds at most this many values (32 MB; a 25 s trial's 22
markers at 200 Hz are 330,000): filtfilt's working copies of a long trial then stay bounded."""


def _column_blocks(cols: list[int], values_per_column: int, /) -> list[list[int]]:
    per = max(FILTER_BLOCK_VALUES // max(values_per_column, 1), 1)
    return [cols[a:a + per] for a in range(0, len(cols), per)]


def _filter_group(s: np.ndarray, out: np.ndarray, cols: list[int], c: float, start: int, stop: int, order: int,
                  rate_hz: float, min_len: int) -> int:
    """Filter samples [start, stop) of the series ``cols`` at cut-off c into ``out``; returns how
    many series were too short to filter (copied as they are)."""
    sel = _columns(cols)
    seg = s[start:stop, sel]
    if stop - start <= min_len:
        out[start:stop, sel] = seg
        return len(cols)
    out[start:stop, sel] = _filtfilt_run(seg, *_butter(int(order), c, float(rate_hz)), rate_hz=rate_hz, cutoff_hz=c)
    return 0


def _columns(cols: list[int], /) -> slice | list[int]:
    """The series ``cols`` (ascending) as a slice when they are consecutive (a view instead of a
    copy: every marker of a trial without gaps is one group)."""
    if cols[-1] - cols[0] + 1 == len(cols):
        return slice(cols[0], cols[-1] + 1)
    return cols


@functools.lru_cache(maxsize=256)
def _butter(order: int, cutoff_hz: float, rate_hz: float, /) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Butterworth design (b, a) of one cut-off and its steady state (scipy's ``lfilter_zi``),
    made once per process (the residual analysis filters at the same 52 cut-offs for every trial).
    The arrays are shared: not to be modified."""
    b, a = butter(order, cutoff_hz, btype="low", fs=rate_hz)
    zi = lfilter_zi(b, a)
    for x in (b, a, zi):
        x.setflags(write=False)
    return b, a, zi


def _filtfilt_run(seg: np.ndarray, b: np.ndarray, a: np.ndarray, zi: np.ndarray, /, *, rate_hz: float,
                  cutoff_hz: float) -> np.ndarray:
    """filtfilt of one run (time first) extended at both ends by its cubic end fits: scipy's
    ``filtfilt(b, a, ext, padtype=None)`` of every series, computed by the compiled kernel
    exubio.model.batch_kernels.filtfilt_columns (the same operations in the same order: bit-identical,
    about 9 times faster, as it steps every series of the run side by side)."""
    from exubio.model.batch_kernels import filtfilt_columns  # numba: imported where used

    n = seg.shape[0]
    flat = seg.reshape(n, -1)
    period = rate_hz / cutoff_hz  # samples
    pad = max(int(round(PAD_PERIODS * period)), 1)
    window = min(n, max(int(round(FIT_PERIODS * period)), _MIN_FIT_SAMPLES))
    ext = np.empty((n + 2 * pad, flat.shape[1]))  # time first, the series side by side
    ext[:pad] = _polynomial_extension(flat[:window], pad)
    ext[pad:pad + n] = flat
    ext[pad + n:] = _polynomial_extension(flat[::-1][:window], pad)[::-1]
    filtfilt_columns(b, a, zi, ext, ext)  # in place: each row is read before it is written
    return ext[pad:pad + n].reshape(seg.shape)


def _polynomial_extension(window: np.ndarray, pad: int, /) -> np.ndarray:
    """Values at samples -pad .. -1 (in that order) of the cubic least-squares fitted to
    ``window`` (w, m) at samples 0 .. w-1."""
    w = window.shape[0]
    degree = min(_PAD_DEGREE, w - 1)
    x = np.arange(w) / w
    coef = np.linalg.lstsq(np.vander(x, degree + 1), window, rcond=None)[0]
    return np.vander(np.arange(-pad, 0) / w, degree + 1) @ coef


# --------------------------------------------------------------------------------------------
# Automatic cut-off: Winter's residual analysis
# --------------------------------------------------------------------------------------------
AUTO_CUTOFF_BOUNDS_HZ = (2.0, 12.0)
"""The interval ``cutoff_hz: auto`` chooses in (Hz). Low end: the paper's 2 Hz, so ``auto`` never
filters harder than the paper did; on slow trials with a noisy thorax frame the residual criterion
alone goes to 0.3-1.9 Hz on the simulated 1.5 mm trials, which removes real motion (the 0.5 Hz
internal-external rotation: 2.4 deg RMSE at 1 Hz against 0.64 deg at 2 Hz). High end: voluntary
arm motion has its content below about 10 Hz; the real C3D and TRC trials choose 3-11.5 Hz, and
on noise-free data, where the criterion has no noise to balance and takes the upper bound, 12 Hz
reconstructs the simulated trials within 0.0002 deg. The high end is further held at or below
the start of the noise band (:data:`RESIDUAL_NOISE_BAND`), which must lie above the cut-off."""

RESIDUAL_NOISE_BAND = (0.25, 0.75)
"""The cut-offs, as fractions of the Nyquist frequency, where the residual curve is taken as
noise only and the noise line is fitted (12.5-37.5 Hz at 100 Hz). For white noise and the
2nd-order zero-lag Butterworth the residual is close to linear in the cut-off there, and the
intercept of the line fitted there is the noise RMS within about 1 % (white noise: 1.010-1.011
sigma at 100 and 200 Hz; section "Filter cut-off and end padding" of studies/README.md)."""

AUTO_CUTOFF_STEP_HZ = 0.25
"""Grid of the residual curve inside AUTO_CUTOFF_BOUNDS_HZ; the crossing is interpolated linearly."""

_NOISE_BAND_POINTS = 11


def residual_cutoffs(
    positions: np.ndarray,
    /,
    *,
    rate_hz: float,
    order: int = 2,
    bounds_hz: tuple[float, float] = AUTO_CUTOFF_BOUNDS_HZ,
) -> tuple[np.ndarray, np.ndarray]:
    """Cut-off per marker by Winter's residual analysis (Winter DA 2009, Biomechanics and Motor
    Control of Human Movement, 4th ed., section 3.4.4.3).

    For each cut-off f the residual R(f) is the RMS difference between the raw and the filtered
    samples (:func:`lowpass`, same order, same run-wise filtering and end extension; samples of
    runs too short to filter are left out). Where f lies above the signal's content, R(f) is the
    noise the filter removes and falls linearly with f: a straight line fitted to R over
    :data:`RESIDUAL_NOISE_BAND` has at f = 0 the intercept ``a``, the RMS of the noise. The
    cut-off is where R falls to ``a`` (the first grid point with R <= a, interpolated linearly
    between it and the one before): there the signal the filter removes balances the noise it
    lets through. Clipped to ``bounds_hz`` (default :data:`AUTO_CUTOFF_BOUNDS_HZ`; the upper bound
    also to the start of the noise band): R still above ``a`` at the upper bound gives the upper
    bound (e.g. noise-free data, where ``a`` is ~0), R below ``a`` at the lower bound the lower bound.

    Per marker, its three coordinates together: R is the RMS over the x, y and z residuals, so the
    choice does not depend on how the thorax axes lie relative to the motion, and one marker is
    filtered with one cut-off (filtering then commutes with rotating the frame).

    positions: (n, k, 3) (or any (n, ..., d): one cut-off per series of d-vectors; 1-D: one series).
    Returns (cutoff_hz, noise_rms) (k,) in Hz and in the units of ``positions``; NaN for a marker
    with no run long enough to filter (more than 3 (order + 1) samples).
    """
    s = as_series(positions)
    lo, hi = float(bounds_hz[0]), float(bounds_hz[1])
    nyquist = 0.5 * rate_hz
    band = (RESIDUAL_NOISE_BAND[0] * nyquist, RESIDUAL_NOISE_BAND[1] * nyquist)
    hi = min(hi, band[0])
    if not 0 < lo <= hi:
        raise InputError(
            f"automatic cut-off: data sampled at {rate_hz:g} Hz are too slow for residual analysis between "
            f"{bounds_hz[0]:g} and {bounds_hz[1]:g} Hz: its noise band starts at {band[0]:g} Hz "
            f"({RESIDUAL_NOISE_BAND[0]:g} x Nyquist); give a number for cutoff_hz"
        )
    grid = np.arange(lo, hi, AUTO_CUTOFF_STEP_HZ)
    grid = np.append(grid[grid < hi - 1e-9], hi)
    noise_grid = np.linspace(band[0], band[1], _NOISE_BAND_POINTS)
    used = _filterable(s, _min_run(order))
    residual = _residual_rms(s, used, rate_hz, np.concatenate([grid, noise_grid]), order)
    r_grid, r_noise = residual[: grid.size], residual[grid.size:]
    cutoff = np.full(s.shape[1], np.nan)
    noise = np.full(s.shape[1], np.nan)
    for j in range(s.shape[1]):
        if not used[:, j].any():
            continue
        intercept = np.polyfit(noise_grid, r_noise[:, j], 1)[1]
        noise[j] = intercept
        below = np.flatnonzero(r_grid[:, j] <= intercept)
        if below.size == 0:
            cutoff[j] = hi
        elif below[0] == 0:
            cutoff[j] = lo
        else:
            k = below[0]
            r0, r1 = r_grid[k - 1, j], r_grid[k, j]
            cutoff[j] = grid[k - 1] + (grid[k] - grid[k - 1]) * (r0 - intercept) / (r0 - r1)
    return cutoff, noise


def _filterable(s: np.ndarray, min_len: int, /) -> np.ndarray:
    """(n, m) True at the samples of runs longer than ``min_len`` (the ones :func:`lowpass` filters)."""
    out = np.zeros(s.shape[:2], dtype=bool)
    for j in range(s.shape[1]):
        for start, stop in valid_runs(np.isfinite(s[:, j]).all(axis=1)):
            if stop - start > min_len:
                out[start:stop, j] = True
    return out


def _residual_rms(s: np.ndarray, used: np.ndarray, rate_hz: float, cutoffs: np.ndarray, order: int) -> np.ndarray:
    """(len(cutoffs), m) RMS of raw minus filtered over the ``used`` samples of each series."""
    count = used.sum(axis=0) * s.shape[2]
    out = np.full((cutoffs.size, s.shape[1]), np.nan)
    runs = _runs(s)
    unused = None if used.all() else ~used  # (a trial without gaps or short runs: nothing to zero)
    for i, c in enumerate(cutoffs):
        diff = _lowpass_series(s, rate_hz=rate_hz, cutoff_hz=c, order=order, runs=runs)[0]
        diff -= s  # in place: one whole-trial array per cut-off, not two
        if unused is not None:
            diff[unused] = 0.0
        sq = np.einsum("nmd,nmd->m", diff, diff)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[i] = np.sqrt(sq / count)
    return out


# --------------------------------------------------------------------------------------------
# The protocol's filter on a trial's markers
# --------------------------------------------------------------------------------------------
def filter_markers(
    pos: np.ndarray, names: Sequence[str], protocol: Protocol, rate_hz: float, src: str
) -> tuple[np.ndarray, dict[str, float]]:
    """Low-pass the thorax-frame markers (n, k, 3) with the protocol's cut-off (a number or
    "auto"); returns the filtered positions and marker -> cut-off applied (Hz)."""
    where = f"{src} with protocol '{protocol.source or protocol.name}' (filter.cutoff_hz: {protocol.cutoff_hz!r})"
    order = protocol.filter_order
    try:
        if isinstance(protocol.cutoff_hz, str):
            if protocol.cutoff_hz != "auto":
                raise InputError(f"cutoff '{protocol.cutoff_hz}' is neither a number (Hz) nor 'auto'")
            cutoff, noise = residual_cutoffs(pos, rate_hz=rate_hz, order=order)
            chosen = {n: (round(float(c), 2), round(float(a) * 1e3, 3))
                      for n, c, a in zip(names, cutoff, noise) if np.isfinite(c)}
            log.info("%s: automatic low-pass cut-off (Hz, noise RMS mm) per marker: %s", src, chosen)
            cutoff = np.where(np.isfinite(cutoff), cutoff, AUTO_CUTOFF_BOUNDS_HZ[0])  # NaN: nothing to filter
        else:
            cutoff = np.full(len(names), float(protocol.cutoff_hz))
        filtered = lowpass(pos, rate_hz=rate_hz, cutoff_hz=cutoff, order=order)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    done = _filterable(pos, _min_run(order)).any(axis=0)
    return filtered, {n: float(c) for n, c, ok in zip(names, cutoff, done) if ok}
