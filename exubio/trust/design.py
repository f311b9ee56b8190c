"""The constrained, weighted least-squares design at a pose, shared by the noise gains
(exubio.trust.observability) and each angle's uncertainty (exubio.trust.angle_uncertainty)."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet

__all__ = ["constrained_design", "information_pinv", "marker_information"]


def constrained_design(kin: Kinematics, points: PointSet, qf: np.ndarray, present: np.ndarray, weights: np.ndarray,
                       free: np.ndarray):
    """For frames qf (b, m): J (b, 3k, f) the markers' Jacobian over the free coordinates, N
    (b, f, f-2) the null space of G there, A = J N, w3 (b, 3k) the weight of each marker coordinate
    (0 where missing) and M = A^T W A (module docstring): what the noise gains and the uncertainty
    (exubio.trust.angle_uncertainty) are built from (see exubio.trust.observability)."""
    w = np.where(present, weights[None, :], 0.0)
    b, k = w.shape
    J = kin.point_jacobian(qf, points)[..., free].reshape(b, 3 * k, len(free))
    w3 = np.repeat(w, 3, axis=1)
    G = kin.G(qf)[..., free]
    _, _, Vt = np.linalg.svd(G)
    N = np.swapaxes(Vt[:, G.shape[1]:, :], 1, 2)
    A = J @ N
    M = np.swapaxes(A, 1, 2) @ (A * w3[..., None])
    return J, N, A, w3, M


def marker_information(kin: Kinematics, points: PointSet, qf: np.ndarray, present: np.ndarray, weights: np.ndarray,
                       free: np.ndarray, *, design: tuple | None = None):
    """For frames qf (b, m): N (b, f, f-2) the null space of G over the free coordinates, M and S
    (b, f-2, f-2) of exubio.trust.observability's docstring; ``design``: constrained_design of the
    same arguments, where the caller has it."""
    _, N, A, w3, M = constrained_design(kin, points, qf, present, weights, free) if design is None else design
    S = np.swapaxes(A, 1, 2) @ (A * (w3**2)[..., None])
    return N, M, S


def information_pinv(M: np.ndarray, /) -> np.ndarray:
    """The pseudo-inverse of the information matrices M (b, r, r), which the covariance
    (exubio.trust.observability) and the sensitivity (exubio.trust.angle_uncertainty) both use."""
    return np.linalg.pinv(M, rcond=1e-12, hermitian=True)
