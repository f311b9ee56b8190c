"""Turn a trial's marker trajectories into the targets a reconstruction method tracks: protocol
markers, expressed frame by frame in the ISB thorax frame, low-pass filtered, with cubic-spline
velocities and accelerations, gaps kept as NaN (never filled with zeros).

Everything is numpy float64, time first, SI units. Each step is a public function;
:func:`prepare_targets` chains them.
"""
from __future__ import annotations

import functools
import logging
from typing import Sequence

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, filtfilt

from exubio.errors import InputError
from exubio.protocol.load import resolve_labels
from exubio.types import Gap, MarkerTargets, Protocol, Trajectories

__all__ = [
    "AUTO_CUTOFF_BOUNDS_HZ",
    "AUTO_CUTOFF_STEP_HZ",
    "FIT_PERIODS",
    "MAX_THORAX_GAP_S",
    "PAD_PERIODS",
    "PLAUSIBLE_MEDIAN_DISTANCE_M",
    "RESIDUAL_NOISE_BAND",
    "detect_gaps",
    "fill_short_gaps",
    "lowpass",
    "prepare_targets",
    "residual_cutoffs",
    "spline_derivatives",
    "thorax_frame",
    "to_thorax_frame",
    "isb_landmarks",
    "valid_runs",
]

log = logging.getLogger(__name__)

MAX_THORAX_GAP_S = 0.25
"""Thorax-landmark gaps up to this long are bridged by linear interpolation (held at the ends)."""

PLAUSIBLE_MEDIAN_DISTANCE_M = (0.02, 1.5)
"""Median distance of the markers from the thorax origin that passes the unit check (m)."""


# --------------------------------------------------------------------------------------------
# Thorax frame
# --------------------------------------------------------------------------------------------
def thorax_frame(
    ij: np.ndarray, px: np.ndarray, c7: np.ndarray, t8: np.ndarray, /
) -> tuple[np.ndarray, np.ndarray]:
    """ISB thorax frame (Wu et al. 2005, J Biomech 38:981) from its four landmarks.

    ij, px, c7, t8: (n, 3) (or (3,)) lab positions of incisura jugularis, processus xiphoideus,
    C7 and T8. Returns ``R`` (n, 3, 3), whose columns are the X, Y, Z axes in lab coordinates,
    and ``origin`` (n, 3) = IJ:

    * Y: from the midpoint of PX and T8 to the midpoint of IJ and C7 (up);
    * Z: normal to the plane of IJ, C7 and the PX-T8 midpoint, pointing to the right;
    * X = Y x Z (anterior).

    Frames with a missing landmark are NaN. Coincident or collinear landmarks raise InputError.
    """
    ij, px, c7, t8 = (np.asarray(a, dtype=float) for a in (ij, px, c7, t8))
    mid_up = 0.5 * (ij + c7)
    mid_low = 0.5 * (px + t8)
    y = mid_up - mid_low
    z = np.cross(ij - c7, mid_up - mid_low)
    ny = np.linalg.norm(y, axis=-1, keepdims=True)
    nz = np.linalg.norm(z, axis=-1, keepdims=True)
    scale = np.linalg.norm(ij - c7, axis=-1, keepdims=True) * ny
    bad = (ny <= 1e-12) | (nz <= 1e-9 * np.maximum(scale, 1e-300))
    bad &= np.isfinite(ny) & np.isfinite(nz)
    if np.any(bad):
        frames = np.flatnonzero(bad.reshape(-1))
        raise InputError(
            f"thorax landmarks are coincident or collinear in {frames.size} frame(s) (first: {frames[0]}); "
            f"IJ, C7 and the PX-T8 midpoint must span a plane"
        )
    y = y / ny
    z = z / nz
    x = np.cross(y, z)
    z = np.cross(x, y)  # exactly orthonormal despite rounding
    rot = np.stack([x, y, z], axis=-1)
    return rot, ij.copy()


def isb_landmarks(landmarks: dict[str, np.ndarray], /) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(IJ, PX, C7, T8) from the landmarks a protocol names: either those four, or IJ with the
    midpoints IJ-C7 and PX-T8 (then C7 = 2 mid_up - IJ and PX = T8 = mid_low, which give the same
    ISB axes: Y through the two midpoints, Z normal to the plane of IJ, C7 and the PX-T8 midpoint)."""
    if "c7" in landmarks:
        return landmarks["ij"], landmarks["px"], landmarks["c7"], landmarks["t8"]
    ij, up, low = landmarks["ij"], landmarks["ij_c7_midpoint"], landmarks["px_t8_midpoint"]
    return ij, low, 2.0 * up - ij, low


def to_thorax_frame(positions: np.ndarray, rot: np.ndarray, origin: np.ndarray, /) -> np.ndarray:
    """Express lab positions (n, k, 3) in the frame (R (n, 3, 3), origin (n, 3)) of each frame:
    ``R^T (p - origin)``. A single frame (R (3, 3), origin (3,)) applies to every sample."""
    p = np.asarray(positions, dtype=float)
    rot = np.asarray(rot, dtype=float)
    origin = np.asarray(origin, dtype=float)
    if rot.ndim == 2:
        return (p - origin) @ rot
    return np.einsum("nji,nkj->nki", rot, p - origin[:, None, :])


# --------------------------------------------------------------------------------------------
# Gaps
# --------------------------------------------------------------------------------------------
def _as_series(positions: np.ndarray) -> np.ndarray:
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
    s = _as_series(p).copy()
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
# Filtering and derivatives
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
    the noise (0.72 deg on the 1.5 mm benchmark against 0.65); measurements: benchmarks/README.md,
    "Filter cut-off and end padding".
    The fit is a regression over the end window, so a noisy end sample is not amplified. Runs of
    at most 3 (order + 1) samples are left unfiltered (logged). The last axis is one sample
    (e.g. (n, k, 3)); a 1-D input is one scalar series. Returns a new array.
    """
    p = np.asarray(positions, dtype=float)
    s = _as_series(p)
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
def _butter(order: int, cutoff_hz: float, rate_hz: float, /) -> tuple[np.ndarray, np.ndarray]:
    """The Butterworth design (b, a) of one cut-off, made once per process (the residual analysis
    filters at the same 52 cut-offs for every trial). The arrays are shared: not to be modified."""
    b, a = butter(order, cutoff_hz, btype="low", fs=rate_hz)
    b.setflags(write=False)
    a.setflags(write=False)
    return b, a


def _filtfilt_run(seg: np.ndarray, b: np.ndarray, a: np.ndarray, /, *, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """filtfilt of one run (time first) extended at both ends by its cubic end fits."""
    n = seg.shape[0]
    flat = seg.reshape(n, -1)
    period = rate_hz / cutoff_hz  # samples
    pad = max(int(round(PAD_PERIODS * period)), 1)
    window = min(n, max(int(round(FIT_PERIODS * period)), _MIN_FIT_SAMPLES))
    head = _polynomial_extension(flat[:window], pad)
    tail = _polynomial_extension(flat[::-1][:window], pad)[::-1]
    # time along the last, contiguous axis: scipy's lfilter runs ~25 % faster than along axis 0 of
    # (time, series), with the same recursion per series (bit-identical results)
    ext = np.empty((flat.shape[1], n + 2 * pad))
    ext[:, :pad] = head.T
    ext[:, pad:pad + n] = flat.T
    ext[:, pad + n:] = tail.T
    filtered = filtfilt(b, a, ext, axis=1, padtype=None)
    return filtered[:, pad:pad + n].T.reshape(seg.shape)


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
sigma at 100 and 200 Hz; section "Filter cut-off and end padding" of benchmarks/README.md)."""

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
    s = _as_series(positions)
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
    for i, c in enumerate(cutoffs):
        diff = _lowpass_series(s, rate_hz=rate_hz, cutoff_hz=c, order=order, runs=runs)[0] - s
        diff[~used] = 0.0
        sq = np.einsum("nmd,nmd->m", diff, diff)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[i] = np.sqrt(sq / count)
    return out


def spline_derivatives(
    time: np.ndarray, positions: np.ndarray, /, *, at: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and accelerations from a cubic spline (scipy ``CubicSpline``,
    not-a-knot ends) through each contiguous run of valid samples of each marker.

    time: (n,) strictly increasing; positions: (n, ...) with the last axis one sample.
    at:   the times to evaluate at (default: ``time``, where the returned positions are the
          input samples). Times outside every valid run, i.e. in gaps, are NaN.

    Derivatives are analytic derivatives of the spline. A run of 2 samples gives a straight
    line (constant velocity, zero acceleration); an isolated single sample gets zero velocity
    and acceleration.
    """
    t = np.asarray(time, dtype=float)
    p = np.asarray(positions, dtype=float)
    if t.ndim != 1 or t.shape[0] != p.shape[0]:
        raise ValueError(f"time {t.shape} does not match positions {p.shape} (time first)")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise InputError("sample times must be strictly increasing")
    s = _as_series(p)
    t_out = t if at is None else np.asarray(at, dtype=float)
    shape_out = (t_out.shape[0],) + s.shape[1:]
    pos = np.full(shape_out, np.nan)
    vel = np.full(shape_out, np.nan)
    acc = np.full(shape_out, np.nan)
    for j in range(s.shape[1]):
        valid = np.isfinite(s[:, j]).all(axis=1)
        for start, stop in valid_runs(valid):
            t0, t1 = t[start], t[stop - 1]
            if at is None:
                sel = slice(start, stop)
            else:
                sel = np.flatnonzero((t_out >= t0) & (t_out <= t1))
                if sel.size == 0:
                    continue
            if stop - start == 1:
                pos[sel, j] = s[start, j]
                vel[sel, j] = 0.0
                acc[sel, j] = 0.0
                continue
            spline = CubicSpline(t[start:stop], s[start:stop, j], axis=0)
            tt = t_out[sel]
            pos[sel, j] = s[start:stop, j] if at is None else spline(tt)
            vel[sel, j] = spline(tt, 1)
            acc[sel, j] = spline(tt, 2)
    shape = (t_out.shape[0],) + p.shape[1:] if p.ndim > 1 else (t_out.shape[0],)
    return pos.reshape(shape), vel.reshape(shape), acc.reshape(shape)


# --------------------------------------------------------------------------------------------
# The whole chain
# --------------------------------------------------------------------------------------------
def preparation_key(protocol: Protocol, /) -> tuple:
    """What :func:`prepare_targets` reads of a protocol: two protocols of equal keys prepare a trial
    into the same targets (a protocol bound to a calibrated model differs only in its markers'
    local positions, which preparation does not read)."""
    return (protocol.name, protocol.source, tuple((m.name, m.aliases, m.optional) for m in protocol.markers),
            protocol.thorax_frame, protocol.cutoff_hz, protocol.filter_order, tuple(sorted(protocol.relabel.items())),
            protocol.side)


def prepare_targets(
    trajectories: Trajectories,
    protocol: Protocol,
    /,
    *,
    resample_hz: float | None = None,
    max_thorax_gap_s: float = MAX_THORAX_GAP_S,
) -> MarkerTargets:
    """Protocol markers of a trial as reconstruction targets.

    1. match the trial labels to the protocol (name, then aliases; extra labels are logged);
    2. take the protocol markers in protocol order (a missing optional marker is all NaN);
    3. express them frame by frame in the ISB thorax frame (unless the protocol's frame is the
       identity); thorax-landmark gaps up to ``max_thorax_gap_s`` are bridged, longer ones make
       every marker missing in those frames;
    4. check that the marker cloud has a plausible size in metres (unit trap);
    5. low-pass filter (:func:`lowpass`, protocol cutoff and order; skipped when the cutoff is
       None); with cutoff ``"auto"`` each marker gets its own cut-off from Winter's residual
       analysis of its thorax-frame positions (:func:`residual_cutoffs`). The cut-offs applied
       are returned in ``MarkerTargets.cutoff_hz``;
    6. cubic-spline velocities and accelerations, at the trial's sample times or, with
       ``resample_hz``, on a new uniform time grid over the same span.

    A non-optional marker seen in fewer than 2 frames raises InputError naming it and the file.
    """
    src = trajectories.source or "trajectories"
    match = resolve_labels(protocol, trajectories.labels, source=trajectories.source)
    if match.unused:
        log.info("%s: labels not used by protocol '%s': %s", src, protocol.name, list(match.unused))
    n = trajectories.n_frames
    if n < 2:
        raise InputError(f"{src}: the trial has {n} frame(s); need at least 2")
    raw = trajectories.positions_m
    names = protocol.marker_names

    pos = np.full((n, len(names), 3), np.nan)
    for j, name in enumerate(names):
        col = match.columns[name]
        if col is not None:
            pos[:, j] = raw[:, col]
        else:
            log.info("%s: optional marker '%s' is not in the trial", src, name)
    pos[~np.isfinite(pos).all(axis=2)] = np.nan

    if not protocol.thorax_frame.is_identity:
        max_gap = int(round(max_thorax_gap_s * trajectories.rate_hz))
        landmarks = {}
        for key, col in match.thorax_columns.items():
            label = getattr(protocol.thorax_frame, key)
            lm = raw[:, col].copy()
            lm[~np.isfinite(lm).all(axis=1)] = np.nan
            valid = ~np.isnan(lm).any(axis=1)
            if not valid.any():
                raise InputError(
                    f"{src}: thorax landmark '{label}' (thorax_frame.{key}) is missing in every frame; "
                    f"the thorax frame cannot be built"
                )
            filled = fill_short_gaps(lm, max_gap_frames=max_gap)
            still = np.isnan(filled).any(axis=1)
            if still.any():
                log.warning(
                    "%s: thorax landmark '%s' is missing in %d frame(s) after bridging gaps up to %d "
                    "frames; every marker is missing there", src, label, int(still.sum()), max_gap,
                )
            landmarks[key] = filled
        try:
            rot, origin = thorax_frame(*isb_landmarks(landmarks))
        except InputError as exc:
            raise InputError(f"{src}: {exc}") from None
        pos = to_thorax_frame(pos, rot, origin)
    if protocol.side == "left":
        # a left arm is mirrored through the thorax's sagittal plane (Z -> -Z of the ISB thorax
        # frame) onto the right-arm model; its joint angles then carry the right arm's signs
        pos = pos * np.array([1.0, 1.0, -1.0])

    for j, m in enumerate(protocol.markers):
        n_valid = int((~np.isnan(pos[:, j]).any(axis=1)).sum())
        if n_valid >= 2:
            continue
        seen = "missing in every frame (all NaN)" if n_valid == 0 else "present in only 1 frame"
        col = match.columns[m.name]
        if m.optional:
            if col is not None:
                log.warning("%s: optional marker '%s' is %s; ignored", src, m.name, seen)
            pos[:, j] = np.nan
            continue
        label = trajectories.labels[col] if col is not None else m.name
        raise InputError(
            f"{src}: marker '{m.name}' (trial label '{label}') is {seen} ({n_valid} of {n} frames valid); "
            f"a tracked marker needs at least 2 frames (mark it 'optional: true' in the protocol to allow this)"
        )

    _check_units(pos, trajectories, src)

    applied: dict[str, float] = {}
    if protocol.cutoff_hz is not None:
        pos, applied = _filter_markers(pos, names, protocol, trajectories.rate_hz, src)

    time = trajectories.time_s
    at = None
    if resample_hz is not None:
        if not resample_hz > 0:
            raise InputError(f"resample_hz must be > 0, got {resample_hz}")
        n_new = int(np.floor((time[-1] - time[0]) * resample_hz + 1e-9)) + 1
        at = time[0] + np.arange(n_new) / resample_hz
    try:
        pos, vel, acc = spline_derivatives(time, pos, at=at)
    except InputError as exc:
        raise InputError(f"{src}: {exc}") from None
    time_out = time.copy() if at is None else at
    return MarkerTargets(
        time_s=time_out,
        marker_names=names,
        positions_m=pos,
        velocities_m_s=vel,
        accelerations_m_s2=acc,
        gaps=detect_gaps(pos, names),
        source=trajectories.source,
        cutoff_hz=applied,
    )


def _filter_markers(
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


def _check_units(pos: np.ndarray, trajectories: Trajectories, src: str) -> None:
    """The trap of millimetres read as metres (or converted twice): markers of an arm lie a few
    centimetres to about a metre from the thorax origin."""
    dist = np.linalg.norm(pos, axis=2)
    dist = dist[np.isfinite(dist)]
    if dist.size == 0:
        raise InputError(f"{src}: no protocol marker has a valid sample in any frame")
    median = float(np.median(dist))
    lo, hi = PLAUSIBLE_MEDIAN_DISTANCE_M
    if lo <= median <= hi:
        return
    declared = trajectories.units_in_file
    if median > hi:
        why = "the data look like millimetres taken as metres"
    else:
        why = "the data look like metres taken as millimetres (converted twice?)"
    raise InputError(
        f"{src}: the median marker distance from the thorax origin is {median:.4g} m, expected "
        f"{lo}-{hi} m; {why} (the file declares units '{declared}')"
    )
