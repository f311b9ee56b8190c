"""The constrained, weighted least-squares design at a pose, shared by the noise gains
(exubio.trust.observability) and each angle's uncertainty (exubio.trust.angle_uncertainty)."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet

__all__ = ["constrained_design"]


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
