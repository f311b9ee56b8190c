"""How far the trunk moves while the arm does, measured on trials whose thorax carries markers: the
size of what a run that assumes the thorax still (``exubio truth``: the bone files carry no thorax
marker) cannot see, which ``exubio.trust.angle_uncertainty.trunk_angle_variance`` carries into every
angle's uncertainty of such a run.

For one trial: the thorax's ISB frame (Wu et al. 2005: origin IJ, Y from the PX-T8 midpoint to the
IJ-C7 midpoint, Z normal to that plane to the right, X = Y x Z) in every frame; its rotation from
its mean over the first ``REST_S`` s as a rotation vector in the start frame's axes (rad), and IJ's
displacement in the same axes (m): xi (n, 6). The driver is the one of the artefact amplitude model
(``exubio.truth.sta_amplitude``): theta, the humerus's rotation angle from its start orientation in
the lab (a rigid fit of the humerus's markers). Pooled over trials, the second moment of xi over
every frame after the rest window, one constant: the trunk of arm tasks moves with the task (a lean
to the mouth, a turn), about as much with the arm near its start as raised (on the six movement
trials of ../shared/data/c3d, 2-7 deg with the humerus within 10 deg of its start, 3-13 deg at 20-40
deg), and of three forms fitted on five of those trials and judged on the sixth (a constant, a
table in bins of theta, a second moment per rad^2 of theta), the constant predicts the held-out
trial best (``python studies/trunk_motion.py``: mean held-out Gaussian log-likelihood per frame).
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


def fit_trunk_amplitude(motions: Sequence[tuple[np.ndarray, np.ndarray]], /, *, rest_frames: Sequence[int] | None = None
                        ) -> tuple[np.ndarray, np.ndarray, int]:
    """(nodes (1,) rad, table (1, 6, 6), frames used) pooled over (xi, theta) pairs of
    ``trunk_motion``: the second moment of xi over every frame after each trial's first
    ``rest_frames`` (its rest window, where xi is zero by construction), one node (the frames' mean
    theta): constant in theta (module docstring), in the artefact table's form
    (``exubio.synth.driver_table``)."""
    xs, ts = [], []
    for i, (xi, theta) in enumerate(motions):
        x, th = np.asarray(xi, dtype=float), np.array(theta, dtype=float)
        n0 = 0 if rest_frames is None else int(rest_frames[i])
        ok = np.isfinite(x).all(axis=1) & np.isfinite(th)
        ok[:n0] = False
        xs.append(x[ok])
        ts.append(th[ok])
    x, th = np.concatenate(xs), np.concatenate(ts)
    if x.shape[0] < 2 or not np.any(th > 0):
        raise InputError("the trials hold no motion after their start: no trunk amplitude")
    return np.array([float(th.mean())]), (x.T @ x / x.shape[0])[None], int(x.shape[0])
