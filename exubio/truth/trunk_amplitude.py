"""How far the trunk moves while the arm does, measured on trials whose thorax carries markers: the
size of what a run that assumes the thorax still (``exubio truth``: the bone files carry no thorax
marker) cannot see, which ``exubio.trust.angle_uncertainty.trunk_angle_variance`` carries into every
angle's uncertainty of such a run.

For one trial: the thorax's ISB frame (Wu et al. 2005: origin IJ, Y from the PX-T8 midpoint to the
IJ-C7 midpoint, Z normal to that plane to the right, X = Y x Z) in every frame; its rotation from
its mean over the first ``REST_S`` s as a rotation vector in the start frame's axes (rad), and IJ's
displacement in the same axes (m): xi (n, 6). The driver is the one of the artefact amplitude model
(``exubio.truth.sta_amplitude``): theta, the humerus's rotation angle from its start orientation in
the lab (a rigid fit of the humerus's markers). Pooled over trials, the second moment per rad^2
C = sum_t xi xi^T / sum_t theta^2 (6 x 6), zero at the start by construction.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import InputError

__all__ = ["REST_S", "thorax_frames", "trunk_motion", "fit_trunk_amplitude"]

REST_S = 0.3


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def thorax_frames(ij: np.ndarray, px: np.ndarray, c7: np.ndarray, t8: np.ndarray, /) -> np.ndarray:
    """ISB thorax frames (n, 3, 3) (columns X anterior, Y up, Z right) from the four landmarks (n, 3)."""
    y = _unit((ij + c7) / 2 - (px + t8) / 2)
    z = _unit(np.cross(ij - c7, y))
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def _rotvec(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


def trunk_motion(positions: np.ndarray, labels: Sequence[str], rate_hz: float, /, *, ij: str, px: str, c7: str,
                 t8: str, humerus: Sequence[str], where: str = "trial") -> tuple[np.ndarray, np.ndarray]:
    """(xi (n, 6), theta (n,)) of one trial (module docstring): ``positions`` (n, k, 3) m in the lab,
    ``labels`` the k marker labels; the thorax landmarks and the humerus's markers (at least 3) by
    label. Frames where a marker is missing are NaN."""
    from ..calibration.cluster import cluster_poses

    idx = {lab: i for i, lab in enumerate(labels)}
    need = [ij, px, c7, t8, *humerus]
    missing = [m for m in need if m not in idx]
    if missing:
        raise InputError(f"{where}: no marker {missing} (has {sorted(labels)}); the trunk's motion needs the thorax's "
                         f"IJ, PX, C7, T8 and the humerus's markers")
    if len(humerus) < 3:
        raise InputError(f"{where}: the humerus's rotation needs at least 3 markers, got {list(humerus)}")
    P = np.asarray(positions, dtype=float)
    n = P.shape[0]
    n0 = max(1, min(n, int(round(REST_S * rate_hz))))
    ok = np.isfinite(P[:, [idx[m] for m in need]]).all(axis=(1, 2))
    if not ok[:n0].any():
        raise InputError(f"{where}: the thorax or humerus markers are missing throughout the first {REST_S:g} s")
    F = np.full((n, 3, 3), np.nan)
    F[ok] = thorax_frames(*(P[ok, idx[m]] for m in (ij, px, c7, t8)))
    from scipy.spatial.transform import Rotation

    F0 = Rotation.from_matrix(F[:n0][ok[:n0]]).mean().as_matrix()
    ij0 = np.nanmean(P[:n0][ok[:n0], idx[ij]], axis=0)
    xi = np.full((n, 6), np.nan)
    xi[ok, :3] = _rotvec(np.einsum("ji,njk->nik", F0, F[ok])) @ np.eye(3)  # rotation from the start, in its axes
    xi[ok, 3:] = (P[ok, idx[ij]] - ij0) @ F0
    H = P[:, [idx[m] for m in humerus]]
    ref = np.nanmean(H[:n0][ok[:n0]], axis=0)
    theta = np.full(n, np.nan)
    R, _, _ = cluster_poses(ref - ref.mean(axis=0), H[ok])
    theta[ok] = np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    return xi, theta


def fit_trunk_amplitude(motions: Sequence[tuple[np.ndarray, np.ndarray]], /) -> tuple[np.ndarray, int]:
    """(C (6, 6) per rad^2, frames used) pooled over (xi, theta) pairs of ``trunk_motion``."""
    num, den, frames = np.zeros((6, 6)), 0.0, 0
    for xi, theta in motions:
        ok = np.isfinite(xi).all(axis=1) & np.isfinite(theta)
        num += xi[ok].T @ xi[ok]
        den += float(np.sum(theta[ok] ** 2))
        frames += int(ok.sum())
    if den <= 0:
        raise InputError("the trials hold no motion of the humerus from its start: no trunk amplitude")
    return num / den, frames
