"""Shoulder-girdle geometry of the subject-scaled thoracoscapular OpenSim model.

Source model: Seth A, Dong M, Matias R, Delp S (2019) "A biomechanical model of the
scapulothoracic joint to accurately capture scapular kinematics during shoulder movements",
Front Neurorobot 13:90 (CC BY 4.0). The file read here is the subject model of the rmr-solver
repository (ComputationalBiomechanicsLab/rmr-solver @ d40ebd8ba658633993e531e408c0d96df30ff367,
`OpenSim Models/for RMR solver/TSM_subject_noWeight.osim`), kept in
../shared/data/models/rmr_TSM_subject_noWeight.osim (see ../shared/data/SOURCES.md). Only numbers
are taken from it; no text of the file is copied here.

OpenSim is not needed: this is a small forward-kinematics reader (xml.etree + numpy) for the joint
types that file uses. Conventions re-implemented from the OpenSim/Simbody sources (read, not
copied):

* PhysicalOffsetFrame ``orientation`` = body-fixed X-Y-Z angles, R = Rx(a) Ry(b) Rz(c)
  (opensim-core OpenSim/Simulation/Model/OffsetFrame.h, ``setRotationToBodyFixedXYZ``).
* A joint places its child body so that the child-side frame M coincides with the parent-side
  frame F moved by the mobilizer transform X_FM(q):
  X_G,child = X_G,parent * X_parent,F * X_FM(q) * inv(X_child,M).
* CustomJoint / SpatialTransform -> Simbody ``MobilizedBody::FunctionBased``
  (simbody Simbody/src/MobilizedBodyImpl.h, ``FunctionBasedImpl::calcMobilizerTransformFromQ``):
  the six TransformAxis values s_i = f_i(q) give R_FM = R(s0, a0) R(s1, a1) R(s2, a2) (rotations
  about the normalised axes, each about the already rotated frame, i.e. body-fixed) and
  p_FM = s3 a3 + s4 a4 + s5 a5 (normalised axes, in F).
* WeldJoint: X_FM = identity.
* ScapulothoracicJoint (opensim-core OpenSim/Simulation/SimbodyEngine/ScapulothoracicJoint.cpp,
  ``extendAddToSystem``; opensim-core commit 0435b081dc383498e217f92ca63bb97616145c14) builds
  three Simbody mobilizers in series:

  1. ``MobilizedBody::Ellipsoid`` from the thorax to a massless body B1. Its inboard frame E is
     the parent offset frame turned by +pi/2 about its Z axis (R_E = R_F Rz(pi/2), same origin);
     its radii, given in E, are the file's ``thoracic_ellipsoid_radii_x_y_z`` swizzled to
     (ry, rx, rz), so that in the parent offset frame F the ellipsoid has semi-axes (rx, ry, rz)
     along F's X, Y, Z and is centred at F's origin. Its outboard frame on B1 is Rz(pi/2).
     The Ellipsoid mobilizer (simbody Simbody/src/RigidBodyNodeSpec_Ellipsoid.h, ``calcX_FM``;
     simbody commit f312d0dda0a99c24523a5322299e284eb3511778): with OpenSim's Euler-angle mode
     (opensim-core Model.cpp ``setUseEulerAngles(..., true)``) the three coordinates
     (scapula_abduction, scapula_elevation, scapula_upward_rot) are body-fixed X-Y-Z angles,
     R_EM = Rx(q0) Ry(q1) Rz(q2), and the origin of M is p_EM = (a n_x, b n_y, c n_z) with
     n = Z axis of M and (a, b, c) the radii in E. This point is always on the ellipsoid surface;
     note that M's Z axis is the unit vector n, which is the surface normal only for a sphere.
  2. ``MobilizedBody::Pin`` from B1 to a massless body B2 (scapula_winging): rotation by q3 about
     the unit axis d = (-sin w, cos w, 0) through the point (o_x, o_y, 0) of B1, with
     w = ``scapula_winging_axis_direction`` and (o_x, o_y) = ``scapula_winging_axis_origin``.
  3. ``MobilizedBody::Weld`` of the scapula to B2: the child offset frame (scapula_offset) is B2.

  At q = 0 the child offset frame coincides in orientation with the parent offset frame and sits
  at (0, 0, rz) of it.

  Check made while writing this (not part of the tests, the files are not in this project):
  opensim-core's own IK regression data (Applications/IK/tests/resources: subject1_abdbonepin.osim,
  a ScapulothoracicJoint with a non-zero winging axis origin and direction; abdbonepin.trc, bone-pin
  markers; std_subject1_abdbonepin_IK.mot, OpenSim's IK solution with the AC constraint enforced)
  is reproduced by this forward kinematics: 10 markers 1.9 mm RMS over the trial, AC constraint
  gap < 3e-5 mm. Swapping the radii back, or ignoring the winging axis origin, gives 16 mm / 10 mm
  RMS and a 20 mm / 13 mm AC gap.

* The model's default coordinate values, as written in this file, do not satisfy its AC
  PointConstraint (a 19 mm gap). OpenSim assembles a model when it initialises it: ``assemble``
  reproduces that step (closest coordinates that satisfy the constraint), and ``main`` reports
  both the raw and the assembled default posture.

Run ``python models/sources/tsm_geometry.py`` to print the geometry in the ISB thorax frame
(Wu et al. 2005, origin IJ, mm) and write ``models/sources/tsm_landmarks.json``.
"""
from __future__ import annotations

import json
import math
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
SHARED = REPO.parent / "shared"
DEFAULT_OSIM = SHARED / "data" / "models" / "rmr_TSM_subject_noWeight.osim"
DEFAULT_TRC = SHARED / "data" / "trc" / "tsm_rmr_ABD01.trc"
DEFAULT_JSON = HERE / "tsm_landmarks.json"

SOURCE = {
    "citation": "Seth A, Dong M, Matias R, Delp S (2019) A biomechanical model of the scapulothoracic "
                "joint to accurately capture scapular kinematics during shoulder movements. "
                "Front Neurorobot 13:90. doi:10.3389/fnbot.2019.00090 (CC BY 4.0)",
    "file": "rmr_TSM_subject_noWeight.osim = ComputationalBiomechanicsLab/rmr-solver @ "
            "d40ebd8ba658633993e531e408c0d96df30ff367, 'OpenSim Models/for RMR solver/"
            "TSM_subject_noWeight.osim' (see ../shared/data/SOURCES.md)",
    "kinematics": "forward kinematics re-implemented from opensim-core "
                  "(ScapulothoracicJoint.cpp, CustomJoint.cpp, OffsetFrame.h @ 0435b081dc38) and "
                  "simbody (RigidBodyNodeSpec_Ellipsoid.h, MobilizedBodyImpl.h FunctionBased @ f312d0dda0a9)",
}

# Muscle path points on the scapula at the coracoid process (van der Helm DSEM attachment points
# as carried by the osim file): the conjoint-tendon origins at the coracoid apex, and the
# pectoralis minor insertion on the coracoid's medial/superior border.
CORACOID_APEX_POINTS = ("Coracobrachialis2-P1", "BIC_brevis2-P1")
CORACOID_OTHER_POINTS = ("PectoralisMinor3-P2",)


# --------------------------------------------------------------------------- rotations
def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def body_xyz(angles) -> np.ndarray:
    """Body-fixed X-Y-Z rotation (SimTK ``setRotationToBodyFixedXYZ``): Rx(a) Ry(b) Rz(c)."""
    a, b, c = (float(v) for v in angles)
    return rot_x(a) @ rot_y(b) @ rot_z(c)


def rot_axis(axis, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the (normalised) ``axis`` (Rodrigues)."""
    k = np.asarray(axis, float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)


@dataclass(frozen=True)
class Transform:
    """Rigid transform X_AB: a point p_B in frame B is R @ p_B + p in frame A."""
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    p: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __matmul__(self, other: "Transform") -> "Transform":
        return Transform(self.R @ other.R, self.R @ other.p + self.p)

    def inv(self) -> "Transform":
        return Transform(self.R.T, -self.R.T @ self.p)

    def apply(self, pt) -> np.ndarray:
        return self.R @ np.asarray(pt, float) + self.p


# --------------------------------------------------------------------------- model structures
@dataclass
class Coordinate:
    name: str
    default: float
    range: tuple[float, float]


@dataclass
class OffsetFrame:
    name: str
    body: str                      # base body name ("ground" for the ground)
    translation: np.ndarray
    orientation: np.ndarray        # body-fixed XYZ angles (rad)

    @property
    def X(self) -> Transform:      # X_body,frame
        return Transform(body_xyz(self.orientation), self.translation.copy())


@dataclass
class TransformAxisDef:
    name: str
    coordinates: list[str]
    axis: np.ndarray
    function: Callable[[list[float]], float]
    function_text: str


@dataclass
class Joint:
    name: str
    kind: str                      # CustomJoint | WeldJoint | ScapulothoracicJoint
    parent: OffsetFrame
    child: OffsetFrame
    coordinates: list[Coordinate]
    axes: list[TransformAxisDef] = field(default_factory=list)        # CustomJoint
    ellipsoid_radii: np.ndarray | None = None                         # ScapulothoracicJoint
    winging_origin: np.ndarray | None = None
    winging_direction: float = 0.0


@dataclass
class Marker:
    name: str
    body: str
    location: np.ndarray


@dataclass
class PathPoint:
    muscle: str
    name: str
    body: str
    location: np.ndarray


@dataclass
class PointConstraint:
    name: str
    body1: str
    body2: str
    location1: np.ndarray
    location2: np.ndarray


@dataclass
class Body:
    name: str
    mass: float
    mass_center: np.ndarray


@dataclass
class TSM:
    path: Path
    bodies: dict[str, Body]
    joints: list[Joint]            # in the file's order (parents first in this file)
    markers: dict[str, Marker]
    path_points: dict[str, PathPoint]
    constraints: list[PointConstraint]

    @property
    def coordinates(self) -> dict[str, Coordinate]:
        return {c.name: c for j in self.joints for c in j.coordinates}

    def default_coords(self) -> dict[str, float]:
        return {n: c.default for n, c in self.coordinates.items()}

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def scapulothoracic(self) -> Joint:
        return next(j for j in self.joints if j.kind == "ScapulothoracicJoint")


# --------------------------------------------------------------------------- parsing
def _vec(el, tag: str, n: int = 3) -> np.ndarray:
    node = el.find(tag)
    if node is None or node.text is None or not node.text.strip():
        return np.zeros(n)
    v = np.array([float(t) for t in node.text.split()])
    if v.size != n:
        raise ValueError(f"{tag}: expected {n} numbers, got {v.size}")
    return v


def _body_of(path: str) -> str:
    """'/bodyset/thorax' -> 'thorax', '/ground' -> 'ground'."""
    parts = [p for p in path.strip().split("/") if p]
    if parts and parts[0] == "bodyset":
        return parts[1]
    if parts and parts[0] == "ground":
        return "ground"
    return parts[-1]


def _function(el) -> tuple[Callable[[list[float]], float], str]:
    """An OpenSim Function element -> (callable of the coordinate values, description)."""
    tag = el.tag
    if tag == "LinearFunction":
        a, b = (float(t) for t in el.find("coefficients").text.split())
        return (lambda x, a=a, b=b: a * x[0] + b), f"Linear({a:g}, {b:g})"
    if tag == "Constant":
        v = float(el.find("value").text)
        return (lambda x, v=v: v), f"Constant({v:g})"
    if tag == "MultiplierFunction":
        inner_parent = el.find("function")
        inner = list(inner_parent)[0]
        f, txt = _function(inner)
        s = float(el.find("scale").text)
        return (lambda x, f=f, s=s: s * f(x)), f"{s:g}*{txt}"
    # SimmSpline / NaturalCubicSpline / others occur in this file only in MovingPathPoints, not in
    # joints: refuse rather than guess their end conditions.
    raise NotImplementedError(f"OpenSim function {tag} is not implemented by this reader")


def _offset_frames(joint_el) -> dict[str, OffsetFrame]:
    frames = {}
    fr = joint_el.find("frames")
    if fr is None:
        return frames
    for f in fr.findall("PhysicalOffsetFrame"):
        frames[f.get("name")] = OffsetFrame(
            f.get("name"), _body_of(f.find("socket_parent").text),
            _vec(f, "translation"), _vec(f, "orientation"))
    return frames


def _resolve_frame(socket: str, frames: dict[str, OffsetFrame]) -> OffsetFrame:
    socket = socket.strip()
    if socket in frames:
        return frames[socket]
    return OffsetFrame(socket, _body_of(socket), np.zeros(3), np.zeros(3))


def _coordinates(joint_el) -> list[Coordinate]:
    out = []
    cs = joint_el.find("coordinates")
    if cs is None:
        return out
    for c in cs.findall("Coordinate"):
        lo, hi = (float(t) for t in c.find("range").text.split())
        out.append(Coordinate(c.get("name"), float(c.find("default_value").text), (lo, hi)))
    return out


def load_tsm(path: str | Path = DEFAULT_OSIM) -> TSM:
    """Parse bodies, joints, markers, muscle path points and point constraints of the osim file."""
    path = Path(path)
    model = ET.parse(path).getroot().find("Model")
    bodies = {"ground": Body("ground", 0.0, np.zeros(3))}
    for b in model.find("BodySet").find("objects").findall("Body"):
        bodies[b.get("name")] = Body(b.get("name"), float(b.find("mass").text), _vec(b, "mass_center"))

    joints = []
    for j in list(model.find("JointSet").find("objects")):
        kind = j.tag
        if kind not in ("CustomJoint", "WeldJoint", "ScapulothoracicJoint"):
            raise NotImplementedError(f"joint type {kind} ({j.get('name')})")
        frames = _offset_frames(j)
        joint = Joint(j.get("name"), kind,
                      _resolve_frame(j.find("socket_parent_frame").text, frames),
                      _resolve_frame(j.find("socket_child_frame").text, frames),
                      _coordinates(j))
        if kind == "CustomJoint":
            st = j.find("SpatialTransform")
            for ta in st.findall("TransformAxis"):
                cn = ta.find("coordinates")
                names = cn.text.split() if cn is not None and cn.text else []
                fel = [c for c in ta if c.tag not in ("coordinates", "axis")]
                if len(fel) != 1:
                    raise ValueError(f"{joint.name}/{ta.get('name')}: no unique function")
                f, txt = _function(fel[0])
                joint.axes.append(TransformAxisDef(ta.get("name"), names, _vec(ta, "axis"), f, txt))
            if len(joint.axes) != 6:
                raise ValueError(f"{joint.name}: {len(joint.axes)} TransformAxis entries, expected 6")
        elif kind == "ScapulothoracicJoint":
            joint.ellipsoid_radii = _vec(j, "thoracic_ellipsoid_radii_x_y_z")
            joint.winging_origin = _vec(j, "scapula_winging_axis_origin", 2)
            joint.winging_direction = float(j.find("scapula_winging_axis_direction").text)
        joints.append(joint)

    markers = {}
    for m in model.find("MarkerSet").find("objects").findall("Marker"):
        markers[m.get("name")] = Marker(m.get("name"), _body_of(m.find("socket_parent_frame").text),
                                        _vec(m, "location"))

    path_points = {}
    fs = model.find("ForceSet")
    if fs is not None:
        for musc in fs.find("objects"):
            for pp in musc.iter("PathPoint"):          # fixed points only (not MovingPathPoint)
                path_points[pp.get("name")] = PathPoint(
                    musc.get("name"), pp.get("name"), _body_of(pp.find("socket_parent_frame").text),
                    _vec(pp, "location"))

    constraints = []
    cs = model.find("ConstraintSet")
    if cs is not None:
        for c in cs.find("objects").findall("PointConstraint"):
            constraints.append(PointConstraint(
                c.get("name"), _body_of(c.find("socket_body_1").text), _body_of(c.find("socket_body_2").text),
                _vec(c, "location_body_1"), _vec(c, "location_body_2")))
    return TSM(path, bodies, joints, markers, path_points, constraints)


# --------------------------------------------------------------------------- kinematics
def custom_joint_X_FM(joint: Joint, q: dict[str, float]) -> Transform:
    """Simbody FunctionBased mobilizer: body-fixed rotations about axes 0-2, translation in F."""
    s = [ax.function([q[n] for n in ax.coordinates]) for ax in joint.axes]
    R = np.eye(3)
    for i in range(3):
        R = R @ rot_axis(joint.axes[i].axis, s[i])
    p = np.zeros(3)
    for i in range(3, 6):
        a = joint.axes[i].axis
        p = p + s[i] * a / np.linalg.norm(a)
    return Transform(R, p)


def scapulothoracic_X_FM(joint: Joint, q: dict[str, float]) -> Transform:
    """Transform of the child offset frame in the parent offset frame F (see module docstring)."""
    abd, elev, urot, wing = (q[c.name] for c in joint.coordinates)
    rx, ry, rz = joint.ellipsoid_radii
    X_F_E = Transform(rot_z(math.pi / 2), np.zeros(3))              # ellipsoid frame E in F
    R_EM = body_xyz((abd, elev, urot))
    n = R_EM[:, 2]
    X_E_M = Transform(R_EM, np.array([ry, rx, rz]) * n)            # radii swizzled to E
    X_B1_M = Transform(rot_z(math.pi / 2), np.zeros(3))            # M frame on massless body B1
    d = np.array([-math.sin(joint.winging_direction), math.cos(joint.winging_direction), 0.0])
    o = np.array([joint.winging_origin[0], joint.winging_origin[1], 0.0])
    Rw = rot_axis(d, wing)
    X_B1_B2 = Transform(Rw, o - Rw @ o)                            # pin about d through o
    return X_F_E @ X_E_M @ X_B1_M.inv() @ X_B1_B2


def joint_X_FM(joint: Joint, q: dict[str, float]) -> Transform:
    if joint.kind == "CustomJoint":
        return custom_joint_X_FM(joint, q)
    if joint.kind == "WeldJoint":
        return Transform()
    if joint.kind == "ScapulothoracicJoint":
        return scapulothoracic_X_FM(joint, q)
    raise NotImplementedError(joint.kind)


def _coords(tsm: TSM, coords: dict[str, float] | None) -> dict[str, float]:
    q = tsm.default_coords()
    if coords:
        unknown = set(coords) - set(q)
        if unknown:
            raise KeyError(f"unknown coordinates {sorted(unknown)}")
        q.update({k: float(v) for k, v in coords.items()})
    return q


def body_transforms(tsm: TSM, coords: dict[str, float] | None = None) -> dict[str, Transform]:
    """X_ground,body of every body (and of each joint's F and M frames as 'joint:<name>:F|M')."""
    q = _coords(tsm, coords)
    X = {"ground": Transform()}
    pending = list(tsm.joints)
    while pending:
        progressed = False
        for j in list(pending):
            if j.parent.body not in X:
                continue
            X_G_F = X[j.parent.body] @ j.parent.X
            X_G_M = X_G_F @ joint_X_FM(j, q)
            X[j.child.body] = X_G_M @ j.child.X.inv()
            X[f"joint:{j.name}:F"] = X_G_F
            X[f"joint:{j.name}:M"] = X_G_M
            pending.remove(j)
            progressed = True
        if not progressed:
            raise ValueError(f"joints with unreachable parents: {[j.name for j in pending]}")
    return X


def marker_positions(tsm: TSM, coords: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    """Ground positions (m) of every marker, plus joint centres and body origins.

    Extra keys: 'GH_centre' (GlenoHumeral joint, humerus-side frame origin), 'elbow_centre'
    (elbow joint, ulna-side frame origin), 'SC_centre', 'ST_ellipsoid_centre' (scapulothoracic
    parent frame origin = ellipsoid centre), 'ST_contact' (scapulothoracic child frame origin),
    'origin:<body>' for every body, and 'coracoid_est' (see ``coracoid_estimate``)."""
    X = body_transforms(tsm, coords)
    out = {name: X[m.body].apply(m.location) for name, m in tsm.markers.items()}
    out["GH_centre"] = X["joint:GlenoHumeral:M"].p.copy()
    out["elbow_centre"] = X["joint:elbow:M"].p.copy()
    out["SC_centre"] = X["joint:sternoclavicular:M"].p.copy()
    st = tsm.scapulothoracic()
    out["ST_ellipsoid_centre"] = X[f"joint:{st.name}:F"].p.copy()
    out["ST_contact"] = X[f"joint:{st.name}:M"].p.copy()
    for b in tsm.bodies:
        out[f"origin:{b}"] = X[b].p.copy()
    body, loc, _ = coracoid_estimate(tsm)
    out["coracoid_est"] = X[body].apply(loc)
    return out


def constraint_violation(tsm: TSM, coords: dict[str, float] | None = None) -> np.ndarray:
    """Stacked ground-frame gaps (m) point_on_body1 - point_on_body2 of every PointConstraint."""
    X = body_transforms(tsm, coords)
    return np.concatenate([X[c.body1].apply(c.location1) - X[c.body2].apply(c.location2)
                           for c in tsm.constraints]) if tsm.constraints else np.zeros(0)


def assemble(tsm: TSM, coords: dict[str, float] | None = None, tol: float = 1e-12,
             max_iter: int = 50) -> dict[str, float]:
    """Coordinates closest (unit weights, sum of squared differences) to ``coords`` (default: the
    file's defaults) that satisfy the point constraints exactly.

    This is the problem OpenSim solves when it initialises a model (opensim-core Model.cpp
    ``createAssemblySolver``/``assemble``: every independent coordinate tracks its current value
    with weight 1, constraints with infinite weight). Solved here by Gauss-Newton projection with
    a finite-difference Jacobian; not checked against OpenSim itself."""
    q0 = _coords(tsm, coords)
    names = list(q0)
    x0 = np.array([q0[n] for n in names])
    x = x0.copy()

    def c_of(v):
        return constraint_violation(tsm, dict(zip(names, v)))

    for _ in range(max_iter):
        c = c_of(x)
        if c.size == 0:
            break
        h = 1e-7
        J = np.column_stack([(c_of(x + h * e) - c_of(x - h * e)) / (2 * h) for e in np.eye(len(x))])
        # minimise |x_new - x0|^2 subject to c + J (x_new - x) = 0
        d = x - x0
        lam = np.linalg.lstsq(J @ J.T, J @ d - c, rcond=None)[0]
        x_new = x0 + J.T @ lam
        if np.linalg.norm(x_new - x) < 1e-13 and np.linalg.norm(c) < tol:
            x = x_new
            break
        x = x_new
    if tsm.constraints and np.linalg.norm(c_of(x)) > 1e-9:
        raise RuntimeError(f"assembly did not converge: |c| = {np.linalg.norm(c_of(x)):.3g} m")
    return dict(zip(names, (float(v) for v in x)))


def coracoid_estimate(tsm: TSM) -> tuple[str, np.ndarray, str]:
    """(body, location in body, description): mean of the coracobrachialis and biceps short-head
    origins (conjoint tendon, coracoid apex) among the scapula muscle path points."""
    pts = [tsm.path_points[n] for n in CORACOID_APEX_POINTS if n in tsm.path_points]
    if not pts or any(p.body != "scapula" for p in pts):
        raise KeyError("no coracoid-apex muscle points on the scapula in this model")
    loc = np.mean([p.location for p in pts], axis=0)
    return "scapula", loc, ("mean of the muscle path points " + " and ".join(p.name for p in pts)
                            + " (coracobrachialis and biceps short head origins = coracoid apex)")


# --------------------------------------------------------------------------- anatomical frames
def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def isb_thorax_frame(ij, c7, px, t8) -> Transform:
    """Wu et al. 2005 thorax frame, as X_in,thorax (columns X, Y, Z; origin IJ).

    Y = unit(mid(IJ,C7) - mid(PX,T8)); Z = unit normal of the plane IJ, C7, mid(PX,T8), pointing to
    the right (anterior x superior); X = Y x Z (anterior)."""
    ij, c7, px, t8 = (np.asarray(v, float) for v in (ij, c7, px, t8))
    mid_up, mid_lo = (ij + c7) / 2, (px + t8) / 2
    y = _unit(mid_up - mid_lo)
    z = _unit(np.cross(ij - c7, mid_up - mid_lo))   # anterior x superior = right
    x = np.cross(y, z)
    return Transform(np.column_stack([x, y, z]), ij.copy())


def isb_clavicle_frame(sc, ac, thorax_y) -> Transform:
    """Wu et al. 2005: origin SC, Z = unit(AC - SC), X = unit(thorax Y x Z) (anterior), Y = Z x X."""
    z = _unit(np.asarray(ac) - np.asarray(sc))
    x = _unit(np.cross(thorax_y, z))
    return Transform(np.column_stack([x, np.cross(z, x), z]), np.asarray(sc, float).copy())


def isb_scapula_frame(aa, ts, ai) -> Transform:
    """Wu et al. 2005: origin AA, Z = unit(AA - TS), X normal to plane AI-AA-TS (anterior), Y = Z x X."""
    aa, ts, ai = (np.asarray(v, float) for v in (aa, ts, ai))
    z = _unit(aa - ts)
    x = _unit(np.cross(ai - aa, ts - aa))           # for a right scapula points anterior
    return Transform(np.column_stack([x, np.cross(z, x), z]), aa.copy())


def isb_humerus_frame(gh, el, em) -> Transform:
    """Wu et al. 2005 option 1: origin GH, Y = unit(GH - mid(EL,EM)), X normal to plane EL-EM-GH
    (anterior for a right arm), Z = X x Y (right)."""
    gh, el, em = (np.asarray(v, float) for v in (gh, el, em))
    y = _unit(gh - (el + em) / 2)
    x = _unit(np.cross(y, el - em))
    return Transform(np.column_stack([x, y, np.cross(x, y)]), gh.copy())


def thorax_frame_of(points: dict[str, np.ndarray]) -> Transform:
    return isb_thorax_frame(points["ij"], points["c7"], points["px"], points["t8"])


def in_frame(X: Transform, pts: dict[str, np.ndarray], scale: float = 1000.0) -> dict[str, np.ndarray]:
    Xi = X.inv()
    return {k: scale * Xi.apply(v) for k, v in pts.items()}


# --------------------------------------------------------------------------- TRC and fitting
def read_trc(path: str | Path) -> tuple[list[str], np.ndarray, str]:
    """(labels, positions (frames, markers, 3) in file units, units) of a tab-separated TRC."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    units = lines[2].split("\t")[lines[1].split("\t").index("Units")].strip()
    labels = [t.strip() for t in lines[3].split("\t")[2:] if t.strip()]
    rows = []
    for line in lines[5:]:
        cells = line.split("\t")
        if len(cells) < 2 + 3 * len(labels) or not cells[0].strip():
            continue
        rows.append([float(c) if c.strip() else np.nan for c in cells[2:2 + 3 * len(labels)]])
    return labels, np.array(rows).reshape(len(rows), len(labels), 3), units


def kabsch(src: np.ndarray, dst: np.ndarray) -> tuple[Transform, float]:
    """Rigid transform T (no scaling) minimising |T(src) - dst|; returns (T, RMS)."""
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    cs, cd = src.mean(0), dst.mean(0)
    H = (src - cs).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = Transform(R, cd - R @ cs)
    res = np.array([T.apply(s) for s in src]) - dst
    return T, float(np.sqrt((res ** 2).sum(1).mean()))


def fit_markers(tsm: TSM, targets: dict[str, np.ndarray], coords: dict[str, float] | None = None,
                free: list[str] | None = None, constraint_weight: float = 100.0,
                max_iter: int = 100) -> tuple[dict[str, float], float]:
    """Unweighted marker inverse kinematics (targets in m, ground frame): Levenberg-Marquardt on the
    ``free`` coordinates (default: every coordinate a target marker depends on), the AC point
    constraint added as a residual with ``constraint_weight``. Returns (coordinates, marker RMS m)."""
    q = _coords(tsm, coords)
    names = [n for n in targets if n in tsm.markers]
    if free is None:
        free = [n for n in q if n not in ("elbow_flexion", "pro_sup")]

    def res(x):
        qq = dict(q)
        qq.update(zip(free, x))
        X = body_transforms(tsm, qq)
        r = [X[tsm.markers[n].body].apply(tsm.markers[n].location) - targets[n] for n in names]
        for c in tsm.constraints:
            r.append(constraint_weight * (X[c.body1].apply(c.location1) - X[c.body2].apply(c.location2)))
        return np.concatenate(r)

    x = np.array([q[n] for n in free])
    r = res(x)
    lam = 1e-3
    for _ in range(max_iter):
        h = 1e-7
        J = np.column_stack([(res(x + h * e) - res(x - h * e)) / (2 * h) for e in np.eye(len(x))])
        A, g = J.T @ J, J.T @ r
        improved = False
        for _ in range(20):
            dx = -np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), g)
            r_new = res(x + dx)
            if r_new @ r_new < r @ r:
                x, r, lam, improved = x + dx, r_new, lam / 3, True
                break
            lam *= 4
        if not improved or np.linalg.norm(dx) < 1e-10:
            break
    q.update(zip(free, (float(v) for v in x)))
    m = r[:3 * len(names)].reshape(-1, 3)
    return q, float(np.sqrt((m ** 2).sum(1).mean()))


THORAX_TRC_MARKERS = ("ij", "centijc7", "centpxt8")


def thorax_fit_to_trc(tsm: TSM, trc_path: str | Path = DEFAULT_TRC, frame: int = 0):
    """Rigid fit (mm) of the model's thorax markers (default coordinates) onto a TRC frame."""
    labels, pos, units = read_trc(trc_path)
    if units != "mm":
        raise ValueError(f"{trc_path}: units {units}, expected mm")
    pts = {k: 1000.0 * v for k, v in marker_positions(tsm).items()}
    src = np.array([pts[n] for n in THORAX_TRC_MARKERS])
    dst = np.array([pos[frame, labels.index(n)] for n in THORAX_TRC_MARKERS])
    T, rms = kabsch(src, dst)
    return T, rms, pts


# --------------------------------------------------------------------------- report
HANGING = {"plane_elv": 0.0, "shoulder_elv": 0.0, "axial_rot": 0.0}
THORAX_MARKERS = ("ij", "c7", "t8", "px", "centijc7", "centpxt8")
CLAVICLE_MARKERS = ("sc", "acc", "ijc", "ClavicleMassCenter")
SCAPULA_MARKERS = ("ac", "aa", "ts", "ai", "Glenoid_Center", "Glenoid_Edge", "ScapulaThoracicContactPt",
                   "ScapulaMassCenter")
HUMERUS_MARKERS = ("HumHead_Center", "gu", "EpL", "EpM", "centelbow", "HumerusMassCenter")
EXTRA_POINTS = ("SC_centre", "AC_joint_clavicle", "AC_joint_scapula", "ST_ellipsoid_centre", "ST_contact",
                "coracoid_est", "GH_centre", "elbow_centre")
SCAPULA_REPORT = ("ac", "aa", "ts", "ai", "coracoid_est", "Glenoid_Center", "GH_centre")


def posture_points(tsm: TSM, coords: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    """marker_positions plus the two AC-constraint points, in metres, ground frame."""
    pts = marker_positions(tsm, coords)
    X = body_transforms(tsm, coords)
    for c in tsm.constraints:
        if {c.body1, c.body2} == {"clavicle", "scapula"}:
            for body, loc in ((c.body1, c.location1), (c.body2, c.location2)):
                pts[f"AC_joint_{body}"] = X[body].apply(loc)
    return pts


def _lengths(d_mm: dict[str, np.ndarray]) -> dict[str, float]:
    gh, el = d_mm["GH_centre"], d_mm["elbow_centre"]
    mid_ep = (d_mm["EpL"] + d_mm["EpM"]) / 2
    out = {
        "clavicle_SC_to_ac_marker_mm": np.linalg.norm(d_mm["ac"] - d_mm["sc"]),
        "clavicle_SC_to_acc_marker_mm": np.linalg.norm(d_mm["acc"] - d_mm["sc"]),
        "clavicle_SC_to_AC_joint_point_mm": np.linalg.norm(d_mm["AC_joint_clavicle"] - d_mm["sc"]),
        "GH_below_ac_marker_mm": d_mm["ac"][1] - gh[1],
        "GH_below_AC_joint_point_mm": d_mm["AC_joint_clavicle"][1] - gh[1],
        "GH_to_ac_marker_distance_mm": np.linalg.norm(d_mm["ac"] - gh),
        "humerus_GH_to_elbow_centre_mm": np.linalg.norm(el - gh),
        "humerus_GH_to_mid_EpL_EpM_mm": np.linalg.norm(mid_ep - gh),
        "humerus_GH_to_centelbow_mm": np.linalg.norm(d_mm["centelbow"] - gh),
        "epicondyle_width_EpL_EpM_mm": np.linalg.norm(d_mm["EpL"] - d_mm["EpM"]),
        "AC_constraint_gap_mm": np.linalg.norm(d_mm["AC_joint_clavicle"] - d_mm["AC_joint_scapula"]),
    }
    return {k: float(v) for k, v in out.items()}


def geometry(tsm: TSM) -> dict:
    """Every number that main() prints, as a JSON-ready dict (mm, ISB thorax frame at IJ)."""
    q_def = tsm.default_coords()
    q_asm = assemble(tsm)
    postures = {
        "default": q_def,
        "default_assembled": q_asm,
        "hanging": {**q_def, **HANGING},
        "hanging_assembled": {**q_asm, **HANGING},
    }
    g = {k: posture_points(tsm, q) for k, q in postures.items()}
    Xt = thorax_frame_of(g["default"])     # thorax markers do not depend on the shoulder coordinates
    mm = {k: in_frame(Xt, v) for k, v in g.items()}
    names = list(THORAX_MARKERS + CLAVICLE_MARKERS + SCAPULA_MARKERS + HUMERUS_MARKERS + EXTRA_POINTS)
    names += [n for n in tsm.markers if n not in names]

    Xb = body_transforms(tsm)
    st = tsm.scapulothoracic()
    R_ell = Xt.R.T @ Xb[f"joint:{st.name}:F"].R            # ellipsoid axes in the ISB thorax frame

    # Landmarks in each segment's own frames (assembled default posture; only the clavicle's ISB
    # frame and the scapula marker 'ac' seen from the clavicle depend on the posture).
    ga, Xa = g["default_assembled"], body_transforms(tsm, q_asm)
    groups = {"thorax": THORAX_MARKERS,
              "clavicle": CLAVICLE_MARKERS + ("AC_joint_clavicle", "ac"),
              "scapula": SCAPULA_MARKERS + ("AC_joint_scapula", "coracoid_est", "GH_centre"),
              "humerus": HUMERUS_MARKERS + ("GH_centre", "elbow_centre")}
    isb = {"thorax": Xt,
           "clavicle": isb_clavicle_frame(ga["sc"], ga["AC_joint_clavicle"], Xt.R[:, 1]),
           "scapula": isb_scapula_frame(ga["aa"], ga["ts"], ga["ai"]),
           "humerus": isb_humerus_frame(ga["GH_centre"], ga["EpL"], ga["EpM"])}
    seg = {}
    for body, pts in groups.items():
        sel = {n: ga[n] for n in pts}
        seg[body] = {"opensim_body_frame": {k: v.tolist() for k, v in in_frame(Xa[body], sel).items()},
                     "isb_frame": {k: v.tolist() for k, v in in_frame(isb[body], sel).items()}}
    seg["clavicle"]["isb_frame_note"] = "origin SC, Z towards the clavicle-side AC joint point"
    seg["humerus"]["isb_frame_note"] = "option 1: origin GH centre, Y from mid(EpL,EpM) to GH"

    trc = None
    if DEFAULT_TRC.is_file():
        T, rms, pts_g = thorax_fit_to_trc(tsm)
        labels, pos, _ = read_trc(DEFAULT_TRC)
        trc = {"file": "tsm_rmr_ABD01.trc (first frame)", "thorax_fit_markers": list(THORAX_TRC_MARKERS),
               "thorax_fit_rms_mm": rms,
               "GH_centre_in_trc_mm": T.apply(pts_g["GH_centre"]).tolist(),
               "elbow_centre_in_trc_mm": T.apply(pts_g["elbow_centre"]).tolist(),
               "humerus_GH_to_elbow_centre_mm": _lengths(mm["default"])["humerus_GH_to_elbow_centre_mm"],
               "humerus_GH_to_mid_EpL_EpM_mm": _lengths(mm["default"])["humerus_GH_to_mid_EpL_EpM_mm"],
               "model_default_minus_trc_first_frame_mm": {
                   n: float(np.linalg.norm(T.apply(pts_g[n]) - pos[0, labels.index(n)])) for n in labels}}
        # Marker IK of the same frame (targets brought into the model's ground by the thorax fit).
        Ti = T.inv()
        targets = {n: Ti.apply(pos[0, labels.index(n)]) / 1000.0 for n in labels}
        q_ik, rms_ik = fit_markers(tsm, targets)
        p_ik = {k: T.apply(1000.0 * v) for k, v in posture_points(tsm, q_ik).items()}
        trc["ik_first_frame"] = {
            "note": "unweighted marker IK of all 9 TRC markers, AC constraint as a residual (weight 100); "
                    "elbow_flexion and pro_sup fixed (unobservable)",
            "marker_rms_mm": 1000.0 * rms_ik,
            "marker_error_mm": {n: float(np.linalg.norm(p_ik[n] - pos[0, labels.index(n)])) for n in labels},
            "AC_constraint_gap_mm": float(np.linalg.norm(p_ik["AC_joint_clavicle"] - p_ik["AC_joint_scapula"])),
            "GH_centre_in_trc_mm": p_ik["GH_centre"].tolist(),
            "elbow_centre_in_trc_mm": p_ik["elbow_centre"].tolist(),
            "coordinates_rad": {k: v for k, v in q_ik.items() if not k.startswith("ground_thorax")},
        }

    body, loc, desc = coracoid_estimate(tsm)
    return {
        "source": SOURCE,
        "frame": "ISB thorax frame (Wu et al. 2005): origin IJ, X anterior, Y superior, Z right; mm",
        "postures": {
            "default": "the coordinate default values of the osim file, as written (they violate the "
                       "model's AC PointConstraint)",
            "default_assembled": "closest coordinates (unit weights) to the defaults that satisfy the AC "
                                 "PointConstraint, as OpenSim assembles a model on initialisation",
            "hanging": "default, but plane_elv = shoulder_elv = axial_rot = 0 (girdle coordinates unchanged)",
            "hanging_assembled": "default_assembled, but plane_elv = shoulder_elv = axial_rot = 0",
        },
        "coordinates_rad": {k: postures[k] for k in ("default", "default_assembled")},
        "landmarks_mm": {
            "default": {n: mm["default"][n].tolist() for n in names},
            "default_assembled": {n: mm["default_assembled"][n].tolist() for n in names},
            "hanging": {n: mm["hanging"][n].tolist() for n in SCAPULA_REPORT + HUMERUS_MARKERS + ("elbow_centre",)},
            "hanging_assembled": {n: mm["hanging_assembled"][n].tolist()
                                  for n in SCAPULA_REPORT + HUMERUS_MARKERS + ("elbow_centre",)},
        },
        "scapulothoracic_ellipsoid": {
            "centre_mm": mm["default"]["ST_ellipsoid_centre"].tolist(),
            "radii_mm_along_axes_1_2_3": (1000 * st.ellipsoid_radii).tolist(),
            "axes_in_thorax_frame_columns": R_ell.tolist(),
            "in_opensim_thorax_body_frame": {"centre_mm": (1000 * st.parent.translation).tolist(),
                                             "orientation_body_xyz_rad": st.parent.orientation.tolist()},
            "winging_axis_origin_m": st.winging_origin.tolist(),
            "winging_axis_direction_rad": st.winging_direction,
        },
        "lengths": {"default": _lengths(mm["default"]), "default_assembled": _lengths(mm["default_assembled"])},
        "coracoid_estimate": {"what": desc, "in_scapula_body_frame_mm": (1000 * loc).tolist(),
                              "other_coracoid_points_in_scapula_body_frame_mm": {
                                  n: (1000 * tsm.path_points[n].location).tolist()
                                  for n in CORACOID_APEX_POINTS + CORACOID_OTHER_POINTS if n in tsm.path_points}},
        "segment_frames_default_assembled": seg,
        "trc_thorax_fit": trc,
    }


def _fmt(v) -> str:
    return " ".join(f"{x:7.1f}" for x in v)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else DEFAULT_OSIM
    if not path.is_file():
        print(f"model file {path} not found", file=sys.stderr)
        return 1
    tsm = load_tsm(path)
    G = geometry(tsm)
    print(f"Source: {SOURCE['citation']}\nFile: {SOURCE['file']}\n{G['frame']}\n")
    qd, qa = G["coordinates_rad"]["default"], G["coordinates_rad"]["default_assembled"]
    print(f"Coordinates (rad)        {'file default':>12s} {'assembled':>10s}")
    for k in qd:
        print(f"  {k:22s} {qd[k]: 12.5f} {qa[k]: 10.5f}")
    L = G["landmarks_mm"]
    print(f"\nLandmarks (mm)              {'default (file values)':^23s} | {'default, AC-assembled':^23s}")
    print(f"  {'':26s} {'X':>7s} {'Y':>7s} {'Z':>7s} | {'X':>7s} {'Y':>7s} {'Z':>7s}")
    for n in L["default"]:
        print(f"  {n:26s} {_fmt(L['default'][n])} | {_fmt(L['default_assembled'][n])}")
    print("\nHumerus hanging (plane_elv = shoulder_elv = axial_rot = 0), girdle coordinates as in each column:")
    print(f"  {'':26s} {'hanging, file girdle':^23s} | {'hanging, assembled girdle':^23s}")
    for n in L["hanging"]:
        print(f"  {n:26s} {_fmt(L['hanging'][n])} | {_fmt(L['hanging_assembled'][n])}")
    e = G["scapulothoracic_ellipsoid"]
    print("\nScapulothoracic ellipsoid (ScapulothoracicJoint):")
    print(f"  centre (mm)                {_fmt(e['centre_mm'])}")
    print(f"  radii (mm)                 {_fmt(e['radii_mm_along_axes_1_2_3'])}")
    R = np.array(e["axes_in_thorax_frame_columns"])
    for i in range(3):
        print(f"  axis {i + 1} in thorax frame     {' '.join(f'{x:7.4f}' for x in R[:, i])}")
    b = e["in_opensim_thorax_body_frame"]
    print(f"  in the OpenSim thorax body frame: centre {_fmt(b['centre_mm'])} mm, "
          f"orientation (body XYZ, rad) {b['orientation_body_xyz_rad']}")
    print(f"  winging axis origin {e['winging_axis_origin_m']} m, direction {e['winging_axis_direction_rad']} rad")
    print(f"\nLengths (mm)                               {'default':>8s} {'assembled':>10s}")
    for k, v in G["lengths"]["default"].items():
        print(f"  {k:40s} {v:8.1f} {G['lengths']['default_assembled'][k]:10.1f}")
    c = G["coracoid_estimate"]
    print(f"\nCoracoid estimate: {c['what']}; in the scapula body frame {_fmt(c['in_scapula_body_frame_mm'])} mm")
    for n, v in c["other_coracoid_points_in_scapula_body_frame_mm"].items():
        print(f"  {n:26s} {_fmt(v)}")
    for body, fr in G["segment_frames_default_assembled"].items():
        for kind in ("opensim_body_frame", "isb_frame"):
            note = fr.get(f"{kind}_note", "")
            print(f"\n{body} points in its {kind.replace('_', ' ')} (mm){'; ' + note if note else ''}:")
            for n, v in fr[kind].items():
                print(f"  {n:26s} {_fmt(v)}")
    t = G["trc_thorax_fit"]
    if t:
        print(f"\nRigid fit of the model thorax markers {t['thorax_fit_markers']} onto {t['file']}: "
              f"RMS {t['thorax_fit_rms_mm']:.2f} mm")
        print(f"  GH centre in the TRC frame (mm)     {_fmt(t['GH_centre_in_trc_mm'])}")
        print(f"  elbow centre in the TRC frame (mm)  {_fmt(t['elbow_centre_in_trc_mm'])}")
        print(f"  humerus length GH-elbow centre {t['humerus_GH_to_elbow_centre_mm']:.1f} mm, "
              f"GH-mid(EpL,EpM) {t['humerus_GH_to_mid_EpL_EpM_mm']:.1f} mm")
        print("  model markers (file defaults) minus TRC first frame, after that fit (mm): "
              + ", ".join(f"{k} {v:.1f}" for k, v in t["model_default_minus_trc_first_frame_mm"].items()))
        ik = t["ik_first_frame"]
        print(f"  marker IK of that frame ({ik['note']}): RMS {ik['marker_rms_mm']:.1f} mm; "
              + ", ".join(f"{k} {v:.1f}" for k, v in ik["marker_error_mm"].items())
              + f"; AC gap {ik['AC_constraint_gap_mm']:.3f} mm")
        print(f"    GH centre in the TRC frame (mm)   {_fmt(ik['GH_centre_in_trc_mm'])}")
        print(f"    elbow centre in the TRC frame (mm){_fmt(ik['elbow_centre_in_trc_mm'])}")
        print("    coordinates (deg): " + ", ".join(f"{k} {math.degrees(v):.1f}"
                                                    for k, v in ik["coordinates_rad"].items()))

    DEFAULT_JSON.write_text(json.dumps(_round(G), indent=1) + "\n", encoding="utf-8")
    print(f"\nwrote {DEFAULT_JSON}")
    return 0


def _round(o, nd: int = 6):
    if isinstance(o, float):
        return round(o, nd)
    if isinstance(o, dict):
        return {k: _round(v, nd) for k, v in o.items()}
    if isinstance(o, list):
        return [_round(v, nd) for v in o]
    return o


if __name__ == "__main__":
    raise SystemExit(main())
