"""The thorax ellipsoid fitted through the scapula contact points."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from exubio.errors import ModelError
from exubio.methods.lsq import newton
from exubio.types import Ellipsoid

ELLIPSOID_RADIUS_WEIGHT_M = 0.3  # in the ellipsoid fit, 10 % of radius costs like 30 mm of centre



def fit_ellipsoid(ellipsoid: Ellipsoid, contacts_m: np.ndarray, /, *, tol: float = 1e-13,
                  max_iterations: int = 60) -> tuple[Ellipsoid, float]:
    """Move the centre in its sagittal plane (x, y) and scale the radii by a common factor k so
    that both contact points (2, 3) lie on the ellipsoid, with the least weighted change
    (|dc|^2 + (ELLIPSOID_RADIUS_WEIGHT_M * d ln k)^2), by least-norm Newton steps (exubio.methods.lsq.newton)
    until max |g| <= tol. Returns the new ellipsoid and k. ModelError (saying why Newton stopped) if
    no such ellipsoid is found near the given one (max |g| not below 1e-10)."""
    x = np.asarray(contacts_m, dtype=float)
    radii0 = np.asarray(ellipsoid.radii_m, dtype=float)
    cz = float(ellipsoid.centre_m[2])
    Minv = np.diag([1.0, 1.0, 1.0 / ELLIPSOID_RADIUS_WEIGHT_M**2])

    def residual(p: np.ndarray):  # p = (centre x, centre y, ln k)
        rr = radii0 * math.exp(p[2])
        d = x - np.array([p[0], p[1], cz])
        return (d * d / rr**2).sum(axis=1) - 1.0, (d, rr)

    def update(p: np.ndarray, g: np.ndarray, aux) -> np.ndarray:
        d, rr = aux
        Jg = np.column_stack([-2 * d[:, 0] / rr[0] ** 2, -2 * d[:, 1] / rr[1] ** 2, -2 * (d * d / rr**2).sum(axis=1)])
        step = -Minv @ Jg.T @ np.linalg.solve(Jg @ Minv @ Jg.T, g)
        return p + np.array([step[0], step[1], np.clip(step[2], -0.5, 0.5)])

    c0 = np.asarray(ellipsoid.centre_m, dtype=float)
    solved = newton(np.array([c0[0], c0[1], 0.0]), residual, update, tol=tol, max_iterations=max_iterations)
    if not solved.residual < 1e-10:
        raise ModelError(f"no thorax ellipsoid near the generic one passes through both contact points "
                         f"{np.round(x * 1000, 1).tolist()} mm (|g| = {solved.residual:.2e}; Newton stopped: "
                         f"{solved.reason.label.replace('_', ' ')})")
    cx, cy, logk = solved.x
    k = math.exp(logk)
    return dataclasses.replace(ellipsoid, centre_m=np.array([cx, cy, cz]), radii_m=radii0 * k), k




def fit_ellipsoid_to_points(points_m: np.ndarray, /, *, centre_z_m: float | None = 0.0) -> tuple[Ellipsoid, np.ndarray]:
    """The thorax-axis-aligned ellipsoid through points (n, 3) in the least-squares sense of the
    radial distance: for each point, |x - c| (1 - 1/sqrt(f)) with f = sum ((x - c)/r)^2 (the
    distance from the surface along the ray from the centre). ``centre_z_m``: fixed lateral
    position of the centre (0: on the mid-sagittal plane, a symmetric thorax); None: fitted.
    Returns the ellipsoid (no contact points) and the residual distances (n,) in m.
    Used to build the generic model's ellipsoid from the contact points of a published rhythm
    (``exubio.synth.rhythm.rhythm_poses``) and on several static poses."""
    from scipy.optimize import least_squares

    x = np.asarray(points_m, dtype=float)
    c0 = x.mean(axis=0)
    r0 = np.maximum(np.abs(x - c0).max(axis=0), 0.05)
    free_z = centre_z_m is None
    if not free_z:
        c0[2] = centre_z_m

    def unpack(p):
        c = np.array([p[0], p[1], p[2] if free_z else centre_z_m])
        return c, np.exp(p[-3:])

    def resid(p):
        c, r = unpack(p)
        return surface_distance(Ellipsoid(centre_m=c, radii_m=r, contact_points=()), x)

    p0 = np.concatenate([c0[:3] if free_z else c0[:2], np.log(r0)])
    sol = least_squares(resid, p0, xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=10000)
    if not sol.success:
        raise ModelError(f"the ellipsoid fit through {len(x)} points did not converge: {sol.message}")
    c, r = unpack(sol.x)
    return Ellipsoid(centre_m=c, radii_m=r, contact_points=()), resid(sol.x)


def surface_distance(ellipsoid: Ellipsoid, points_m: np.ndarray, /) -> np.ndarray:
    """Signed distance (m) of points (..., 3) from the ellipsoid along the ray from its centre
    (positive outside)."""
    d = np.asarray(points_m, dtype=float) - np.asarray(ellipsoid.centre_m, dtype=float)
    f = np.sqrt(((d / np.asarray(ellipsoid.radii_m, dtype=float)) ** 2).sum(axis=-1))
    return np.linalg.norm(d, axis=-1) * (1.0 - 1.0 / f)


def fit_ellipsoid_poses(ellipsoid: Ellipsoid, contacts_m: np.ndarray, /, *, prior: float = 1e-3
                        ) -> tuple[Ellipsoid, float]:
    """The least change of ``ellipsoid`` (centre in its sagittal plane, radii by a common factor k,
    as fit_ellipsoid) that brings the contact points of several poses (n, 3) closest to its surface
    in least squares of their distances (surface_distance); a weak prior (``prior`` times the
    change, weighted as in fit_ellipsoid) keeps what the points leave open. Returns the ellipsoid
    and k."""
    from scipy.optimize import least_squares

    x = np.asarray(contacts_m, dtype=float)
    c0 = np.array(ellipsoid.centre_m, dtype=float)
    r0 = np.asarray(ellipsoid.radii_m, dtype=float)

    def build(p):
        c = c0.copy()
        c[0] += p[0]
        c[1] += p[1]
        return dataclasses.replace(ellipsoid, centre_m=c, radii_m=r0 * math.exp(p[2]))

    def resid(p):
        return np.concatenate([surface_distance(build(p), x), prior * np.array([p[0], p[1], ELLIPSOID_RADIUS_WEIGHT_M * p[2]])])

    sol = least_squares(resid, np.zeros(3), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    if not sol.success:
        raise ModelError(f"no thorax ellipsoid fits the contact points of the static poses: {sol.message}")
    return build(sol.x), math.exp(sol.x[2])
