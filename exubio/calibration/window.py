"""The calibration window: which frames of a trial hold the static pose."""
from __future__ import annotations

import logging
import warnings

import numpy as np

from exubio.errors import InputError
from exubio.prep.filtering import valid_runs
from exubio.types import MarkerTargets

log = logging.getLogger(__name__)

STILL_SPEED_M_S = 0.05
"""Automatic static window: every marker slower than this (filtered spline velocity)."""
MIN_STILL_S = 0.2


def _nanmean(a: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmean without the warning for all-NaN slices (they stay NaN)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(a, axis=axis)



def parse_frames(text: str | None, /) -> slice | None:
    """``"A:B"`` (or ``"A:"``, ``":B"``, ``"A:B:S"``) -> slice; None or "" -> None (automatic)."""
    if text is None or not str(text).strip():
        return None
    parts = str(text).strip().split(":")
    if len(parts) not in (2, 3):
        raise InputError(f"--static-frames '{text}': expected START:STOP (frame numbers, 0-based, STOP excluded)")
    try:
        vals = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise InputError(f"--static-frames '{text}': expected whole frame numbers like 0:50") from None
    if len(vals) == 3 and vals[2] is not None and vals[2] <= 0:
        raise InputError(f"--static-frames '{text}': the step must be > 0")
    return slice(*vals)


def find_still_frames(targets: MarkerTargets, /, *, max_speed_m_s: float = STILL_SPEED_M_S,
                      min_duration_s: float = MIN_STILL_S) -> slice:
    """The longest run of frames in which every present marker moves slower than
    ``max_speed_m_s`` (filtered spline velocities). If no run lasts ``min_duration_s``: the
    stretch of that length whose fastest marker is slowest on average (logged)."""
    n = targets.n_frames
    speed = np.linalg.norm(targets.velocities_m_s, axis=2)
    fastest = np.max(np.where(np.isnan(speed), -np.inf, speed), axis=1)  # the fastest marker per frame
    fastest[~np.isfinite(fastest)] = np.inf  # no marker at all: not still
    dt = float(np.median(np.diff(targets.time_s))) if n > 1 else 1.0
    min_len = max(2, min(n, int(round(min_duration_s / dt))))
    runs = valid_runs(fastest < max_speed_m_s)
    if runs:
        a, b = max(runs, key=lambda r: r[1] - r[0])
        if b - a >= min_len:
            return slice(a, b)
    sums = np.convolve(np.minimum(fastest, 1e9), np.ones(min_len), mode="valid")
    a = int(np.argmin(sums))
    log.warning("%s: no still stretch of %.2f s (markers < %.0f mm/s); calibrating on frames %d:%d, the stillest %d frames",
                targets.source or "trial", min_duration_s, max_speed_m_s * 1000, a, a + min_len, min_len)
    return slice(a, a + min_len)



def _window(targets: MarkerTargets, frames: slice | None) -> tuple[range, bool]:
    if frames is None:
        sl = find_still_frames(targets)
        return range(targets.n_frames)[sl], True
    rng = range(targets.n_frames)[frames]
    past = [v for v in (frames.start, frames.stop) if v is not None and abs(v) > targets.n_frames]
    if past:
        raise InputError(f"{targets.source or 'trial'}: the calibration frames {frames.start}:{frames.stop} reach past "
                         f"the trial, which has {targets.n_frames} frames (0:{targets.n_frames}); nothing is clipped")
    if len(rng) == 0:
        raise InputError(f"{targets.source or 'trial'}: the calibration frames {frames.start}:{frames.stop} select no "
                         f"frame of the {targets.n_frames} in the trial")
    return rng, False

