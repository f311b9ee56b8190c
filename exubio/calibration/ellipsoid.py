"""The thorax ellipsoid fitted through the scapula contact points."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from exubio.errors import ModelError
from exubio.types import Ellipsoid

ELLIPSOID_RADIUS_WEIGHT_M = 0.3  # in the ellipsoid fit, 10 % of radius costs like 30 mm of centre



def fit_ellipsoid(ellipsoid: Ellipsoid, contacts_m: np.ndarray, /, *, tol: float = 1e-13,
                  max_iterations: int = 60) -> tuple[Ellipsoid, float]:
    """Move the centre in its sagittal plane (x, y) and scale the radii by a common factor k so
    that both contact points (2, 3) lie on the ellipsoid, with the least weighted change
    (|dc|^2 + (ELLIPSOID_RADIUS_WEIGHT_M * d ln k)^2). Returns the new ellipsoid and k. ModelError if no such
    ellipsoid is found near the given one."""
    x = np.asarray(contacts_m, dtype=float)
    radii0 = np.asarray(ellipsoid.radii_m, dtype=float)
    c = np.array(ellipsoid.centre_m, dtype=float)
    logk = 0.0
    Minv = np.diag([1.0, 1.0, 1.0 / ELLIPSOID_RADIUS_WEIGHT_M**2])
    g = None
    for _ in range(max_iterations):
        rr = radii0 * math.exp(logk)
        d = x - c
        g = (d * d / rr**2).sum(axis=1) - 1.0
        if np.abs(g).max() < tol:
            break
        Jg = np.column_stack([-2 * d[:, 0] / rr[0] ** 2, -2 * d[:, 1] / rr[1] ** 2, -2 * (d * d / rr**2).sum(axis=1)])
        step = -Minv @ Jg.T @ np.linalg.solve(Jg @ Minv @ Jg.T, g)
        c[0] += step[0]
        c[1] += step[1]
        logk += float(np.clip(step[2], -0.5, 0.5))
    if g is None or not np.abs(g).max() < 1e-10:
        raise ModelError(f"no thorax ellipsoid near the generic one passes through both contact points "
                         f"{np.round(x * 1000, 1).tolist()} mm (|g| = {np.abs(g).max():.2e})")
    return dataclasses.replace(ellipsoid, centre_m=c, radii_m=radii0 * math.exp(logk)), math.exp(logk)


