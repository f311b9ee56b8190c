"""Inverse dynamics of exubio's kinematic tree in numpy, on exubio.model.kinematics: Newton-Euler
per segment, summed over each joint's subtree, in the thorax frame (the model's world), which may
itself move in the lab (exubio.dynamics.thorax_motion).

For every segment s (centre of mass c_s, mass m_s, tensor I_s about c_s, world = thorax frame):
    F_s = m_s (a_cs - g),    N_s = I_s alpha_s + omega_s x (I_s omega_s)
the force and moment (about c_s) the rest of the body must apply to move it as q, q', q'' say.
With the thorax still, a_cs and alpha_s are the relative ones and g = -9.80665 Y. With the thorax
moving (origin acceleration a_O, angular velocity w, acceleration w', gravity g, all in thorax
coordinates: ``FrameTerms``), every vector stays in thorax coordinates and the absolute motion is

    a_cs = a_O + w' x c + w x (w x c) + 2 w x v_rel + a_rel,
    omega_s = w + omega_rel,   alpha_s = w' + alpha_rel + w x omega_rel

(the non-inertial frame terms: Euler, centripetal, Coriolis). External loads (exubio.dynamics.loads)
come off the wrench of the segment they act on.
The net wrench the parent applies to segment s across its joint (centre p_s) is the sum over the
subtree of s: F_joint = sum F_d, M_joint = sum (N_d + (c_d - p_s) x F_d), minus any external load
on the subtree. The generalized force of coordinate j (axis a_j through p_s of its joint) is
    tau_j = a_j . M_joint(s)
which equals sum_s J_cs^T F_s + J_ws^T N_s (M q'' + h - gravity): the tests check both.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.dynamics.thorax_motion import FrameTerms
from exubio.model.kinematics import Kinematics, cross

__all__ = ["GRAVITY_M_S2", "InverseDynamics", "inverse_dynamics", "girdle_split"]

GRAVITY_M_S2 = np.array([0.0, -9.80665, 0.0])
"""Gravity in the thorax frame (Y superior; the thorax is upright and fixed)."""


@dataclass(frozen=True)
class InverseDynamics:
    """tau: (n, m) generalized forces (N m; the open chain: what every coordinate needs);
    joint_force: (n, n_seg, 3) force (N) and joint_moment: (n, n_seg, 3) moment (N m, about the
    joint centre) the parent applies to each segment across its joint, thorax frame (row 0, the
    thorax, is zero); R: (n, n_seg, 3, 3) the segment rotations."""

    tau: np.ndarray
    joint_force: np.ndarray
    joint_moment: np.ndarray
    R: np.ndarray


def _subtree(kin: Kinematics) -> np.ndarray:
    """D[s, d] = 1 when segment d is s or below it."""
    n = kin.n_segments
    D = np.eye(n)
    for d in range(n):
        a = kin.parent_index[d]
        while a >= 0:
            D[a, d] = 1.0
            a = kin.parent_index[a]
    return D


def inverse_dynamics(kin: Kinematics, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, /, *,
                     gravity: np.ndarray = GRAVITY_M_S2, frame: FrameTerms | None = None,
                     external: tuple[np.ndarray, np.ndarray] | None = None) -> InverseDynamics:
    """Generalized forces and joint wrenches for q, q', q'' (n, m) (module docstring) with the
    segments' mass, centre of mass and inertia of ``kin.model``. ``frame``: the thorax's own motion
    (None: still, ``gravity`` in the thorax frame); ``external``: (force, moment about the origin)
    (n, S, 3) each of the external loads per segment (exubio.dynamics.loads.load_wrenches)."""
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    model = kin.model
    fr = kin.frames(q)
    coms = kin.point_set([(s.name, np.asarray(s.com_m, dtype=float)) for s in model.segments])
    c = kin.points(q, coms, frames=fr)  # (n, S, 3)
    Jc = kin.point_jacobian(q, coms, frames=fr, positions=c)  # (n, S, 3, m)
    a_c = np.einsum("nsim,nm->nsi", Jc, qdd) + kin.point_bias_acceleration(q, qd, coms)
    g = np.broadcast_to(gravity, c.shape)
    aff = kin.affects.astype(float)
    wq = fr.axes * qd[..., None]  # (n, m, 3)
    omega = np.einsum("sm,nmc->nsc", aff, wq)
    frame_rate = np.einsum("jk,nkc->njc", kin.precedes.astype(float), wq)  # rate of the frame carrying axis j
    dax = cross(frame_rate, fr.axes) * qd[..., None] + fr.axes * qdd[..., None]
    alpha = np.einsum("sm,nmc->nsc", aff, dax)
    if frame is not None:
        w = np.asarray(frame.angular_velocity, dtype=float)[:, None, :]
        wd = np.asarray(frame.angular_acceleration, dtype=float)[:, None, :]
        v_rel = np.einsum("nsim,nm->nsi", Jc, qd)
        a_c = (np.asarray(frame.origin_acceleration, dtype=float)[:, None, :] + cross(wd, c)
               + cross(w, cross(w, c)) + 2.0 * cross(w, v_rel) + a_c)
        alpha = wd + alpha + cross(w, omega)
        omega = w + omega
        g = np.broadcast_to(np.asarray(frame.gravity, dtype=float)[:, None, :], c.shape)
    mass = np.array([s.mass_kg for s in model.segments])
    I_local = np.array([np.asarray(s.inertia_kgm2, dtype=float) for s in model.segments])
    I_world = fr.R @ I_local @ np.swapaxes(fr.R, -1, -2)
    F = mass[:, None] * (a_c - g)
    N = np.einsum("nsij,nsj->nsi", I_world, alpha) + cross(omega, np.einsum("nsij,nsj->nsi", I_world, omega))
    D = _subtree(kin)
    Q = N + cross(c, F)  # moment about the thorax-frame origin
    if external is not None:
        F, Q = F - external[0], Q - external[1]
    F_joint = np.einsum("sd,ndc->nsc", D, F)
    # moment about the joint centre p_s of the subtree's wrenches: sum N_d + c_d x F_d - p_s x F_joint
    M_joint = np.einsum("sd,ndc->nsc", D, Q) - cross(fr.p, F_joint)
    F_joint[:, 0] = 0.0
    M_joint[:, 0] = 0.0
    tau = np.einsum("njc,njc->nj", fr.axes, M_joint[:, kin.coordinate_segment])
    return InverseDynamics(tau=tau, joint_force=F_joint, joint_moment=M_joint, R=fr.R)


def girdle_split(kin: Kinematics, q: np.ndarray, tau: np.ndarray, /) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split the girdle's generalized forces into the scapulothoracic contact and joint torques.

    The constrained equations of motion M q'' + h = tau_joint + G^T lambda have more unknowns (the
    girdle's 6 torques and the 2 contact forces) than equations: statically indeterminate. Rule:
    lambda = argmin |tau - G^T lambda| (least squares over the girdle's coordinates), i.e. the thorax
    contact carries every part of the girdle's load it can (the constraint forces do no work and
    cost no muscle), and the SC/AC torques carry only the rest, which is orthogonal to the contact
    directions. Unique wherever G has full rank (always on the ellipsoid), continuous in time, and
    the arm's coordinates are untouched (G has no arm columns).

    Returns (tau_joint (n, m), lambda (n, 2), normal force (n, 2) N): the force on the scapula at
    each contact point is lambda_k * 2 A e_k along the ellipsoid's outward normal; its signed size
    2 lambda_k |A e_k| is > 0 when the thorax pushes the scapula outwards (compression).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    tau = np.atleast_2d(np.asarray(tau, dtype=float))
    G = kin.G(q)  # (n, 2, m)
    GGt = G @ np.swapaxes(G, -1, -2)
    lam = np.linalg.solve(GGt, np.einsum("nkm,nm->nk", G, tau)[..., None])[..., 0]
    tau_joint = tau - np.einsum("nkm,nk->nm", G, lam)
    e = kin.points(q, kin.contacts) - kin.centre
    normal = 2.0 * lam * np.linalg.norm(e * kin.a_diag, axis=-1)
    return tau_joint, lam, normal
