"""The kinematics of one frame at a time (the live loop's): ``FrameForward``, the segment rotations
and origins of one posture (Kinematics.frames' products without the joint axes and pivots, bitwise
the same R and p), and ``FrameInverse``, the joint coordinates of one frame from its segment
rotations, the rule of exubio.model.kinematics.Kinematics.coordinates_from_rotations for one
frame in fewer array operations (both revolute joints in one, the two angle triples of the spherical
joints wrapped into their ranges in one call, the range constants computed once). A frame costs the
number of operations, not of joints; the angles agree with coordinates_from_rotations to round-off
(tests/model/test_frame_angles.py)."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics
from exubio.model.ranges import violation, wrap_into_range

__all__ = ["FrameForward", "FrameInverse"]

_VEE_I = np.array([2, 0, 1])
_VEE_J = np.array([1, 2, 0])  # vee(R) = R[_VEE_I, _VEE_J] - R[_VEE_J, _VEE_I]


class FrameForward:
    """``forward(q)``: (R (n_seg, 3, 3), p (n_seg, 3)) of one posture q (m,), as Kinematics.frames
    (the same compiled kernel, exubio.model.kernels.forward, without the batch's reshaping)."""

    def __init__(self, kin: Kinematics, /):
        from exubio.model import kernels  # numba: imported where used

        self.forward = kernels.forward
        self.tables = kin.kernel_tables()
        self.n_seg, self.m = kin.n_segments, kin.n_coordinates

    def __call__(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, p = np.empty((1, self.n_seg, 3, 3)), np.empty((1, self.n_seg, 3))
        ax = np.empty((1, self.m, 3))
        self.forward(np.ascontiguousarray(q, dtype=float).reshape(1, -1), *self.tables, R, p, ax, np.empty_like(ax))
        return R[0], p[0]


class FrameInverse:
    """``inverse(R, q_previous)``: the coordinates (m,) of segment rotations R (n_seg, 3, 3), as
    ``kin.coordinates_from_rotations(R, q_previous=q_previous)``."""

    def __init__(self, kin: Kinematics, /):
        self.kin = kin
        t = self.t = kin._inverse
        self.m = kin.n_coordinates
        self.ranges = kin.model.coordinate_ranges_rad
        self.proj = np.array(t.rev_proj).reshape(-1, 3, 3)
        lo, hi = self.ranges[:, 0], self.ranges[:, 1]
        bounded = np.isfinite(lo) & np.isfinite(hi)
        self.mid = np.where(bounded, 0.5 * (np.where(bounded, lo, 0.0) + np.where(bounded, hi, 0.0)), 0.0)

    def __call__(self, R: np.ndarray, q_previous: np.ndarray | None = None) -> np.ndarray:
        t = self.t
        Rrel = np.swapaxes(R[t.parents], -1, -2) @ R[t.children]
        Rs = t.Bt @ Rrel @ t.B
        qa = np.empty(self.m)
        if t.rev.size:  # the angle about the axis, cos from the part of R orthogonal to it
            Rr = Rrel[t.rev]
            vee = Rr[:, _VEE_I, _VEE_J] - Rr[:, _VEE_J, _VEE_I]
            qa[t.rev_q] = np.arctan2(0.5 * np.einsum("rc,rc->r", vee, t.rev_axes),
                                     0.5 * np.einsum("rij,rjk,rki->r", self.proj, Rr, self.proj))
        if t.card.size:
            Rc = Rs[t.card]
            qa[t.card_q[:, 0]] = np.arctan2(Rc[:, 2, 1], Rc[:, 1, 1])
            qa[t.card_q[:, 1]] = np.arctan2(Rc[:, 0, 2], Rc[:, 0, 0])
        ref = self.mid if q_previous is None else np.asarray(q_previous, dtype=float)
        if not t.sph.size:
            return wrap_into_range(qa, self.ranges, ref)
        Rp = Rs[t.sph]
        q2 = np.arctan2(Rp[:, 0, 2], np.hypot(Rp[:, 0, 0], Rp[:, 0, 1]))
        q1 = np.arctan2(-Rp[:, 1, 2], Rp[:, 2, 2])
        q3 = np.arctan2(-Rp[:, 0, 1], Rp[:, 0, 0])
        lock = np.cos(q2) < 1e-6
        if lock.any():  # Rx(q1) Ry(+-90) Rz(q3): keep q1 (the previous one, or 0), solve q3
            first = np.zeros_like(q1) if q_previous is None else ref[t.sph_q[:, 0]]
            q1 = np.where(lock, first, q1)
            phi = np.arctan2(Rp[:, 1, 0], Rp[:, 1, 1])
            q3 = np.where(lock, phi - np.sign(Rp[:, 0, 2]) * q1, q3)
        both = np.empty((2, self.m))  # the two angle triples of the spherical joints; the rest alike
        both[:] = qa
        sq = t.sph_q
        both[0, sq[:, 0]], both[0, sq[:, 1]], both[0, sq[:, 2]] = q1, q2, t.sph_sign * q3
        both[1, sq[:, 0]], both[1, sq[:, 1]], both[1, sq[:, 2]] = q1 + np.pi, np.pi - q2, t.sph_sign * (q3 + np.pi)
        sol = wrap_into_range(both, self.ranges, ref)
        cost = np.abs(violation(sol, self.ranges))[:, sq].sum(axis=-1)  # (2, joints)
        take_b = cost[1] < cost[0] - 1e-12
        if q_previous is not None:
            near = np.abs(sol[:, sq] - ref[sq]).sum(axis=-1)
            take_b |= (np.abs(cost[1] - cost[0]) <= 1e-12) & (near[1] < near[0])
        out = sol[0]
        out[sq] = np.where(take_b[:, None], sol[1, sq], sol[0, sq])
        return out
