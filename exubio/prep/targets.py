"""Turn a trial's marker trajectories into the targets a reconstruction method tracks: protocol
markers, expressed frame by frame in the ISB thorax frame, low-pass filtered, with cubic-spline
velocities and accelerations, gaps kept as NaN (never filled with zeros).

Everything is numpy float64, time first, SI units. Each step is a public function of its module
(exubio.prep.thorax: the thorax frame; exubio.prep.filtering: gaps, the low-pass filter and its
cut-offs; here: the spline derivatives); :func:`prepare_targets` chains them.
"""
from __future__ import annotations

import logging

import numpy as np
from scipy.interpolate import CubicSpline

from exubio.errors import InputError
from exubio.io.heap import release_freed_heap
from exubio.prep.filtering import as_series, detect_gaps, filter_markers, valid_runs
from exubio.prep.thorax import MAX_THORAX_GAP_S, isb_landmarks, lab_landmarks, thorax_frame, to_thorax_frame
from exubio.protocol.labels import resolve_labels
from exubio.types import MarkerTargets, Protocol, Trajectories

__all__ = ["PLAUSIBLE_MEDIAN_DISTANCE_M", "prepare_targets", "spline_derivatives"]

log = logging.getLogger(__name__)

PLAUSIBLE_MEDIAN_DISTANCE_M = (0.02, 1.5)
"""Median distance of the markers from the thorax origin that passes the unit check (m)."""


# --------------------------------------------------------------------------------------------
# Spline derivatives
# --------------------------------------------------------------------------------------------
def spline_derivatives(
    time: np.ndarray, positions: np.ndarray, /, *, at: np.ndarray | None = None, overwrite_positions: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and accelerations from a cubic spline (scipy ``CubicSpline``,
    not-a-knot ends) through each contiguous run of valid samples of each marker.

    time: (n,) strictly increasing; positions: (n, ...) with the last axis one sample.
    at:   the times to evaluate at (default: ``time``, where the returned positions are the
          input samples). Times outside every valid run, i.e. in gaps, are NaN.

    Derivatives are analytic derivatives of the spline. A run of 2 samples gives a straight
    line (constant velocity, zero acceleration); an isolated single sample gets zero velocity
    and acceleration.

    ``overwrite_positions`` (with ``at`` None): the positions returned are ``positions`` itself,
    its samples outside every valid run set to NaN (no whole-trial copy: for a caller that owns
    the array and drops it, as :func:`prepare_targets` does).
    """
    t = np.asarray(time, dtype=float)
    p = np.asarray(positions, dtype=float)
    if t.ndim != 1 or t.shape[0] != p.shape[0]:
        raise ValueError(f"time {t.shape} does not match positions {p.shape} (time first)")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise InputError("sample times must be strictly increasing")
    s = as_series(p)
    t_out = t if at is None else np.asarray(at, dtype=float)
    shape_out = (t_out.shape[0],) + s.shape[1:]
    reuse = overwrite_positions and at is None
    pos = s if reuse else np.full(shape_out, np.nan)
    vel = np.full(shape_out, np.nan)
    acc = np.full(shape_out, np.nan)
    for j in range(s.shape[1]):
        valid = np.isfinite(s[:, j]).all(axis=1)
        if reuse:
            s[~valid, j] = np.nan  # what the copy holds there; the valid runs, the splines' data, stay as they are
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
            if not reuse:
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
        landmarks = lab_landmarks(trajectories, protocol, match, max_thorax_gap_s=max_thorax_gap_s)
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
        pos, applied = filter_markers(pos, names, protocol, trajectories.rate_hz, src)

    time = trajectories.time_s
    at = None
    if resample_hz is not None:
        if not resample_hz > 0:
            raise InputError(f"resample_hz must be > 0, got {resample_hz}")
        n_new = int(np.floor((time[-1] - time[0]) * resample_hz + 1e-9)) + 1
        at = time[0] + np.arange(n_new) / resample_hz
    try:
        pos, vel, acc = spline_derivatives(time, pos, at=at, overwrite_positions=True)  # pos: this function's own
    except InputError as exc:
        raise InputError(f"{src}: {exc}") from None
    time_out = time.copy() if at is None else at
    release_freed_heap()  # the filter's and the splines' working arrays, freed: back to the system
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
