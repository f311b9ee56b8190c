"""The ISB thorax frame of a trial (Wu et al. 2005): the frame from its four landmarks (or the
midpoints a protocol may name instead), and lab positions expressed in it frame by frame."""
from __future__ import annotations

import logging

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import cross
from exubio.prep.filtering import fill_short_gaps

log = logging.getLogger(__name__)

__all__ = ["MAX_THORAX_GAP_S", "isb_landmarks", "lab_landmarks", "thorax_frame", "to_thorax_frame"]

MAX_THORAX_GAP_S = 0.25
"""Thorax-landmark gaps up to this long are bridged by linear interpolation (held at the ends)."""


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
    z = cross(ij - c7, mid_up - mid_low)
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
    x = cross(y, z)
    z = cross(x, y)  # exactly orthonormal despite rounding
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


def lab_landmarks(trajectories, protocol, match, /, *, max_thorax_gap_s: float = MAX_THORAX_GAP_S) -> dict[str, np.ndarray]:
    """The protocol's thorax landmarks (key of ``protocol.thorax_frame`` -> (n, 3) lab positions) of a
    trial, gaps up to ``max_thorax_gap_s`` bridged (exubio.prep.filtering.fill_short_gaps), longer
    ones NaN (logged); ``match``: the trial's exubio.protocol.labels.LabelMatch. A landmark missing
    in every frame raises InputError naming it."""
    src = trajectories.source or "trajectories"
    raw = trajectories.positions_m
    max_gap = int(round(max_thorax_gap_s * trajectories.rate_hz))
    landmarks = {}
    for key, col in match.thorax_columns.items():
        label = getattr(protocol.thorax_frame, key)
        lm = raw[:, col].copy()
        lm[~np.isfinite(lm).all(axis=1)] = np.nan
        if np.isnan(lm).any(axis=1).all():
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
    return landmarks
