"""The range-of-motion limits of the PF system (exubio.backend.exudyn_system.PFSystem): the limit
elements, added when the system is built, and their switching during a run.

Range-of-motion limits (optional, ``limits_rad``): the one-sided potential that LS shares,
V = sum_j k_lim / 2 (q_j - hi_j)^2 above hi_j, (lo_j - q_j)^2 below lo_j, as one Exudyn element per
joint whose generalized forces are exactly -dV/dq (no approximation):
- spherical and cardan joints: ``ObjectConnectorRigidBodySpringDamper`` between a frame on the
  parent and one on the child at the joint centre. Its ``rotation`` argument is Exudyn's
  RotationMatrix2RotXYZ of the frames' relative rotation, R = Rx(t0) Ry(t1) Rz(t2) (t0, t2 in
  (-pi, pi], t1 in [-pi/2, pi/2]); with the frames built on the joint's axes (x = axis 1, y =
  axis 2) these Tait-Bryan angles are the joint coordinates (minus a centre, below). A symbolic
  ``springForceTorqueUserFunction`` (``_limit_torque``) returns the torque W^-T dV/dt in the parent
  frame, W the angles' axes (Exudyn applies the connector's torque through the markers' rotation
  Jacobians, so the generalized forces are -W^T m = -dV/dt).
- revolute joints (and a cardan joint whose second angle is held): ``ObjectConnectorTorsionalSpringDamper``
  about the joint axis, symbolic ``springTorqueUserFunction`` k_lim x (angle beyond its range).
Chosen by measurement (CPU-time ratio to the same run without limits, interleaved runs, every
element switched on): rigid-body spring-damper with the symbolic torque +12 % per element, with a
trivial symbolic function +10 % (the cost is the user-function call, whose arguments include two
6x6 matrices), native (linear, no user function) +5 %; torsional spring-damper symbolic +6 %,
native +3.5 %. Native elements are linear springs, two-sided within a step (an offset switched by
the pre-step would pull a joint that moved back inside to the limit); the symbolic ones are exact.
An element is therefore switched off (``activeConnector`` False: Exudyn skips it, measured +0 %)
except near a limit: at the start of each step the pre-step reads the Rotation output of an
element (2 us) and switches it on while one of its angles is within margin = w_max h of a limit
or beyond it, w_max = ``limit_max_rate_rad_s`` (10 rad/s, the fastest joint rates of arm motion;
h = the step: 0.1 rad at 10 ms), so no joint can cross a limit during a step with its element
off; a joint d > margin from its limits is looked at again only after (d - margin) / w_max.
Measured on the benchmark trial (the model's ranges, none reached): +1-3 % (paired runs; Exudyn's
python timer +0.005-0.007 ms/frame: about one Rotation read per step); with the benchmark's
gh_abduction, elbow_flexion, wrist_flexion and sc_elevation limited inside their motion (beyond a
limit 30-60 % of the time): +22-34 %, 0.34 Jacobians per step instead of 0.26.
Principal angles wrap, so each element measures its angles from a centre (a joint frame turned
about the first axis on the parent's side, about the last on the child's): the middle of the
range, or a quarter turn (cardan middle angle: an eighth) inside a one-sided limit; a limit
without 30 deg to spare before the wrap, and a spherical joint's middle-angle limit at or beyond
+-90 deg (that angle never gets there), get no element. A spherical joint with three free
angles may sit on either branch of its sequence (the principal one, |middle angle| <= 90 deg, or
the other, (t0 + pi, +-pi - t1, t2 + pi)); the pre-step judges which one lies within the ranges of
all three coordinates (or nearer them), as exubio.model.kinematics reports it, and tells the torque
function through the connector's ``offset[0]`` (+1 / -1), which then measures the angles on that
branch (the middle angle runs against the principal one there). E.g. the glenohumeral joint at
more than 90 deg of internal rotation in a palm-down T-pose: before, its principal first and last
angles, 180 deg outside their ranges, were pulled on and Newton failed at the first frame.
"""
from __future__ import annotations

import logging
import math
from typing import AbstractSet, Sequence

import numpy as np

import exudyn as exu
import exudyn.itemInterface as eii
from exudyn.advancedUtilities import CreateSymbolicUserFunction

from exubio.backend.pf_numerics import LimitElement, frame_with_z, limit_window
from exubio.model.kinematics import Kinematics, axis_rotation
from exubio.types import JointKind, Model

__all__ = ["DEFAULT_LIMIT_MAX_RATE_RAD_S", "LimitSwitching", "add_limit_elements"]

esym = exu.symbolic

log = logging.getLogger(__name__)

DEFAULT_LIMIT_MAX_RATE_RAD_S = 10.0  # fastest joint-angle rate the switching of the limits allows for
_LIMIT_MIN_COS = 1e-2  # spherical joints: 1 / cos(middle angle) capped at 100 (gimbal lock, |q2| > 89.4 deg)


# --------------------------------------------------------------------------------------------
# The elements, added when the system is built
# --------------------------------------------------------------------------------------------
def add_limit_elements(mbs, model: Model, kin: Kinematics, bodies: Sequence[int], q0: np.ndarray,
                       locked_segments: AbstractSet[int], held_coordinates: AbstractSet[int], limits_rad,
                       k_lim: float) -> list[LimitElement]:
    """One limit element per joint with a finite range on a solved coordinate (see the module
    docstring), added to ``mbs`` (being built: ``bodies`` per segment of ``model``, the reference
    posture ``q0``) switched off; a run switches it on near a limit (:class:`LimitSwitching`)."""
    m = model.n_coordinates
    lim = np.array(limits_rad, dtype=float)
    if lim.shape != (m, 2):
        raise ValueError(f"PFSystem: limits_rad must have shape ({m}, 2), got {lim.shape}")
    if np.isnan(lim).any() or np.any(lim[:, 0] > lim[:, 1]) or np.isposinf(lim[:, 0]).any() or np.isneginf(lim[:, 1]).any():
        raise ValueError("PFSystem: limits_rad rows must be [lower, upper] with lower <= upper (+-inf = no limit)")
    if not (math.isfinite(k_lim) and k_lim > 0):
        raise ValueError(f"PFSystem: limit_stiffness_nm_per_rad must be finite and > 0, got {k_lim}")
    out: list[LimitElement] = []
    names = model.segment_names
    half = 0.5 * math.pi
    for i, seg in enumerate(model.segments[1:], start=1):
        if i in locked_segments:
            continue
        joint = seg.joint
        idx = [int(j) for j in kin.joint_coordinate_indices(i)]
        axes = [np.asarray(a, dtype=float) for a in joint.axes]
        if joint.kind is JointKind.REVOLUTE:
            B = frame_with_z(axes[0])[:, [2, 0, 1]]  # x = the axis: R_rel = B Rx(q) B^T
            slots = [(0, idx[0], 1.0, "periodic")]
        else:
            B = np.column_stack([axes[0], axes[1], np.cross(axes[0], axes[1])])  # Rx(q1) Ry(q2) [Rz(s q3)]
            slots = [(0, idx[0], 1.0, "periodic"),
                     (1, idx[1], 1.0, "middle" if joint.kind is JointKind.SPHERICAL else "window")]
            if joint.kind is JointKind.SPHERICAL:
                slots.append((2, idx[2], float(np.sign(axes[2] @ B[:, 2])), "periodic"))
        bounds: list = [None, None, None]  # per theta_i: (lower, upper) of theta_i - centre_i, or None
        centre = [0.0, 0.0, 0.0]
        for ti, j, sign, kind in slots:
            if j in held_coordinates:
                continue
            lo, hi = (lim[j] if sign > 0 else -lim[j, ::-1])  # range of theta_i = sign * q_j
            lo, hi, c = limit_window(float(lo), float(hi), kind, half)
            if lo is None:
                if np.isfinite(lim[j]).any():
                    log.info("joint '%s': the range of '%s' cannot be enforced (too wide to tell its ends apart)",
                             joint.name, model.coordinate_names[j])
                continue
            bounds[ti], centre[ti] = (lo, hi), c
        if all(b is None for b in bounds):
            continue
        # marker frames: theta' = RotXYZ(J0^T R_rel J1) = theta - centre (joint frames in the
        # parent's and the child's coordinates; the two coincide at q = 0)
        ex, ey, ez = np.eye(3)
        J0 = B @ axis_rotation(ex, np.array(centre[0]))
        parent, child = bodies[names.index(seg.parent)], bodies[i]
        centre_m = [float(x) for x in joint.centre_m]
        if joint.kind is JointKind.REVOLUTE or (joint.kind is JointKind.CARDAN and idx[1] in held_coordinates):
            # one free rotation, about the parent-fixed x of B: a torsional spring-damper about
            # it (the frames' z; a held second cardan angle v is undone on the child's side)
            v = float(q0[idx[1]]) if joint.kind is JointKind.CARDAN else 0.0
            P = np.column_stack([ey, ez, ex])  # (B P)'s z is B's x
            m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent, localHT=exu.HT(rotation=J0 @ P, translation=centre_m)))
            m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child, localHT=exu.HT(
                rotation=B @ axis_rotation(ey, np.array(-v)) @ P, translation=[0.0, 0.0, 0.0])))
            uf = CreateSymbolicUserFunction(mbs, _limit_torque_1d(k_lim, *bounds[0]), "springTorqueUserFunction",
                                            itemTypeName="ObjectConnectorTorsionalSpringDamper")
            obj = mbs.AddObject(eii.ObjectConnectorTorsionalSpringDamper(
                markerNumbers=[m0, m1], springTorqueUserFunction=uf, activeConnector=False,
                visualization=eii.VObjectConnectorTorsionalSpringDamper(show=False)))
            out.append(LimitElement(joint.name, obj, uf, [(0, *bounds[0])], scalar=True))
            continue
        if joint.kind is JointKind.SPHERICAL:
            J1 = B @ axis_rotation(ez, np.array(-centre[2]))
        else:
            J1 = B @ axis_rotation(ey, np.array(-centre[1]))
        m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent, localHT=exu.HT(rotation=J0, translation=centre_m)))
        m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child, localHT=exu.HT(rotation=J1, translation=[0.0, 0.0, 0.0])))
        three = joint.kind is JointKind.SPHERICAL and idx[2] not in held_coordinates  # else t2 is fixed
        uf = CreateSymbolicUserFunction(mbs, _limit_torque(k_lim, bounds, three),
                                        "springForceTorqueUserFunction", itemTypeName="ObjectConnectorRigidBodySpringDamper")
        obj = mbs.AddObject(eii.ObjectConnectorRigidBodySpringDamper(
            markerNumbers=[m0, m1], springForceTorqueUserFunction=uf, activeConnector=False,
            offset=[1.0, 0.0, 0.0, 0.0, 0.0, 0.0],  # the branch flag of _limit_torque
            visualization=eii.VObjectConnectorRigidBodySpringDamper(show=False)))
        # the other branch of a spherical joint's sequence is a choice only with all three angles
        # free; which branch the joint is on is judged against the full ranges of its three
        # coordinates (the middle one's included where no element can enforce it)
        choice = None
        if three:
            choice = []
            for ti, j, sign, _kind in slots:
                lo, hi = (lim[j] if sign > 0 else -lim[j, ::-1])
                choice.append((ti, float(lo) - centre[ti], float(hi) - centre[ti]))
        out.append(LimitElement(joint.name, obj, uf, [(ti, b[0], b[1]) for ti, b in enumerate(bounds) if b is not None],
                                          branch_bounds=choice))
    return out


def _limit_torque_1d(k_lim: float, lower: float, upper: float):
    """Symbolic springTorqueUserFunction of a torsional limit spring: k_lim times the angle's
    excursion beyond [lower, upper] (a spring torque: Exudyn applies -torque about the axis to the
    child, so the generalized force is -dV/dq). A closure without default arguments."""

    def limit_torque(mbs, t, itemNumber, rotation, angularVelocity, stiffness, damping, offset):
        torque = 0.0 * rotation
        if math.isfinite(upper):
            torque = k_lim * esym.max(rotation - upper, 0.0)
        if math.isfinite(lower):
            below = k_lim * esym.min(rotation - lower, 0.0)
            torque = below if not math.isfinite(upper) else torque + below
        return torque

    return limit_torque


def _limit_torque(k_lim: float, bounds, three_angles: bool):
    """Symbolic springForceTorqueUserFunction of a limit connector: no force, and the spring torque
    m = W^-T dV/dtheta (joint-0 frame) of V = sum_i k_lim / 2 (theta_i beyond its range)^2. Exudyn
    applies a connector's force like a spring's (-m on the child, +m on the parent: the generalized
    force on theta is -W^T m = -dV/dtheta).

    W's columns are the axes of the Tait-Bryan angles (the relative angular velocity is
    W theta_t): w0 = e_x, w1 = Rx(t0) e_y, w2 = Rx(t0) Ry(t1) e_z. Its dual basis (rows of W^-1) is
    d0 = (1, s0 s1 / c1, -c0 s1 / c1), d1 = w1, d2 = (0, -s0, c0) / c1, so m = g0 d0 + g1 d1 +
    g2 d2 with g_i = dV/dtheta_i. Unless ``three_angles`` (a cardan joint, or a spherical one with
    its last angle held) the joint takes any torque along d2 (theta_2 is fixed), so d0 reduces to
    e_x. ``bounds``: per angle (lower, upper) or None; 1/c1 is capped at 1/_LIMIT_MIN_COS (gimbal
    lock of a spherical joint: |t1| > 89.4 deg).
    A closure without default arguments (Exudyn's symbolic conversion rejects those)."""

    def limit_torque(mbs, t, itemNumber, displacement, rotation, velocity, angularVelocity, stiffness, damping,
                     rotJ0, rotJ1, offset):
        # offset[0] = +1: the joint is on the principal branch of its sequence; -1: on the other one
        # (the pre-step sets it: LimitElement.distance), whose angles are (t0 + pi, +-pi - t1,
        # t2 + pi) and whose middle angle runs against the principal one (d t1'/d t1 = -1)
        f = offset[0]
        h = 0.5 * (1.0 + f)
        g = [None, None, None]
        for i in range(3):
            if bounds[i] is None:
                continue
            if i == 1:
                alt = math.pi * esym.sign(rotation[1]) - rotation[1]
            else:
                alt = rotation[i] - math.pi * esym.sign(rotation[i])
            x = h * rotation[i] + (1.0 - h) * alt
            lo, hi = bounds[i]
            if math.isfinite(hi):
                g[i] = k_lim * esym.max(x - hi, 0.0)
            if math.isfinite(lo):
                below = k_lim * esym.min(x - lo, 0.0)
                g[i] = below if g[i] is None else g[i] + below
            if i == 1:
                g[i] = f * g[i]
        zero = 0.0 * rotation[0]
        m = [None, None, None]

        def add(i, term):
            m[i] = term if m[i] is None else m[i] + term

        if g[1] is not None or (three_angles and (g[0] is not None or g[2] is not None)):
            s0, c0 = esym.sin(rotation[0]), esym.cos(rotation[0])
        if three_angles and (g[0] is not None or g[2] is not None):
            inv_c1 = 1.0 / esym.max(esym.cos(rotation[1]), _LIMIT_MIN_COS)
        if g[0] is not None:
            add(0, g[0])
            if three_angles:
                t1 = esym.sin(rotation[1]) * inv_c1
                add(1, g[0] * s0 * t1)
                add(2, -(g[0] * c0 * t1))
        if g[1] is not None:
            add(1, g[1] * c0)
            add(2, g[1] * s0)
        if g[2] is not None:
            add(1, -(g[2] * s0 * inv_c1))
            add(2, g[2] * c0 * inv_c1)
        m = [zero if x is None else x for x in m]
        return [zero, zero, zero, m[0], m[1], m[2]]

    return limit_torque


# --------------------------------------------------------------------------------------------
# Their switching during a run
# --------------------------------------------------------------------------------------------
class LimitSwitching:
    """The limit elements of a run of steps of ``step_s`` (see the module docstring): a joint's element
    is on while one of its angles is within ``margin`` (one step of travel at the largest rate) of a
    limit or beyond it, judged from the state at the start of each step (:meth:`check`, due when the
    step starts at or after ``next_check``); a joint d > margin away is looked at again only once it
    may have come within the margin, i.e. after (d - margin) / rate. Made at the start of a run: the
    elements are reset and looked at in the initial state."""

    def __init__(self, mbs, elements: Sequence[LimitElement], max_rate_rad_s: float, step_s: float):
        self.elements = elements
        self.sd, self.set_parameter = mbs.systemData, mbs.SetObjectParameter
        self.get_output, self.rotation_output = mbs.GetObjectOutput, exu.OutputVariableType.Rotation
        self.rate = max_rate_rad_s
        self.margin = self.rate * step_s
        self.next_check = math.inf  # the earliest time a joint must be looked at again
        set_parameter = self.set_parameter
        for e in elements:
            e.active, e.next_check, e.on_since, e.active_s = False, -math.inf, 0.0, 0.0
            set_parameter(e.obj, "activeConnector", False)
            if e.branches is not None:
                e.branch = 1.0
                set_parameter(e.obj, "offset", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        if elements:  # from the initial state, before the initial accelerations are computed
            sd = self.sd
            sd.SetODE2Coordinates(sd.GetODE2Coordinates(configuration=exu.ConfigurationType.Initial),
                                  configuration=exu.ConfigurationType.Current)
            self.check(0.0)

    def check(self, t_start: float) -> None:
        """Switch the elements due at ``t_start`` (the start of a step) on or off, and say when each
        is due again."""
        get_output, rotation_output, set_parameter = self.get_output, self.rotation_output, self.set_parameter
        margin, rate = self.margin, self.rate
        first = math.inf
        for e in self.elements:
            if e.next_check <= t_start:
                branch = e.branch
                d = e.distance(get_output(e.obj, rotation_output))
                if e.branch != branch:
                    set_parameter(e.obj, "offset", [e.branch, 0.0, 0.0, 0.0, 0.0, 0.0])
                if (d < margin) != e.active:
                    e.active = not e.active
                    set_parameter(e.obj, "activeConnector", e.active)
                    if e.active:
                        e.on_since = t_start
                    else:
                        e.active_s += t_start - e.on_since
                e.next_check = t_start + (d - margin) / rate
            if e.next_check < first:
                first = e.next_check
        self.next_check = first

    def active_time_s(self, t_end: float) -> dict[str, float]:
        """Per joint with a limit element, the time (s) it was switched on (near or beyond a limit)
        up to ``t_end``."""
        return {e.joint: e.active_s + (t_end - e.on_since if e.active else 0.0) for e in self.elements}
