"""The Exudyn multibody system of the potential-field method, built from a Model (bodies, joints,
the ellipsoid, the marker springs): ``PFSystem``.

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
(``activeConnector``) for the steps that touch the gap.

The backend's modules, one job each (only they import exudyn, with exubio.backend.pf_numerics as
their pure-numpy side): this one builds the system; exubio.backend.exudyn_limits adds the
range-of-motion limit elements and switches them during a run; exubio.backend.exudyn_integrate
integrates the system through a trial's targets (``PFSystem.run``), exubio.backend.exudyn_live
through frames as they come (``PFSystem.run_live``);
exubio.backend.pf_types holds the data that goes in and out (SpringSet, IntegratorOptions, PFRun).

Outside backend/ nothing knows about Exudyn: inputs and outputs are numpy arrays (SI units, time
first) and the frozen dataclasses of exubio.backend.pf_types. Segment indices are those of
``Model.segments`` (0 = thorax, fixed).
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

import exudyn as exu
import exudyn.itemInterface as eii
from exudyn.advancedUtilities import CreateSymbolicUserFunction
from exudyn.rigidBodyUtilities import RotationMatrix2EulerParameters

from exubio.backend.exudyn_integrate import BuiltSystem, SpringTargets, integrate_trial
from exubio.backend.exudyn_live import integrate_live
from exubio.backend.exudyn_limits import DEFAULT_LIMIT_MAX_RATE_RAD_S, add_limit_elements
from exubio.backend.pf_numerics import LimitElement, ep_G, frame_with_z
from exubio.backend.pf_types import FrameMotion, IntegratorOptions, PFRun, SpringSet
from exubio.errors import ModelError
from exubio.model.kinematics import axis_rotation, PointSet
from exubio.protocol.bind import Binding
from exubio.model.ranges import DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD  # k_lim, shared with LS
from exubio.types import JointKind

__all__ = ["DEFAULT_LIMIT_MAX_RATE_RAD_S", "DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD", "GRAVITY_M_S2", "IntegratorOptions", "PFRun",
           "PFSystem", "SpringSet"]

GRAVITY_M_S2 = np.array([0.0, -9.81, 0.0])  # thorax frame: Y up
_SYMBOLIC_SPRINGS = False  # benchmarks only: force the symbolic spring force (the former design)
_AUX_MASS_KG = 1e-3  # mass of each auxiliary ellipsoid point (numerically needed, physically negligible)


# --------------------------------------------------------------------------------------------
# The system
# --------------------------------------------------------------------------------------------
class PFSystem:
    """An Exudyn system of a Model with one spring-damper per model point of ``springs``.

    The reference configuration of every body is the posture q0 (so a run starts exactly there,
    with velocities from qd0); every ``run`` starts again from (q0, qd0).

    limits_rad: (m, 2) range [lower, upper] of every coordinate (rad, +-inf = no limit on that
        side), or None: no limits. Held coordinates and the joints of locked segments get none.
        See exubio.backend.exudyn_limits for the elements.
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
        for (see exubio.backend.exudyn_limits); faster joints may cross a limit for one step
        before their element switches on.
    """

    def __init__(self, binding: Binding, /, *, q0: np.ndarray, qd0: np.ndarray | None = None,
                 springs: SpringSet | None = None, gravity: bool = False, limits_rad: np.ndarray | None = None,
                 limit_stiffness_nm_per_rad: float = DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD,
                 limit_max_rate_rad_s: float = DEFAULT_LIMIT_MAX_RATE_RAD_S, inertia_scale: float = 1.0):
        """``binding``: the model, its kinematics, the coordinates the protocol holds and the segments
        no marker observes (locked) (exubio.protocol.bind.Binding); ``springs``: default one on the
        tracked point of every protocol marker with its stiffness and damping."""
        model = binding.model
        self.model = model
        self.locked_segments = frozenset(int(i) for i in binding.unobserved)
        self.held_coordinates = frozenset(int(i) for i in np.flatnonzero(binding.held))
        self.kin = binding.kin
        if springs is None:
            markers = binding.protocol.markers
            springs = SpringSet.from_points(binding.points,
                                            stiffness_n_per_m=np.array([m.stiffness_n_per_m for m in markers]),
                                            damping_ns_per_m=np.array([m.damping_ns_per_m for m in markers]))
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
            mass = float(seg.mass_kg) * inertia_scale  # the springs accelerate this (PFOptions.inertia_scale)
            com = np.asarray(seg.com_m, dtype=float)
            inertia = (np.asarray(seg.inertia_kgm2, dtype=float) * inertia_scale
                       + mass * (com @ com * np.eye(3) - np.outer(com, com)))
            body = mbs.AddObject(eii.ObjectRigidBody(
                nodeNumber=node, mass=mass, centerOfMass=list(com),
                inertia=[inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[1, 2], inertia[0, 2], inertia[0, 1]],
                visualization=eii.VObjectRigidBody(show=False)))
            if gravity:  # the segment's real weight, whatever inertia the dynamics are given
                mk = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=body, localPosition=list(com)))
                mbs.AddLoad(eii.LoadForceVector(markerNumber=mk,
                                                loadVector=list(float(seg.mass_kg) * np.asarray(GRAVITY_M_S2))))
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
            self._limits = add_limit_elements(mbs, model, self.kin, self._bodies, self.q0, self.locked_segments,
                                              self.held_coordinates, limits_rad, float(limit_stiffness_nm_per_rad))
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
        self._ltg_all = np.array(self._ltg[1:], dtype=np.int64).reshape(len(self._ltg) - 1, -1)
        self._ep_ref_moving, self._p_ref_moving = self._ep_ref[1:].copy(), self._p_ref[1:].copy()
        self._aux_ltg = [np.asarray(sd.GetNodeLTGODE2(n), dtype=int) for n in self._aux_nodes]
        self._n_ode2 = sd.ODE2Size()
        self._eye = np.eye(3)
        self._built = BuiltSystem(mbs, SpringTargets(mbs, self._spring_objects, self._targets, self._native, springs),
                                  self._limits, self.limit_max_rate_rad_s, self._n_ode2, n_seg, self._decode,
                                  self._decode_frame)
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
            first_chunk_extra: int = 0, lead_in: tuple[np.ndarray, np.ndarray] | None = None) -> PFRun:
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
        ``lead_in``: (positions, velocities) of frames before the first of targets_pos, run as if
        concatenated before targets_pos and targets_vel but without that whole-trial copy (``active``
        then covers the lead-in's frames too; ``first_chunk_extra`` is usually their number).
        """
        return integrate_trial(self._built, targets_pos, targets_vel, active, frame_dt_s=frame_dt_s, options=options,
                               progress=progress, on_frames=on_frames, chunk_frames=chunk_frames,
                               first_chunk_extra=first_chunk_extra, lead_in=lead_in)

    def run_live(self, next_frame: Callable[[int], tuple | None], on_frame: Callable[[int, FrameMotion], None], /, *,
                 frame_dt_s: float, options: IntegratorOptions = IntegratorOptions(),
                 interrupt: Callable[[], None] | None = None) -> PFRun:
        """Integrate the PF system through marker frames as they come (live, causal): one step per
        frame, frame i at t = i * frame_dt_s, from (q0, qd0) at frame 0.

        next_frame(i): the targets of frame i = 0, 1, 2, ... as (positions (k, 3) m, velocities
            (k, 3) m/s, active (k,) bool), or None to end the run there. It is called once per frame,
            in order, when the step that ends on frame i is about to be solved (so it may block until
            the frame arrives); frame 0 before the start. A spring is used in a step only if its marker
            is active at both frames the step joins (as ``run``).
        on_frame(i, motion): the segment motion of frame i (a FrameMotion) as soon as the solver has accepted the step that ends on it; frame 0 once the initial
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
        return integrate_live(self._built, next_frame, on_frame, frame_dt_s=frame_dt_s, options=options,
                              interrupt=interrupt)

    def _motion(self, X, Xt, Xtt) -> FrameMotion:
        """The segment motion of system states X, Xt, Xtt (n, N): a FrameMotion whose arrays have a first
        axis of n frames (the five (n, n_seg, 3) arrays views of one block), vectorised over the segments."""
        from exubio.model import kernels  # numba: imported where used

        X, Xt, Xtt = (np.ascontiguousarray(a, dtype=float) for a in (X, Xt, Xtt))
        n, n_seg = X.shape[0], len(self.model.segments)
        R, (p, v, a, w, al) = np.empty((n, n_seg, 3, 3)), np.empty((5, n, n_seg, 3))
        kernels.euler_parameter_motion(X, Xt, Xtt, self._ltg_all, self._ep_ref_moving, self._p_ref_moving,
                                       R, p, v, a, w, al)
        return FrameMotion(R, p, v, a, w, al)

    def _decode_frame(self, X, Xt, Xtt) -> FrameMotion:
        """The segment motion of one system state (X, Xt, Xtt (N,)): a live run's frame."""
        return FrameMotion(*(arr[0] for arr in self._motion(X[None], Xt[None], Xtt[None])))

    def _decode(self, X, Xt, Xtt, frame_dt_s, *, first: int = 0) -> PFRun:
        """The segment motion of frames first ... first + len(X) - 1 from the system coordinates."""
        motion = self._motion(X, Xt, Xtt)
        n = motion.rotations.shape[0]
        return PFRun(time_s=(first + np.arange(n)) * frame_dt_s, **motion._asdict(), completed_frames=n,
                     success=True, message="", wall_time_s=0.0)


def _spring_force(target):
    """The symbolic spring-damper force c (r - r_M) + d (v - v_M); ``target`` = [r_M, v_M].

    A closure without default arguments (Exudyn's symbolic conversion rejects those)."""

    def spring_force(mbs, t, itemNumber, displacement, velocity, stiffness, damping, offset):
        return [stiffness[i] * (displacement[i] - target[i]) + damping[i] * (velocity[i] - target[3 + i]) for i in range(3)]

    return spring_force
