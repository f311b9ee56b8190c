"""Turn a trial's marker trajectories into the targets a reconstruction method tracks: protocol
markers, expressed frame by frame in the ISB thorax frame, low-pass filtered, with cubic-spline
velocities and accelerations, gaps kept as NaN (never filled with zeros).

Everything is numpy float64, time first, SI units. Each step is a public function;
:func:`prepare_targets` chains them.
"""
from __future__ import annotations

import logging
from typing import Sequence

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, filtfilt

from exubio.errors import InputError
from exubio.protocol import resolve_labels
from exubio.types import Gap, MarkerTargets, Protocol, Trajectories

__all__ = [
    "MAX_THORAX_GAP_S",
    "PLAUSIBLE_MEDIAN_DISTANCE_M",
    "detect_gaps",
    "fill_short_gaps",
    "lowpass",
    "prepare_targets",
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
def lowpass(positions: np.ndarray, /, *, rate_hz: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Zero-lag Butterworth low-pass (scipy ``butter`` + ``filtfilt``), time along axis 0.

    The filter of the given ``order`` is designed at ``cutoff_hz`` and run forward and backward,
    so there is no phase lag and the effective order doubles (a 2nd-order design gives a
    4th-order response, attenuated to 1/2 rather than 1/sqrt(2) at the cutoff; no cutoff
    correction is applied, as in the paper's "2nd-order zero-lag Butterworth at 2 Hz").

    Each contiguous run of valid samples of each marker is filtered separately: gaps stay NaN
    and are never filled. Each run is extended at both ends by odd reflection over one cutoff
    period (``rate_hz / cutoff_hz`` samples, fewer in a shorter run), which keeps end transients
    small; runs of at most 3 (order + 1) samples are left unfiltered (logged). The last axis is one sample (e.g. (n, k, 3)); a 1-D input is one
    scalar series. Returns a new array.
    """
    if not 0 < cutoff_hz < 0.5 * rate_hz:
        raise InputError(
            f"low-pass cutoff {cutoff_hz} Hz must be > 0 and below the Nyquist frequency "
            f"{0.5 * rate_hz} Hz of data sampled at {rate_hz} Hz"
        )
    if int(order) != order or order < 1:
        raise ValueError(f"filter order must be a whole number >= 1, got {order!r}")
    b, a = butter(int(order), cutoff_hz, btype="low", fs=rate_hz)
    min_len = 3 * max(len(a), len(b))  # scipy's default padding: shorter runs are not filtered
    pad_wanted = max(min_len, int(round(rate_hz / cutoff_hz)))
    p = np.asarray(positions, dtype=float)
    s = _as_series(p)
    out = np.full_like(s, np.nan)
    n_short = 0
    for j in range(s.shape[1]):
        valid = np.isfinite(s[:, j]).all(axis=1)
        for start, stop in valid_runs(valid):
            seg = s[start:stop, j]
            if stop - start > min_len:
                pad = min(pad_wanted, stop - start - 1)
                out[start:stop, j] = filtfilt(b, a, seg, axis=0, padtype="odd", padlen=pad)
            else:
                out[start:stop, j] = seg
                n_short += 1
    if n_short:
        log.info(
            "low-pass: %d run(s) of valid samples no longer than %d samples left unfiltered",
            n_short, min_len,
        )
    return out.reshape(p.shape)


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
    5. low-pass filter (protocol cutoff and order; skipped when the cutoff is None);
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

    if protocol.cutoff_hz is not None:
        try:
            pos = lowpass(pos, rate_hz=trajectories.rate_hz, cutoff_hz=protocol.cutoff_hz,
                          order=protocol.filter_order)
        except InputError as exc:
            raise InputError(f"{src} with protocol '{protocol.source or protocol.name}': {exc}") from None

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
    )


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
