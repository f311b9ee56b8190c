"""The pose of a rigid marker cluster in every frame (pure numpy): the SVD least-squares fit of a
reference shape (Kabsch; Soderkvist & Wedin 1993, J Biomech 26:1473). The segment poses that
functional centres and axes (exubio.calibration.functional) and the scapula's motion
(exubio.calibration.scapula_motion) start from."""
from __future__ import annotations

import numpy as np

from exubio.errors import InputError

__all__ = ["cluster_poses", "cluster_reference"]

_COLLINEAR_RATIO = 1e-3  # cluster: 2nd singular value of the centred shape / 1st below it = collinear



def cluster_reference(markers: np.ndarray, /, frame: int | None = None) -> np.ndarray:
    """A reference shape (k, 3) for ``cluster_poses``: the markers at ``frame`` (default: the
    first frame where all are finite) minus their centroid, so the cluster's local frame has its
    origin at that centroid and the lab's axes at that frame."""
    m = _as_markers(markers, "cluster_reference")
    complete = np.flatnonzero(np.isfinite(m).all(axis=(1, 2)))
    if frame is None:
        if complete.size == 0:
            raise InputError(f"cluster_reference: no frame has all {m.shape[1]} markers")
        frame = int(complete[0])
    elif not np.isfinite(m[frame]).all():
        raise InputError(f"cluster_reference: frame {frame} misses a marker")
    ref = m[frame]
    return ref - ref.mean(axis=0)


def cluster_poses(reference: np.ndarray, markers: np.ndarray, /) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pose of a rigid marker cluster in every frame: ``markers[i] ~ R[i] @ reference + t[i]``.

    reference: (k, 3) the cluster's marker positions in its local frame (m), k >= 3, not collinear.
    markers:   (n, k, 3) lab positions (m), NaN where missing.
    Returns R (n, 3, 3), t (n, 3) and rms (n,) (rms distance of the fitted from the measured
    markers, m). A frame with fewer than 3 finite markers, or only collinear ones, is NaN.
    Least squares by SVD with the reflection excluded (Kabsch; Soderkvist & Wedin 1993).
    """
    ref = np.asarray(reference, dtype=float)
    if ref.ndim != 2 or ref.shape[1] != 3 or ref.shape[0] < 3:
        raise InputError(f"cluster_poses: reference must have shape (k>=3, 3), got {ref.shape}")
    if not np.isfinite(ref).all():
        raise InputError("cluster_poses: the reference has non-finite coordinates")
    if _collinear(ref):
        raise InputError("cluster_poses: the reference markers are collinear (or coincide); a pose needs 3 "
                         "markers spanning a plane")
    m = _as_markers(markers, "cluster_poses")
    if m.shape[1] != ref.shape[0]:
        raise InputError(f"cluster_poses: {ref.shape[0]} reference markers but {m.shape[1]} marker trajectories")
    n, k = m.shape[:2]
    R = np.full((n, 3, 3), np.nan)
    t = np.full((n, 3), np.nan)
    rms = np.full(n, np.nan)
    finite = np.isfinite(m).all(axis=2)  # (n, k)
    patterns, inverse = np.unique(finite, axis=0, return_inverse=True)
    inverse = np.asarray(inverse).reshape(-1)
    for p, mask in enumerate(patterns):
        if mask.sum() < 3 or _collinear(ref[mask]):
            continue
        frames = np.flatnonzero(inverse == p)
        P = ref[mask]  # (j, 3)
        Q = m[frames][:, mask, :]  # (f, j, 3)
        p0 = P.mean(axis=0)
        q0 = Q.mean(axis=1)
        H = np.einsum("ja,fjb->fab", P - p0, Q - q0[:, None, :])  # sum_j p_j q_j^T
        U, _, Vt = np.linalg.svd(H)
        d = np.sign(np.linalg.det(np.einsum("fab,fbc->fac", U, Vt)))  # det(U Vt) = det(V U^T)
        d[d == 0] = 1.0
        D = np.zeros((frames.size, 3, 3))
        D[:, 0, 0] = 1.0
        D[:, 1, 1] = 1.0
        D[:, 2, 2] = d
        Rf = np.einsum("fba,fbc,fdc->fad", Vt, D, U)  # V D U^T
        tf = q0 - np.einsum("fab,b->fa", Rf, p0)
        fitted = np.einsum("fab,jb->fja", Rf, P) + tf[:, None, :]
        R[frames] = Rf
        t[frames] = tf
        rms[frames] = np.sqrt(np.mean(np.sum((fitted - Q) ** 2, axis=2), axis=1))
    return R, t, rms


def _as_markers(markers: np.ndarray, who: str) -> np.ndarray:
    m = np.asarray(markers, dtype=float)
    if m.ndim != 3 or m.shape[2] != 3:
        raise InputError(f"{who}: markers must have shape (n_frames, k, 3), got {m.shape}")
    return m


def _collinear(points: np.ndarray) -> bool:
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(s[0] <= 0 or s[1] < _COLLINEAR_RATIO * s[0])
