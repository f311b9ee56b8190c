"""The Exudyn multibody system of the potential-field method; the only module that imports exudyn.

Redundant coordinates (measured ~20x faster than Exudyn's minimal-coordinate kinematic tree, see
shared/notes/exudyn-pf-findings.md): every movable segment is an ``ObjectRigidBody`` on a
``NodeRigidBodyEP`` (Euler parameters) whose reference configuration is the initial posture q0;
the joints are native constraints (spherical: ``ObjectJointSpherical``; revolute about any axis:
``ObjectJointRevoluteZ`` between two marker frames whose z axis is the joint axis; cardan:
``ObjectJointGeneric`` with one constrained rotation, t_y0 . t_z1 = 0, which needs perpendicular
axes). Each scapula contact point is held on the thorax ellipsoid through an auxiliary point
node (spherical joint to the scapula point) and an ``ObjectConnectorCoordinateVector`` with a
quadratic term, so g = (r - c)^T A (r - c) - 1 = 0 is an index-3 constraint without Python.

Every measured marker pulls its segment-fixed model point through a linear spring-damper,
f = c (r_R - r_M) + d (v_R - v_M) = c (r_R - [r_M + (d/c) v_M]) + d v_R: Exudyn's own
``ObjectConnectorCartesianSpringDamper`` from the ground origin to the model point whose offset
is set to r_M + (d/c) v_M once per time step by a pre-step function (no Python inside Newton,
analytic Jacobian; measured ~20 % faster than the same force as a symbolic user function, which
remains the fallback when a spring has c = 0). A missing marker switches its spring off
(``activeConnector``) for the steps that touch the gap. The equations of motion are integrated
with Exudyn's implicit generalized-alpha solver (index 3, modified Newton, Eigen's sparse LU
with the analysed pattern reused). A step may span several frames: the springs are then set to
the frame each step ends on and the frames inside a step are quintic Hermite interpolations of
the step states (q, q̇, q̈ of one polynomial, so the three stay consistent); a last, shorter step
ends on the last frame. Segment poses, velocities and accelerations are returned at the frame
times.

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

Outside this module nothing knows about Exudyn: inputs and outputs are numpy arrays (SI units,
time first) and the frozen dataclasses below. Segment indices are those of ``Model.segments``
(0 = thorax, fixed).
"""
from __future__ import annotations

import dataclasses
import logging
import math
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence, Mapping

import numpy as np

import exudyn as exu
import exudyn.itemInterface as eii
from exudyn.advancedUtilities import CreateSymbolicUserFunction
from exudyn.rigidBodyUtilities import RotationMatrix2EulerParameters

from exubio.backend.pf_numerics import (LimitElement, StateRecord, ep_G, ep_rotation, frame_with_z, frames_from_steps,
                                       hermite, limit_window, quintic)
from exubio.errors import ModelError
from exubio.model.kinematics import axis_rotation, Kinematics, PointSet
from exubio.model.ranges import DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD  # k_lim, shared with LS
from exubio.types import JointKind, Model

esym = exu.symbolic

log = logging.getLogger(__name__)

GRAVITY_M_S2 = np.array([0.0, -9.81, 0.0])  # thorax frame: Y up
_SYMBOLIC_SPRINGS = False  # benchmarks only: force the symbolic spring force (the former design)
_AUX_MASS_KG = 1e-3  # mass of each auxiliary ellipsoid point (numerically needed, physically negligible)
_ROW_BLOCK = 4096  # spring targets of this many step ends are made at a time
_TIMER_FIELDS = (
    "total", "factorization", "newtonIncrement", "integrationFormula", "ODE2RHS", "AERHS",
    "totalJacobian", "massMatrix", "reactionForces", "python", "postNewton", "writeSolution", "overhead",
)  # fmt: skip
DEFAULT_LIMIT_MAX_RATE_RAD_S = 10.0  # fastest joint-angle rate the switching of the limits allows for
_LIMIT_MIN_COS = 1e-2  # spherical joints: 1 / cos(middle angle) capped at 100 (gimbal lock, |q2| > 89.4 deg)


# --------------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpringSet:
    """The model points tied to measured markers, one spring-damper each.

    segment_index:     (k,) index into ``Model.segments`` (not 0: the thorax does not move).
    local_m:           (k, 3) model-point positions in their segment's frame (m).
    stiffness_n_per_m: (k,) spring constants c (N/m).
    damping_ns_per_m:  (k,) damping constants d (N s/m).
    """

    segment_index: np.ndarray
    local_m: np.ndarray
    stiffness_n_per_m: np.ndarray
    damping_ns_per_m: np.ndarray

    def __post_init__(self) -> None:
        idx = np.asarray(self.segment_index, dtype=int).reshape(-1)
        k = idx.shape[0]
        local = np.asarray(self.local_m, dtype=float)
        if local.shape != (k, 3):
            raise ValueError(f"SpringSet: local_m must have shape ({k}, 3), got {local.shape}")
        c = np.broadcast_to(np.asarray(self.stiffness_n_per_m, dtype=float), (k,)).copy()
        d = np.broadcast_to(np.asarray(self.damping_ns_per_m, dtype=float), (k,)).copy()
        if np.any(~np.isfinite(c)) or np.any(c < 0) or np.any(~np.isfinite(d)) or np.any(d < 0):
            raise ValueError("SpringSet: stiffness and damping must be finite and >= 0")
        for name, value in (("segment_index", idx), ("local_m", local), ("stiffness_n_per_m", c), ("damping_ns_per_m", d)):
            object.__setattr__(self, name, value)

    @classmethod
    def from_points(cls, points: PointSet, /, *, stiffness_n_per_m, damping_ns_per_m) -> "SpringSet":
        """Springs on a kinematics PointSet; constants are scalars or (k,) arrays."""
        return cls(points.segment_index, points.local_m, stiffness_n_per_m, damping_ns_per_m)

    @property
    def n_springs(self) -> int:
        return int(self.segment_index.shape[0])


@dataclass(frozen=True)
class IntegratorOptions:
    """Settings of Exudyn's generalized-alpha integration (the PF method passes its own, see
    exubio.methods.pf.PFOptions; these defaults are the ones for one step per frame).

    step_s: time step; None = one step per frame. Shorter than a frame: frame_dt_s / step_s must
        be an integer (targets between frames: cubic Hermite interpolation of positions and
        velocities). Longer: step_s / frame_dt_s must be an integer (see ``PFSystem.run``).
    spectral_radius, newton_relative_tolerance, modified_newton_contractivity: at one step per
        5 ms frame (0, 1e-5, 0.2) keep q̈ closest to the derivative of q̇ (benchmarks/README.md).
        Exudyn's Newton stops when its residual (forces in N and constraint violations in m, one
        L2 norm) has dropped by newton_relative_tolerance, or is below
        newton_absolute_tolerance.
    modified_newton: Jacobian kept over steps and rebuilt when the contraction of the Newton
        residual is worse than ``modified_newton_contractivity`` (modified Newton measured 2-4x
        faster *and* more accurate than full Newton here; a Jacobian every step: +30 % time).
    sparse_solver: Eigen's SparseLU reusing its analysed pattern (~15 % faster than Exudyn's own
        dense LU, the 1.13 default); False = the dense LU.
    timing_breakdown: fill ``PFRun.solver_times_s`` with Exudyn's CPU timers (~1 % cost).
    """

    step_s: float | None = None
    spectral_radius: float = 0.0
    newton_relative_tolerance: float = 1e-5
    newton_absolute_tolerance: float = 1e-10
    modified_newton: bool = True
    modified_newton_contractivity: float = 0.2
    max_newton_iterations: int = 25
    adaptive_step: bool = True
    sparse_solver: bool = True
    timing_breakdown: bool = True


@dataclass(frozen=True)
class PFRun:
    """Segment motion at the input frame times (n frames, n_seg = all model segments incl. thorax).

    rotations:   (n, n_seg, 3, 3) segment orientations R (local -> thorax frame).
    origins_m:   (n, n_seg, 3) segment frame origins (joint centres).
    velocities_m_s, accelerations_m_s2: (n, n_seg, 3) of the origins.
    angular_velocities_rad_s, angular_accelerations_rad_s2: (n, n_seg, 3), thorax frame.
    completed_frames: frames the solver reached (rows from here on are NaN if it stopped early).
    success: the solver finished the whole trial; message: its error otherwise.
    wall_time_s: the solve alone; solver_times_s: Exudyn's CPU-time breakdown (s).
    newton_iterations, jacobian_updates, steps: solver statistics of the whole run; step_s: the
    step used. limit_active_s: per joint with a limit element, the time (s) it was switched on
    (near or beyond a limit).
    """

    time_s: np.ndarray
    rotations: np.ndarray
    origins_m: np.ndarray
    velocities_m_s: np.ndarray
    accelerations_m_s2: np.ndarray
    angular_velocities_rad_s: np.ndarray
    angular_accelerations_rad_s2: np.ndarray
    completed_frames: int
    success: bool
    message: str
    wall_time_s: float
    solver_times_s: Mapping[str, float] = field(default_factory=dict)
    newton_iterations: int = 0
    jacobian_updates: int = 0
    steps: int = 0
    step_s: float = float("nan")
    limit_active_s: Mapping[str, float] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])


# --------------------------------------------------------------------------------------------
# The system
# --------------------------------------------------------------------------------------------
class PFSystem:
    """An Exudyn system of a Model with one spring-damper per model point of ``springs``.

    The reference configuration of every body is the posture q0 (so a run starts exactly there,
    with velocities from qd0); every ``run`` starts again from (q0, qd0).

    limits_rad: (m, 2) range [lower, upper] of every coordinate (rad, +-inf = no limit on that
        side), or None: no limits. Held coordinates and the joints of locked segments get none.
        See the module docstring for the elements.
    limit_stiffness_nm_per_rad: k_lim of the limit potential. Default 1e4 N m/rad. The marker
        springs hold a coordinate with c sum L^2: 4-135 N m/rad per marker (c = 1500 N/m, lever
        arms L = 0.05-0.3 m); on the 21-marker protocol 16-22 N m/rad for pronation and the wrist,
        620 for the elbow, 3.4e3 for the glenohumeral and up to 4.6e3 for the girdle coordinates
        with the other coordinates held, at most 110 N m/rad with them free (which is what resists
        markers that drive one coordinate beyond its range). A coordinate settles tau / k_lim
        beyond its limit, tau the springs' generalized force: 0.57 deg per 10 N m. Measured: an
        elbow driven 20 deg beyond by exact markers stays 0.4 deg beyond (k_lim = 1e3: 3.5 deg);
        the benchmark abduction with gh_abduction limited 25 deg below its motion: 0.26 deg (1e3:
        2.2 deg, 3e4: 0.10 deg). Stiffer limits cost Jacobian updates: their modes (up to ~1e4
        rad/s on the scapula's small inertia, against <= 175 rad/s of the springs) make modified
        Newton rebuild its Jacobian as a limit engages: on that trial 0.29 / 0.31 / 0.35 / 0.46 /
        0.63 Jacobians per step (0.27 without limits) and +26 / 33 / 34 / 50 / 67 % time for
        k_lim = 1e3 / 3e3 / 1e4 / 3e4 / 1e5 N m/rad. 1e4 is the knee. No limit damping: the
        integrator's numerical damping (rho_inf 0.5) takes the impact. An elbow driven into its
        limit at 3.7 rad/s (markers going on to 20 deg beyond) peaks 0.9 deg beyond one step later
        and its rate rings for 3 steps (-0.3, -0.1, +0.08 rad/s), then eases to the 0.4 deg of the
        equilibrium as the markers stop (k_lim 1e5: +-0.9 rad/s for 5 steps; 1e3: 6 deg beyond).
    limit_max_rate_rad_s: the largest joint-angle rate the switching of the limit elements allows
        for (see the module docstring); faster joints may cross a limit for one step before their
        element switches on.
    """

    def __init__(self, model: Model, springs: SpringSet, /, *, q0: np.ndarray, qd0: np.ndarray | None = None,
                 gravity: bool = False, kinematics: Kinematics | None = None, locked_segments: Sequence[int] = (),
                 held_coordinates: Sequence[int] = (), limits_rad: np.ndarray | None = None,
                 limit_stiffness_nm_per_rad: float = DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD,
                 limit_max_rate_rad_s: float = DEFAULT_LIMIT_MAX_RATE_RAD_S):
        self.model = model
        self.locked_segments = frozenset(int(i) for i in locked_segments)
        self.held_coordinates = frozenset(int(i) for i in held_coordinates)
        self.kin = kinematics if kinematics is not None else Kinematics(model)
        self.springs = springs
        n_seg = len(model.segments)
        m = model.n_coordinates
        q0 = np.asarray(q0, dtype=float)
        qd0 = np.zeros(m) if qd0 is None else np.asarray(qd0, dtype=float)
        if q0.shape != (m,) or qd0.shape != (m,):
            raise ValueError(f"PFSystem: q0 and qd0 must have shape ({m},), got {q0.shape} and {qd0.shape}")
        if springs.n_springs == 0:
            raise ValueError("PFSystem: no springs")
        bad = (springs.segment_index < 1) | (springs.segment_index >= n_seg)
        if np.any(bad):
            raise ModelError(
                f"{model.source or model.name}: springs must sit on movable segments 1..{n_seg - 1} "
                f"{list(model.segment_names[1:])}; got segment indices {springs.segment_index[bad].tolist()}"
            )
        if model.segments[0].joint is not None or model.segments[0].parent is not None:
            raise ModelError(f"{model.source or model.name}: the first segment must be the fixed thorax")
        self.q0, self.qd0 = q0.copy(), qd0.copy()

        t_build = time.perf_counter()
        self._sc = exu.SystemContainer()
        mbs = self._mbs = self._sc.AddSystem()
        R0, p0 = self.kin.poses(q0)
        origins = PointSet(np.arange(n_seg), np.zeros((n_seg, 3)))
        v0 = np.einsum("kcm,m->kc", self.kin.point_jacobian(q0, origins), qd0)
        w0 = self.kin.segment_angular_velocities(q0, qd0)

        self._ground = mbs.AddObject(eii.ObjectGround())
        self._nodes: list = [None]  # per segment; thorax has none
        self._bodies: list = [self._ground]
        self._ep_ref = np.zeros((n_seg, 4))
        self._p_ref = np.zeros((n_seg, 3))
        for i, seg in enumerate(model.segments[1:], start=1):
            ep = np.asarray(RotationMatrix2EulerParameters(R0[i]), dtype=float)
            ep_t = 0.25 * ep_G(ep).T @ w0[i]
            self._ep_ref[i], self._p_ref[i] = ep, p0[i]
            node = mbs.AddNode(eii.NodeRigidBodyEP(
                referenceCoordinates=list(p0[i]) + list(ep), initialVelocities=list(v0[i]) + list(ep_t),
                visualization=eii.VNodeRigidBodyEP(show=False)))
            mass = float(seg.mass_kg)
            com = np.asarray(seg.com_m, dtype=float)
            inertia = np.asarray(seg.inertia_kgm2, dtype=float) + mass * (com @ com * np.eye(3) - np.outer(com, com))
            body = mbs.AddObject(eii.ObjectRigidBody(
                nodeNumber=node, mass=mass, centerOfMass=list(com),
                inertia=[inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[1, 2], inertia[0, 2], inertia[0, 1]],
                visualization=eii.VObjectRigidBody(show=False)))
            if gravity:
                mk = mbs.AddMarker(eii.MarkerBodyMass(bodyNumber=body))
                mbs.AddLoad(eii.LoadMassProportional(markerNumber=mk, loadVector=list(GRAVITY_M_S2)))
            self._nodes.append(node)
            self._bodies.append(body)

        names = model.segment_names
        for i, seg in enumerate(model.segments[1:], start=1):
            if i in self.locked_segments:  # no marker moves it: held at its initial relative orientation
                self._add_locked_joint(seg, self._bodies[names.index(seg.parent)], self._bodies[i],
                                       R0[names.index(seg.parent)].T @ R0[i])
            else:
                idx = [int(j) for j in self.kin.joint_coordinate_indices(i)]
                held = [j in self.held_coordinates for j in idx]
                parent, child = self._bodies[names.index(seg.parent)], self._bodies[i]
                if all(held):
                    self._add_locked_joint(seg, parent, child, R0[names.index(seg.parent)].T @ R0[i])
                elif any(held):
                    if held != [False] * (len(idx) - 1) + [True]:
                        raise ModelError(f"joint '{seg.joint.name}': only its last coordinate, or all, can be held; "
                                         f"asked to hold {[self.model.coordinate_names[j] for j, h in zip(idx, held) if h]}")
                    self._add_joint_last_held(seg, parent, child, float(q0[idx[-1]]))
                else:
                    self._add_joint(seg, parent, child)
        self._limits: list[LimitElement] = []
        if limits_rad is not None:
            self._add_limits(limits_rad, float(limit_stiffness_nm_per_rad))
        self.limit_max_rate_rad_s = float(limit_max_rate_rad_s)
        if not self.limit_max_rate_rad_s > 0:
            raise ValueError(f"PFSystem: limit_max_rate_rad_s must be > 0, got {limit_max_rate_rad_s}")

        # ellipsoid: auxiliary point held to each contact point, g = (r - c)^T A (r - c) - 1 = 0
        ell = model.ellipsoid
        a = ell.a_diag
        c = np.asarray(ell.centre_m, dtype=float)
        contacts = self.kin.contacts
        rc0 = self.kin.points(q0, contacts)
        vc0 = np.einsum("kcm,m->kc", self.kin.point_jacobian(q0, contacts), qd0)
        ground_node = mbs.AddNode(eii.NodePointGround())
        ground_coords = mbs.AddMarker(eii.MarkerNodeCoordinates(nodeNumber=ground_node))
        self._aux_nodes = []
        for j in range(len(contacts.segment_index)):
            node = mbs.AddNode(eii.NodePoint(referenceCoordinates=list(rc0[j]), initialVelocities=list(vc0[j]),
                                             visualization=eii.VNodePoint(show=False)))
            mbs.AddObject(eii.ObjectMassPoint(nodeNumber=node, mass=_AUX_MASS_KG, visualization=eii.VObjectMassPoint(show=False)))
            on_body = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=self._bodies[contacts.segment_index[j]],
                                                           localPosition=list(contacts.local_m[j])))
            on_node = mbs.AddMarker(eii.MarkerNodePosition(nodeNumber=node))
            mbs.AddObject(eii.ObjectJointSpherical(markerNumbers=[on_body, on_node], visualization=eii.VObjectJointSpherical(show=False)))
            coords = mbs.AddMarker(eii.MarkerNodeCoordinates(nodeNumber=node))
            mbs.AddObject(eii.ObjectConnectorCoordinateVector(
                markerNumbers=[ground_coords, coords], scalingMarker1=[list(-2.0 * a * c)],
                quadraticTermMarker1=[list(a)], offset=[1.0 - float(c @ (a * c))]))
            self._aux_nodes.append(node)

        # springs: ground origin -> model point, force from a symbolic function of a 6-vector target
        origin = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=self._ground, localPosition=[0.0, 0.0, 0.0]))
        self._targets = []  # symbolic Vector(6) per spring: target position, velocity
        self._user_functions = []  # must stay alive as long as the system
        self._spring_objects = []
        self._point_markers = []
        # c (r - r_M) + d (v - v_M) = c (r - [r_M + (d/c) v_M]) + d v: Exudyn's own Cartesian
        # spring-damper with the offset r_M + (d/c) v_M set once per step (analytic Jacobian, no
        # user function; ~20 % faster than a symbolic force function). A spring without stiffness
        # cannot carry the damper's target velocity in its offset: then every spring is symbolic.
        self._native = bool(np.all(springs.stiffness_n_per_m > 0)) and not _SYMBOLIC_SPRINGS
        for k in range(springs.n_springs):
            point = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=self._bodies[springs.segment_index[k]],
                                                         localPosition=list(springs.local_m[k])))
            if self._native:
                target = uf = None
                extra = {}
            else:
                target = exu.symbolic.Vector(f"pf_target_{k}", [0.0] * 6)
                uf = CreateSymbolicUserFunction(mbs, _spring_force(target), "springForceUserFunction",
                                                itemTypeName="ObjectConnectorCartesianSpringDamper")
                extra = {"springForceUserFunction": uf}
            obj = mbs.AddObject(eii.ObjectConnectorCartesianSpringDamper(
                markerNumbers=[origin, point], stiffness=[float(springs.stiffness_n_per_m[k])] * 3,
                damping=[float(springs.damping_ns_per_m[k])] * 3, **extra,
                visualization=eii.VObjectConnectorCartesianSpringDamper(show=False)))
            self._targets.append(target)
            self._user_functions.append(uf)
            self._spring_objects.append(obj)
            self._point_markers.append(point)
        mbs.Assemble()
        sd = mbs.systemData
        self._ltg = [None] + [np.asarray(sd.GetNodeLTGODE2(n), dtype=int) for n in self._nodes[1:]]
        self._ltg_all = np.array(self._ltg[1:], dtype=int).reshape(len(self._ltg) - 1, -1)
        self._aux_ltg = [np.asarray(sd.GetNodeLTGODE2(n), dtype=int) for n in self._aux_nodes]
        self._n_ode2 = sd.ODE2Size()
        self.build_time_s = time.perf_counter() - t_build

    # ---------------------------------------------------------------- building blocks
    def _add_locked_joint(self, seg, parent_body, child_body, R_rel: np.ndarray) -> None:
        """A rigid connection that keeps the child at the relative orientation R_rel."""
        mbs = self._mbs
        centre = [float(x) for x in seg.joint.centre_m]
        m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent_body, localHT=exu.HT(rotation=R_rel, translation=centre)))
        m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child_body, localHT=exu.HT(rotation=np.eye(3), translation=[0.0, 0.0, 0.0])))
        mbs.AddObject(eii.ObjectJointGeneric(markerNumbers=[m0, m1], constrainedAxes=[1, 1, 1, 1, 1, 1],
                                             visualization=eii.VObjectJointGeneric(show=False)))

    def _add_joint_last_held(self, seg, parent_body, child_body, value: float) -> None:
        """A spherical joint with its third rotation held (a cardan joint), or a cardan joint with its
        second held (a revolute joint), the held rotation fixed at ``value`` in the child's frame."""
        mbs = self._mbs
        joint = seg.joint
        centre = [float(x) for x in joint.centre_m]
        axes = [np.asarray(a, dtype=float) for a in joint.axes]
        offset = axis_rotation(axes[-1], np.array(value)).T  # child-frame coordinates of the free axes
        if joint.kind is JointKind.SPHERICAL:
            a1, a2 = axes[0], axes[1]
            J0 = frame_with_z(a1)[:, [1, 2, 0]]
            J1 = offset @ frame_with_z(a2)
            m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent_body, localHT=exu.HT(rotation=J0, translation=centre)))
            m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child_body, localHT=exu.HT(rotation=J1, translation=[0.0, 0.0, 0.0])))
            mbs.AddObject(eii.ObjectJointGeneric(markerNumbers=[m0, m1], constrainedAxes=[1, 1, 1, 1, 0, 0],
                                                 visualization=eii.VObjectJointGeneric(show=False)))
        elif joint.kind is JointKind.CARDAN:
            J = frame_with_z(axes[0])
            m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent_body, localHT=exu.HT(rotation=J, translation=centre)))
            m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child_body, localHT=exu.HT(rotation=offset @ J, translation=[0.0, 0.0, 0.0])))
            mbs.AddObject(eii.ObjectJointRevoluteZ(markerNumbers=[m0, m1], visualization=eii.VObjectJointRevoluteZ(show=False)))
        else:
            raise ModelError(f"joint '{joint.name}' ({joint.kind.value}): hold all of its coordinates or none")

    def _add_joint(self, seg, parent_body, child_body) -> None:
        mbs = self._mbs
        joint = seg.joint
        centre = [float(x) for x in joint.centre_m]
        if joint.kind is JointKind.SPHERICAL:
            m0 = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=parent_body, localPosition=centre))
            m1 = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=child_body, localPosition=[0.0, 0.0, 0.0]))
            mbs.AddObject(eii.ObjectJointSpherical(markerNumbers=[m0, m1], visualization=eii.VObjectJointSpherical(show=False)))
        elif joint.kind is JointKind.REVOLUTE:
            # parent and child frames coincide at q = 0, so the axis is the same local vector on both
            J = frame_with_z(joint.axes[0])
            m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent_body, localHT=exu.HT(rotation=J, translation=centre)))
            m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child_body, localHT=exu.HT(rotation=J, translation=[0.0, 0.0, 0.0])))
            mbs.AddObject(eii.ObjectJointRevoluteZ(markerNumbers=[m0, m1], visualization=eii.VObjectJointRevoluteZ(show=False)))
        elif joint.kind is JointKind.CARDAN:
            a1, a2 = (np.asarray(x, dtype=float) for x in joint.axes)
            if abs(a1 @ a2) > 1e-9 * np.linalg.norm(a1) * np.linalg.norm(a2):
                raise ModelError(f"{self.model.source or self.model.name}: cardan joint '{joint.name}' needs perpendicular axes")
            # ObjectJointGeneric with only rotation x constrained imposes t_y0 . t_z1 = 0:
            # y of the parent's joint frame = a1 (fixed in the parent), z of the child's = a2.
            J0 = frame_with_z(a1)[:, [1, 2, 0]]
            J1 = frame_with_z(a2)
            m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent_body, localHT=exu.HT(rotation=J0, translation=centre)))
            m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child_body, localHT=exu.HT(rotation=J1, translation=[0.0, 0.0, 0.0])))
            mbs.AddObject(eii.ObjectJointGeneric(markerNumbers=[m0, m1], constrainedAxes=[1, 1, 1, 1, 0, 0],
                                                 visualization=eii.VObjectJointGeneric(show=False)))
        else:  # pragma: no cover - JointKind is closed
            raise ModelError(f"joint kind {joint.kind} is not supported by the Exudyn backend")

    def _add_limits(self, limits_rad, k_lim: float) -> None:
        """One limit element per joint with a finite range on a solved coordinate (see the module
        docstring), switched off; ``run`` switches it on near a limit."""
        m = self.model.n_coordinates
        lim = np.array(limits_rad, dtype=float)
        if lim.shape != (m, 2):
            raise ValueError(f"PFSystem: limits_rad must have shape ({m}, 2), got {lim.shape}")
        if np.isnan(lim).any() or np.any(lim[:, 0] > lim[:, 1]) or np.isposinf(lim[:, 0]).any() or np.isneginf(lim[:, 1]).any():
            raise ValueError("PFSystem: limits_rad rows must be [lower, upper] with lower <= upper (+-inf = no limit)")
        if not (math.isfinite(k_lim) and k_lim > 0):
            raise ValueError(f"PFSystem: limit_stiffness_nm_per_rad must be finite and > 0, got {k_lim}")
        mbs = self._mbs
        names = self.model.segment_names
        half = 0.5 * math.pi
        for i, seg in enumerate(self.model.segments[1:], start=1):
            if i in self.locked_segments:
                continue
            joint = seg.joint
            idx = [int(j) for j in self.kin.joint_coordinate_indices(i)]
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
                if j in self.held_coordinates:
                    continue
                lo, hi = (lim[j] if sign > 0 else -lim[j, ::-1])  # range of theta_i = sign * q_j
                lo, hi, c = limit_window(float(lo), float(hi), kind, half)
                if lo is None:
                    if np.isfinite(lim[j]).any():
                        log.info("joint '%s': the range of '%s' cannot be enforced (too wide to tell its ends apart)",
                                 joint.name, self.model.coordinate_names[j])
                    continue
                bounds[ti], centre[ti] = (lo, hi), c
            if all(b is None for b in bounds):
                continue
            # marker frames: theta' = RotXYZ(J0^T R_rel J1) = theta - centre (joint frames in the
            # parent's and the child's coordinates; the two coincide at q = 0)
            ex, ey, ez = np.eye(3)
            J0 = B @ axis_rotation(ex, np.array(centre[0]))
            parent, child = self._bodies[names.index(seg.parent)], self._bodies[i]
            centre_m = [float(x) for x in joint.centre_m]
            if joint.kind is JointKind.REVOLUTE or (joint.kind is JointKind.CARDAN and idx[1] in self.held_coordinates):
                # one free rotation, about the parent-fixed x of B: a torsional spring-damper about
                # it (the frames' z; a held second cardan angle v is undone on the child's side)
                v = float(self.q0[idx[1]]) if joint.kind is JointKind.CARDAN else 0.0
                P = np.column_stack([ey, ez, ex])  # (B P)'s z is B's x
                m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent, localHT=exu.HT(rotation=J0 @ P, translation=centre_m)))
                m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child, localHT=exu.HT(
                    rotation=B @ axis_rotation(ey, np.array(-v)) @ P, translation=[0.0, 0.0, 0.0])))
                uf = CreateSymbolicUserFunction(mbs, _limit_torque_1d(k_lim, *bounds[0]), "springTorqueUserFunction",
                                                itemTypeName="ObjectConnectorTorsionalSpringDamper")
                obj = mbs.AddObject(eii.ObjectConnectorTorsionalSpringDamper(
                    markerNumbers=[m0, m1], springTorqueUserFunction=uf, activeConnector=False,
                    visualization=eii.VObjectConnectorTorsionalSpringDamper(show=False)))
                self._limits.append(LimitElement(joint.name, obj, uf, [(0, *bounds[0])], scalar=True))
                continue
            if joint.kind is JointKind.SPHERICAL:
                J1 = B @ axis_rotation(ez, np.array(-centre[2]))
            else:
                J1 = B @ axis_rotation(ey, np.array(-centre[1]))
            m0 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=parent, localHT=exu.HT(rotation=J0, translation=centre_m)))
            m1 = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=child, localHT=exu.HT(rotation=J1, translation=[0.0, 0.0, 0.0])))
            three = joint.kind is JointKind.SPHERICAL and idx[2] not in self.held_coordinates  # else t2 is fixed
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
            self._limits.append(LimitElement(joint.name, obj, uf, [(ti, b[0], b[1]) for ti, b in enumerate(bounds) if b is not None],
                                              branch_bounds=choice))

    def _coordinates_for(self, q: np.ndarray) -> np.ndarray:
        """The system's ODE2 coordinates (relative to the reference posture q0) for posture q."""
        R, p = self.kin.poses(q)
        x = np.zeros(self._n_ode2)
        for i in range(1, len(self.model.segments)):
            ep = np.asarray(RotationMatrix2EulerParameters(R[i]), dtype=float)
            if ep @ self._ep_ref[i] < 0:
                ep = -ep
            x[self._ltg[i]] = np.concatenate([p[i] - self._p_ref[i], ep - self._ep_ref[i]])
        rc = self.kin.points(q, self.kin.contacts)
        rc0 = self.kin.points(self.q0, self.kin.contacts)
        for j, ltg in enumerate(self._aux_ltg):
            x[ltg] = rc[j] - rc0[j]
        return x

    # ---------------------------------------------------------------- queries
    @property
    def n_springs(self) -> int:
        return self.springs.n_springs

    def model_points(self, q: np.ndarray, /) -> np.ndarray:
        """Exudyn's own positions (k, 3) of the spring model points with the bodies set to posture q.

        Only the current configuration is touched; a later ``run`` still starts from q0.
        """
        q = np.asarray(q, dtype=float)
        if q.shape != (self.model.n_coordinates,):
            raise ValueError(f"model_points: q must have shape ({self.model.n_coordinates},), got {q.shape}")
        self._mbs.systemData.SetODE2Coordinates(list(self._coordinates_for(q)), configuration=exu.ConfigurationType.Current)
        return np.array([self._mbs.GetMarkerOutput(mk, exu.OutputVariableType.Position, configuration=exu.ConfigurationType.Current)
                         for mk in self._point_markers])

    # ---------------------------------------------------------------- run
    def run(self, targets_pos: np.ndarray, targets_vel: np.ndarray, active: np.ndarray | None = None, /, *,
            frame_dt_s: float, options: IntegratorOptions = IntegratorOptions(),
            progress: Callable[[int], None] | None = None,
            on_frames: Callable[[PFRun], None] | None = None, chunk_frames: int = 8000,
            first_chunk_extra: int = 0) -> PFRun:
        """Integrate the PF system through the measured marker trajectories.

        targets_pos, targets_vel: (n, k, 3) marker positions (m) and velocities (m/s) at the frame
            times i * frame_dt_s; frame 0 is the initial state (q0, qd0). Values where ``active``
            is False are ignored (NaN allowed there).
        active: (n, k) bool, False where a marker is missing: its spring is switched off. A step
            uses a spring only if it is active in every frame the step touches.

        Steps: ``options.step_s`` None = one per frame; shorter than a frame: a whole number per
        frame, the targets between frames from cubic Hermite interpolation of positions and
        velocities; longer: a whole number of frames per step (the springs see the frames the
        steps end on; the frames inside a step are quintic Hermite interpolations of the step
        states q, q̇, q̈), the last step shortened to end on the last frame.

        Streaming: with ``on_frames`` the frames go there as soon as the steps reach them, as
        PFRuns of ``chunk_frames`` consecutive frames (``time_s`` says which; the last chunk may
        be shorter, and ends at the last frame the solver reached), computed exactly as in one
        pass; the solver keeps only the steps still needed, and the PFRun returned carries the
        statistics with no frames. An exception raised by ``on_frames`` stops the solver and is
        raised from here. ``first_chunk_extra``: the first chunk has this many frames more (a
        lead-in before the frames the caller counts, exubio.methods.pf). Without it, the PFRun returned holds every frame.
        """
        pos = np.asarray(targets_pos, dtype=float)
        vel = np.asarray(targets_vel, dtype=float)
        k = self.n_springs
        if pos.ndim != 3 or pos.shape[1:] != (k, 3) or pos.shape[0] < 2:
            raise ValueError(f"run: targets_pos must have shape (n >= 2, {k}, 3), got {pos.shape}")
        if vel.shape != pos.shape:
            raise ValueError(f"run: targets_vel must have shape {pos.shape}, got {vel.shape}")
        n = pos.shape[0]
        act = np.ones((n, k), dtype=bool) if active is None else np.asarray(active, dtype=bool)
        if act.shape != (n, k):
            raise ValueError(f"run: active must have shape ({n}, {k}), got {act.shape}")
        finite = np.isfinite(pos).all(axis=2) & np.isfinite(vel).all(axis=2)
        if np.any(act & ~finite):
            f, j = np.argwhere(act & ~finite)[0]
            raise ValueError(f"run: marker {j} is active but not finite at frame {f}; mark missing samples inactive")
        if not frame_dt_s > 0:
            raise ValueError(f"run: frame_dt_s must be > 0, got {frame_dt_s}")
        step = frame_dt_s if options.step_s is None else float(options.step_s)
        if not step > 0:
            raise ValueError(f"run: step_s must be > 0, got {step}")
        if step < frame_dt_s * (1 - 1e-9):  # sub-steps: a whole number per frame
            sub = int(round(frame_dt_s / step))
            if abs(sub * step - frame_dt_s) > 1e-9 * frame_dt_s:
                raise ValueError(f"run: frame_dt_s / step_s must be a positive integer when step_s < frame_dt_s, "
                                 f"got {frame_dt_s} / {step}")
            per_frame, n_steps = 1.0 / sub, (n - 1) * sub
        else:  # a whole number of frames per step; a last step over the remaining frames
            per = int(round(step / frame_dt_s))
            if abs(per * frame_dt_s - step) > 1e-9 * step:
                raise ValueError(f"run: step_s / frame_dt_s must be a positive integer when step_s > frame_dt_s, "
                                 f"got {step} / {frame_dt_s}")
            per_frame, n_steps = float(per), int(math.ceil((n - 1) / per))
            if (n - 1) % per and not options.adaptive_step:
                raise ValueError(f"run: {n - 1} frame intervals are not a multiple of {per} frames per step "
                                 f"(needs adaptive_step=True for the shorter last step)")
        d_over_c = np.divide(self.springs.damping_ns_per_m, self.springs.stiffness_n_per_m,
                             out=np.zeros(k), where=self.springs.stiffness_n_per_m > 0)[:, None]

        def rows_of(p, v):  # what the springs are set to: native offset r_M + (d/c) v_M, or [r_M, v_M]
            return (p + d_over_c * v).tolist() if self._native else np.concatenate([p, v], axis=-1).tolist()

        def measured(i):  # positions and velocities of frame(s) i, zero where a marker is missing
            a = act[i][..., None]
            return np.where(a, pos[i], 0.0), np.where(a, vel[i], 0.0)

        # the rows of the frames the steps end on (nested lists: fast setters), made a block at a
        # time; other frames on demand
        ends = np.unique(np.r_[np.arange(0, n, max(int(round(per_frame)), 1)), n - 1])
        frame_rows: dict[int, list] = {}

        def frame_row(i):
            row = frame_rows.get(i)
            if row is None:
                e = int(np.searchsorted(ends, i))
                if e == len(ends) or ends[e] != i:  # a reduced step that ends on another frame
                    return rows_of(*measured(i))
                block = ends[e:e + _ROW_BLOCK]
                frame_rows.clear()
                frame_rows.update(zip(block.tolist(), rows_of(*measured(block))))
                row = frame_rows[i]
            return row

        def rows_between(x):  # a step that ends between frames (sub-steps, reduced steps): cubic Hermite
            i = min(max(int(math.floor(x + 1e-9)), 0), n - 2)
            (p0, p1), (v0, v1) = measured(np.array([i, i + 1]))
            p, v = hermite(p0, v0, p1, v1, x - i, frame_dt_s)
            return rows_of(p, v)

        # a step uses a spring only if its marker is present in every frame the step touches
        cmiss = np.vstack([np.zeros((1, k), dtype=np.int32), np.cumsum(~act, axis=0, dtype=np.int32)])
        any_missing = bool(cmiss[-1].any())
        mbs = self._mbs
        springs = self._spring_objects
        native, symbolic_targets, set_parameter = self._native, self._targets, mbs.SetObjectParameter

        def set_targets(row):
            if native:
                for j in range(k):
                    set_parameter(springs[j], "offset", row[j])
            else:
                for j in range(k):
                    symbolic_targets[j].SetVector(row[j])

        state = act[0].copy()
        set_targets(frame_row(0))
        for j in range(k):
            mbs.SetObjectParameter(springs[j], "activeConnector", bool(state[j]))

        sd = mbs.systemData
        record_t: list[float] = []  # times of the recorded states: t = 0, then every accepted step
        chunk = n if on_frames is None else max(int(chunk_frames), 1)
        extra = max(int(first_chunk_extra), 0)
        record = StateRecord(self._n_ode2, capacity=min(n_steps, int(math.ceil((chunk + extra) / per_frame)) + 2) + 16)
        eps = 1e-6 * frame_dt_s
        flushed, accepted, failure = [0], [0], [None]
        parts: list[PFRun] = []  # without on_frames: every frame, joined at the end

        def flush(upto: int) -> None:
            """Frames [flushed, upto) that the recorded steps reach go on; steps no later frame needs
            are dropped."""
            first = flushed[0]
            t_steps = np.asarray(record_t)
            X, Xt, Xtt, done = frames_from_steps(t_steps, record.arrays(), upto - first, frame_dt_s, self._n_ode2,
                                                 first=first)
            if done == 0:
                return
            part = self._decode(X[:done], Xt[:done], Xtt[:done], frame_dt_s, first=first)
            flushed[0] = first + done
            keep_from = max(int(np.searchsorted(t_steps, flushed[0] * frame_dt_s - eps, side="left")) - 1, 0)
            record.drop_first(keep_from)
            del record_t[:keep_from]
            if on_frames is None:
                parts.append(part)
            else:
                on_frames(part)

        limits = self._limits
        check_limits, next_limit_check = self._limit_switching(per_frame * frame_dt_s)

        interrupted = [False]

        def pre_step(mbs, t):  # receives t_{n+1}: the end of the step about to be solved
            if interrupted[0] or failure[0] is not None:  # Ctrl-C, or on_frames failed: stop the solver here
                return False
            if limits:  # the current state is that of the step's start, the last accepted time
                t_start = record_t[-1] if record_t else 0.0
                if t_start >= next_limit_check[0]:
                    check_limits(t_start)
            x = t / frame_dt_s
            i = int(x + 0.5)
            if any_missing:
                start = record_t[-1] if record_t else 0.0  # the step starts at the last accepted time
                lo = min(max(int(math.floor(start / frame_dt_s + 1e-6)), 0), n - 1)
                hi = min(max(int(math.ceil(x - 1e-6)), 0), n - 1)
                now = (cmiss[hi + 1] - cmiss[lo]) == 0
                for j in np.flatnonzero(now != state):
                    mbs.SetObjectParameter(springs[j], "activeConnector", bool(now[j]))
                state[:] = now
            if abs(x - i) < 1e-6:
                row = frame_row(i)
            else:
                row = rows_between(x)
            set_targets(row)
            return True

        reported = [0]
        report_every = max(1, int(round(0.5 / frame_dt_s)))  # progress about every 0.5 s of motion

        def post_step(mbs, t):  # every accepted step, and once at t = 0 after the initial accelerations
            record_t.append(t)
            record.append(sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t(), sd.GetODE2Coordinates_tt())
            if t > 0.0:
                accepted[0] += 1
            upto = min(flushed[0] + chunk + (extra if flushed[0] == 0 else 0), n)
            if upto < n and t >= (upto - 1) * frame_dt_s - eps and failure[0] is None:
                try:
                    flush(upto)
                except BaseException as exc:  # raised from run() once Exudyn has returned
                    failure[0] = exc
            if progress is not None:
                frame = int(t / frame_dt_s + 0.5)
                if frame - reported[0] >= report_every:
                    progress(frame - reported[0])
                    reported[0] = frame
            return True

        mbs.SetPreStepUserFunction(pre_step)
        mbs.SetPostStepUserFunction(post_step)
        settings = self._settings(n_steps, (n - 1) * frame_dt_s, options)
        solver = exu.MainSolverImplicitSecondOrder()
        print_before = exu.config.printToConsole
        exu.config.printToConsole = False  # Exudyn prints progress/warnings itself; we log instead
        message = ""
        t0 = time.perf_counter()
        previous_handler = _catch_sigint(interrupted)
        try:
            success = bool(solver.InitializeSolver(mbs, settings))
            if success:
                # steps of per_frame frames; with adaptive steps the solver shortens the last one to end
                # on the last frame (a uniform endTime / numberOfSteps would miss the frame times)
                solver.it.maxStepSize = solver.it.currentStepSize = per_frame * frame_dt_s
                t_steps = time.perf_counter()
                success = bool(solver.SolveSteps(mbs, settings))
                solver.timer.total = time.perf_counter() - t_steps  # SolveSteps alone does not set it
                solver.FinalizeSolver(mbs, settings)
            if not success:
                message = solver.GetErrorString() or "solver did not finish"
        except Exception as exc:  # Exudyn raises its own error types on divergence
            success = False
            message = f"{type(exc).__name__}: {exc}"
        finally:
            exu.config.printToConsole = print_before
            mbs.SetPreStepUserFunction(0)
            mbs.SetPostStepUserFunction(0)
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)
        if interrupted[0]:
            raise KeyboardInterrupt
        wall = time.perf_counter() - t0

        if failure[0] is not None:
            raise failure[0]
        wall = time.perf_counter() - t0
        flush(n)  # the frames after the last full chunk, up to the last the solver reached
        completed = flushed[0]
        success = success and completed == n
        if not success:
            log.warning("PF integration stopped at frame %d of %d: %s", completed, n, message)

        timer = solver.timer
        times = {name: float(getattr(timer, name)) for name in _TIMER_FIELDS if hasattr(timer, name)} if options.timing_breakdown else {}
        it = solver.it
        t_end = record_t[-1] if record_t else 0.0
        active_s = {e.joint: e.active_s + (t_end - e.on_since if e.active else 0.0) for e in limits}
        frames = _join(parts, n, frame_dt_s, len(self.model.segments)) if on_frames is None else self._decode(
            *(np.zeros((0, self._n_ode2)) for _ in range(3)), frame_dt_s, first=completed)
        return dataclasses.replace(
            frames, completed_frames=int(completed), success=bool(success), message=message, wall_time_s=float(wall),
            solver_times_s=times, newton_iterations=int(it.newtonStepsCount), jacobian_updates=int(it.newtonJacobiCount),
            steps=accepted[0], step_s=float(per_frame * frame_dt_s), limit_active_s=active_s)

    def run_live(self, next_frame: Callable[[int], tuple | None], on_frame: Callable[[int, PFRun], None], /, *,
                 frame_dt_s: float, options: IntegratorOptions = IntegratorOptions(),
                 interrupt: Callable[[], None] | None = None) -> PFRun:
        """Integrate the PF system through marker frames as they come (live, causal): one step per
        frame, frame i at t = i * frame_dt_s, from (q0, qd0) at frame 0.

        next_frame(i): the targets of frame i = 0, 1, 2, ... as (positions (k, 3) m, velocities
            (k, 3) m/s, active (k,) bool), or None to end the run there. It is called once per frame,
            in order, when the step that ends on frame i is about to be solved (so it may block until
            the frame arrives); frame 0 before the start. A spring is used in a step only if its marker
            is active at both frames the step joins (as ``run``).
        on_frame(i, state): the segment motion of frame i (a PFRun of one frame, ``time_s`` = [i dt]) as
            soon as the solver has accepted the step that ends on it; frame 0 once the initial
            accelerations are computed.

        The steps are those of ``run`` with step_s = frame_dt_s (the same pre-step, limit switching
        and solver settings; a step the solver halves gets its targets by cubic Hermite interpolation
        between the two frames it lies between, both already received, and the frames the steps
        then no longer end on are the quintic Hermite interpolation of the two step states around
        them, as ``run`` does), so a run through the same frames gives the same motion as ``run``. An exception raised by either function stops the
        solver and is raised from here. Ctrl-C (SIGINT, main thread) stops the solver at the next step
        and raises KeyboardInterrupt from here; ``interrupt`` is called from the signal handler (e.g.
        to wake a next_frame that waits for data). Returns the run's statistics
        (no frames); ``completed_frames`` = the frames handed to on_frame.
        """
        if not frame_dt_s > 0:
            raise ValueError(f"run_live: frame_dt_s must be > 0, got {frame_dt_s}")
        k = self.n_springs
        d_over_c = np.divide(self.springs.damping_ns_per_m, self.springs.stiffness_n_per_m,
                             out=np.zeros(k), where=self.springs.stiffness_n_per_m > 0)[:, None]
        native, symbolic_targets = self._native, self._targets
        mbs, sd = self._mbs, self._mbs.systemData
        springs, set_parameter = self._spring_objects, mbs.SetObjectParameter
        frames: dict[int, tuple] = {}  # the last frames received: i -> (pos, vel, active)

        def fetch(i):
            got = next_frame(i)
            if got is None:
                return False
            p, v, a = (np.asarray(x) for x in got)
            a = a.astype(bool)
            if p.shape != (k, 3) or v.shape != (k, 3) or a.shape != (k,):
                raise ValueError(f"run_live: frame {i} must be positions ({k}, 3), velocities ({k}, 3), active ({k},); "
                                 f"got {p.shape}, {v.shape}, {a.shape}")
            if np.any(a & ~(np.isfinite(p).all(axis=1) & np.isfinite(v).all(axis=1))):
                raise ValueError(f"run_live: a marker is active but not finite at frame {i}")
            frames[i] = (np.where(a[:, None], p, 0.0), np.where(a[:, None], v, 0.0), a)
            frames.pop(i - 8, None)  # a rejected step may be retried over earlier frames: keep a few
            return True

        def set_targets(p, v):
            row = (p + d_over_c * v).tolist() if native else np.concatenate([p, v], axis=-1).tolist()
            if native:
                for j in range(k):
                    set_parameter(springs[j], "offset", row[j])
            else:
                for j in range(k):
                    symbolic_targets[j].SetVector(row[j])

        failure: list = [None]
        if not fetch(0):
            return self._decode(*(np.zeros((0, self._n_ode2)) for _ in range(3)), frame_dt_s, first=0)
        state = frames[0][2].copy()
        set_targets(frames[0][0], frames[0][1])
        for j in range(k):
            set_parameter(springs[j], "activeConnector", bool(state[j]))
        limits = self._limits
        check_limits, next_limit_check = self._limit_switching(frame_dt_s)
        received, last_t, done, ended = [0], [0.0], [0], [False]
        interrupted = [False]
        accepted = [0]
        eps = 1e-6

        def pre_step(mbs, t):
            if interrupted[0] or failure[0] is not None or ended[0]:
                return False
            try:
                if limits and last_t[0] >= next_limit_check[0]:
                    check_limits(last_t[0])
                x = t / frame_dt_s
                i = int(math.ceil(x - eps))
                while received[0] < i:  # the frame this step ends on (or lies before)
                    if not fetch(received[0] + 1):
                        ended[0] = True
                        return False
                    received[0] += 1
                lo = int(math.floor(last_t[0] / frame_dt_s + eps))
                now = frames[i][2] & frames[max(lo, i - 1)][2] if i - 1 >= lo else frames[i][2]
                for j in np.flatnonzero(now != state):
                    set_parameter(springs[j], "activeConnector", bool(now[j]))
                state[:] = now
                if abs(x - i) < eps:
                    set_targets(frames[i][0], frames[i][1])
                else:  # a reduced step between frames i - 1 and i
                    (p0, v0, _), (p1, v1, _) = frames[i - 1], frames[i]
                    set_targets(*hermite(p0, v0, p1, v1, x - (i - 1), frame_dt_s))
            except BaseException as exc:
                failure[0] = exc
                return False
            return True

        previous: list = [None]  # (t, X, Xt, Xtt) of the last accepted step

        def post_step(mbs, t):
            last_t[0] = t
            if t > 0.0:
                accepted[0] += 1
            if failure[0] is not None or ended[0]:  # (Exudyn may finish a step after a pre-step said stop)
                return True
            cur = (t, np.asarray(sd.GetODE2Coordinates()), np.asarray(sd.GetODE2Coordinates_t()),
                   np.asarray(sd.GetODE2Coordinates_tt()))
            try:  # every frame this step reached: its state, or inside the step (after a reduced step)
                # the quintic Hermite of the two step states, as run's frames_from_steps
                while done[0] <= received[0] and done[0] * frame_dt_s <= t + eps * frame_dt_s:
                    i = done[0]
                    ti = i * frame_dt_s
                    if abs(ti - t) <= eps * frame_dt_s or previous[0] is None:
                        X, Xt, Xtt = cur[1], cur[2], cur[3]
                    else:
                        t0_, X0, V0, A0 = previous[0]
                        h = t - t0_
                        X, Xt, Xtt = quintic(X0, V0, A0, cur[1], cur[2], cur[3], (ti - t0_) / h, h)
                    on_frame(i, self._decode(X[None], Xt[None], Xtt[None], frame_dt_s, first=i))
                    done[0] = i + 1
            except BaseException as exc:
                failure[0] = exc
                return False
            previous[0] = cur
            return True

        mbs.SetPreStepUserFunction(pre_step)
        mbs.SetPostStepUserFunction(post_step)
        horizon = 1e9  # steps: the run ends when next_frame says so
        settings = self._settings(int(horizon), horizon * frame_dt_s, options)
        solver = exu.MainSolverImplicitSecondOrder()
        print_before = exu.config.printToConsole
        exu.config.printToConsole = False
        message = ""
        t0 = time.perf_counter()
        previous_handler = _catch_sigint(interrupted, interrupt)
        try:
            success = bool(solver.InitializeSolver(mbs, settings))
            if success:
                solver.it.maxStepSize = solver.it.currentStepSize = frame_dt_s
                success = bool(solver.SolveSteps(mbs, settings))
                solver.FinalizeSolver(mbs, settings)
            if not success and not ended[0]:
                message = solver.GetErrorString() or "solver did not finish"
        except Exception as exc:
            success = False
            message = f"{type(exc).__name__}: {exc}"
        finally:
            exu.config.printToConsole = print_before
            mbs.SetPreStepUserFunction(0)
            mbs.SetPostStepUserFunction(0)
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)
        if interrupted[0]:
            raise KeyboardInterrupt
        if failure[0] is not None:
            raise failure[0]
        wall = time.perf_counter() - t0
        it = solver.it
        active_s = {e.joint: e.active_s + (last_t[0] - e.on_since if e.active else 0.0) for e in limits}
        empty = self._decode(*(np.zeros((0, self._n_ode2)) for _ in range(3)), frame_dt_s, first=done[0])
        return dataclasses.replace(
            empty, completed_frames=int(done[0]), success=bool(ended[0] and not message), message=message,
            wall_time_s=float(wall), newton_iterations=int(it.newtonStepsCount), jacobian_updates=int(it.newtonJacobiCount),
            steps=accepted[0], step_s=float(frame_dt_s), limit_active_s=active_s)

    def _limit_switching(self, step_s: float):
        """Reset the limit elements for a run of steps of ``step_s`` and return (check_limits(t_start),
        next_limit_check: a one-element list, the earliest time a joint must be looked at again)."""
        # range-of-motion limits: a joint's limit element is on while one of its angles is within
        # `margin` (one step of travel at the largest rate) of a limit or beyond it, judged from the
        # state at the start of each step; a joint d > margin away is looked at again only once it
        # may have come within the margin, i.e. after (d - margin) / rate
        limits = self._limits
        mbs, sd, set_parameter = self._mbs, self._mbs.systemData, self._mbs.SetObjectParameter
        rate = self.limit_max_rate_rad_s
        margin = rate * step_s
        get_output, rotation_output = mbs.GetObjectOutput, exu.OutputVariableType.Rotation
        next_limit_check = [math.inf]

        def check_limits(t_start):
            first = math.inf
            for e in limits:
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
            next_limit_check[0] = first

        for e in limits:
            e.active, e.next_check, e.on_since, e.active_s = False, -math.inf, 0.0, 0.0
            set_parameter(e.obj, "activeConnector", False)
            if e.branches is not None:
                e.branch = 1.0
                set_parameter(e.obj, "offset", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        if limits:  # from the initial state, before the initial accelerations are computed
            sd.SetODE2Coordinates(sd.GetODE2Coordinates(configuration=exu.ConfigurationType.Initial),
                                  configuration=exu.ConfigurationType.Current)
            check_limits(0.0)
        return check_limits, next_limit_check

    def _settings(self, n_steps: int, end_time: float, options: IntegratorOptions):
        s = exu.SimulationSettings()
        ti = s.timeIntegration
        ti.numberOfSteps = n_steps
        ti.endTime = end_time
        ti.verboseMode = 0
        ti.adaptiveStep = options.adaptive_step
        ti.generalizedAlpha.spectralRadius = options.spectral_radius
        ti.generalizedAlpha.useIndex2Constraints = False  # index 3 (index 2 stalls with the quadratic constraint)
        ti.generalizedAlpha.computeInitialAccelerations = True
        ti.newton.useModifiedNewton = options.modified_newton
        ti.newton.modifiedNewtonContractivity = options.modified_newton_contractivity
        ti.newton.relativeTolerance = options.newton_relative_tolerance
        ti.newton.absoluteTolerance = options.newton_absolute_tolerance
        ti.newton.maxIterations = options.max_newton_iterations
        if options.sparse_solver:  # Eigen's SparseLU, symbolic analysis kept while the pattern holds
            s.linearSolver.solverType = exu.LinearSolverType.EigenSparse
            s.linearSolver.reuseAnalyzedPattern = True
        else:
            s.linearSolver.solverType = exu.LinearSolverType.EXUdense
        s.solution.file.write = False
        s.solution.sensors.active = False
        s.show.computationTime = options.timing_breakdown
        s.show.globalTimers = False
        s.show.statistics = False
        return s

    def _decode(self, X, Xt, Xtt, frame_dt_s, *, first: int = 0) -> PFRun:
        """The segment motion of frames first ... first + len(X) - 1 from the system coordinates
        (vectorised over the segments: a live run decodes one frame at a time)."""
        X, Xt, Xtt = (np.asarray(a) for a in (X, Xt, Xtt))
        n = X.shape[0]
        n_seg = len(self.model.segments)
        L = self._ltg_all  # (n_seg - 1, 7): each movable segment's node coordinates
        x, xt, xtt = X[:, L], Xt[:, L], Xtt[:, L]  # (n, n_seg - 1, 7)
        ep = x[..., 3:] + self._ep_ref[1:]
        G = ep_G(ep / np.linalg.norm(ep, axis=-1, keepdims=True))
        R = np.empty((n, n_seg, 3, 3))
        R[:, 0] = np.eye(3)
        R[:, 1:] = ep_rotation(ep)
        p, v, a, w, al = (np.zeros((n, n_seg, 3)) for _ in range(5))
        p[:, 1:] = x[..., :3] + self._p_ref[1:]
        v[:, 1:], a[:, 1:] = xt[..., :3], xtt[..., :3]
        w[:, 1:] = np.einsum("nsij,nsj->nsi", G, xt[..., 3:])
        al[:, 1:] = np.einsum("nsij,nsj->nsi", G, xtt[..., 3:])
        return PFRun(
            time_s=(first + np.arange(n)) * frame_dt_s, rotations=R, origins_m=p, velocities_m_s=v,
            accelerations_m_s2=a, angular_velocities_rad_s=w, angular_accelerations_rad_s2=al, completed_frames=n,
            success=True, message="", wall_time_s=0.0)


def _join(parts: Sequence[PFRun], n: int, frame_dt_s: float, n_seg: int) -> PFRun:
    """One PFRun of n frames from consecutive parts; frames no part reached are NaN."""
    shapes = {"rotations": (n_seg, 3, 3), "origins_m": (n_seg, 3), "velocities_m_s": (n_seg, 3),
              "accelerations_m_s2": (n_seg, 3), "angular_velocities_rad_s": (n_seg, 3),
              "angular_accelerations_rad_s2": (n_seg, 3)}
    done = sum(p.n_frames for p in parts)
    out = {}
    for name, shape in shapes.items():
        arrays = [getattr(p, name) for p in parts] + ([np.full((n - done,) + shape, np.nan)] if done < n else [])
        out[name] = np.concatenate(arrays) if len(arrays) > 1 else arrays[0]
    return PFRun(time_s=np.arange(n) * frame_dt_s, completed_frames=done, success=done == n, message="",
                 wall_time_s=0.0, **out)


def _spring_force(target):
    """The symbolic spring-damper force c (r - r_M) + d (v - v_M); ``target`` = [r_M, v_M].

    A closure without default arguments (Exudyn's symbolic conversion rejects those)."""

    def spring_force(mbs, t, itemNumber, displacement, velocity, stiffness, damping, offset):
        return [stiffness[i] * (displacement[i] - target[i]) + damping[i] * (velocity[i] - target[3 + i]) for i in range(3)]

    return spring_force


# --------------------------------------------------------------------------------------------
# Range-of-motion limits
# --------------------------------------------------------------------------------------------
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


def _catch_sigint(flag: list[bool], also: Callable[[], None] | None = None):
    """During a solve, Ctrl-C sets ``flag`` (the step function then stops the solver, and the run
    raises KeyboardInterrupt once Exudyn has returned) instead of raising inside an Exudyn callback,
    where Exudyn would catch it, print it and go on. Returns the previous handler (None when not
    in the main thread, where handlers cannot be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):  # noqa: ARG001
        flag[0] = True
        if also is not None:
            also()

    return signal.signal(signal.SIGINT, handler)
