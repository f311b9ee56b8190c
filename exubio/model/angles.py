"""ISB joint angles of the shoulder: Euler/Cardan decompositions, the ISB anatomical frames of the
model's segments, and the sternoclavicular (SC), acromioclavicular (AC), scapulothoracic (ST),
glenohumeral (GH) and humerothoracic (HT) angles of a motion.

Conventions
-----------
* Sequences are **intrinsic** (mobile axes): ``"YXZ"`` (also written ``"Y-X'-Z''"``) means
  R = R_Y(a) R_X(b) R_Z(c), the second rotation about the once-rotated X axis, and so on.
  ``euler_angles`` returns (a, b, c) in radians, each in (-pi, pi].
* Tait-Bryan (Cardan) sequences (three different axes): b in [-pi/2, pi/2]. Proper Euler
  sequences (first axis = last axis, e.g. ``"YXY"``): b in [0, pi] by default, or in [-pi, 0]
  with ``negative_middle=True`` (ISB humerothoracic elevation is negative).
* Gimbal lock (cos b = 0 for Tait-Bryan, sin b = 0 for proper Euler, within ``gimbal_tol``): only
  a +- c is defined; the first angle is set to 0 and the third carries the whole rotation.
* Anatomical frames follow Wu et al. 2005 (J Biomech 38:981-992) for a right arm, from the model's
  landmarks in its reference posture (where every segment frame is parallel to the ISB thorax
  frame X anterior, Y superior, Z right):

  - thorax: the global frame (the model is defined in the ISB thorax frame);
  - clavicle: Z from SC to AC; X perpendicular to Z and to the thorax Y axis, anterior
    (X = Y_thorax x Z); Y = Z x X;
  - scapula: Z from TS to AA; X normal to the plane AI-AA-TS, anterior; Y = Z x X;
  - humerus (Wu option 1): Y from the elbow centre to GH; X normal to the plane EL-EM-GH,
    anterior; Z = X x Y. The elbow centre is the model's elbow joint centre EJC (in the generic
    model the midpoint of EL and EM; on a calibrated model the registered elbow-centre marker),
    else the midpoint of EL and EM; the plane is spanned by GH, the centre and EL (EL - EJC is
    parallel to EL - EM when EJC is their midpoint), so a calibration that registers only EL
    and EJC still gives Wu's frame.

* Joint angles are the decomposition of the relative rotation R_proximal^T R_distal of the
  anatomical frames, **without any sign flip**: SC, AC, ST in Y-X'-Z''; GH in X-Z'-Y'' (Phadke
  et al. 2011, the sequence of the paper and of Ludewig et al. 2009 as distributed by Spartacus);
  HT in Y-X'-Y'' with the middle angle <= 0. For a right arm this gives (verified on the
  simulated abduction and flexion of ``exubio.synth.simulate``, see tests/model/test_angles.py):

  ====  =====================  ===========================  ==============================
  joint first angle            second angle                 third angle
  ====  =====================  ===========================  ==============================
  SC    Y: + protraction,      X': - elevation              Z'': + posterior (backward)
        - retraction                                        axial rotation
  AC    Y: + internal rotation X': - upward rotation        Z'': + posterior tilt
  ST    Y: + internal rotation X': - upward rotation        Z'': + posterior tilt
  GH    X: - elevation         Z': + flexion (forward)      Y'': + internal, - external
        (abduction)                                         axial rotation
  HT    Y: plane of elevation  X': - elevation              Y'': + internal axial rotation
        (0 abduction, 90 deg
        forward flexion)
  ====  =====================  ===========================  ==============================

  These are the signs of Ludewig et al. 2009's published means (retraction, elevation, posterior
  clavicle rotation, scapular upward rotation and posterior tilt during arm elevation come out
  negative, negative, positive, negative, positive). ``humerothoracic_elevation`` is the positive
  angle between the humerus long axis and the thorax Y axis (= -b of HT).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from exubio.model.anatomy import ISB_FRAME_SEGMENTS, isb_frame
from exubio.errors import InputError, ModelError
from exubio.model.frame_definitions import JOINT_SEGMENTS, FrameDefinition, JointDefinition, NotBuildable, build_frame
from exubio.model.kinematics import Kinematics
from exubio.types import Model

__all__ = [
    "ISB_SEQUENCES",
    "ANGLE_NAMES",
    "ISB_COLUMNS",
    "isb_table",
    "definition_frame",
    "joint_angles",
    "measured_isb_joints",
    "anatomical_frames",
    "angles_of_frames",
    "euler_angles",
    "humerothoracic_elevation",
    "isb_angles",
    "rotation_from_euler",
    "segment_anatomical_rotations",
]

ISB_SEQUENCES: dict[str, str] = {"SC": "YXZ", "AC": "YXZ", "ST": "YXZ", "GH": "XZY", "HT": "YXY"}
"""Rotation sequence of every joint angle set (intrinsic)."""

ANGLE_NAMES: dict[str, tuple[str, str, str]] = {
    "SC": ("protraction (+) / retraction (-)", "elevation (-)", "posterior rotation (+)"),
    "AC": ("internal rotation (+)", "upward rotation (-)", "posterior tilt (+)"),
    "ST": ("internal rotation (+)", "upward rotation (-)", "posterior tilt (+)"),
    "GH": ("elevation (-)", "forward flexion (+)", "internal (+) / external (-) rotation"),
    "HT": ("plane of elevation", "elevation (-)", "axial rotation, internal (+)"),
}
"""What each of the three angles means, with its sign (right arm)."""

ISB_COLUMNS: dict[str, tuple[str, str, str]] = {
    "SC": ("SC_Y_protraction", "SC_X_elevation", "SC_Z_posterior_rotation"),
    "AC": ("AC_Y_internal_rotation", "AC_X_upward_rotation", "AC_Z_posterior_tilt"),
    "ST": ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt"),
    "GH": ("GH_X_elevation", "GH_Z_flexion", "GH_Y_internal_rotation"),
    "HT": ("HT_Y_plane_of_elevation", "HT_X_elevation", "HT_Y_axial_rotation"),
}
"""Column names of the ISB angles file: joint, axis (in sequence order: the axes of each joint's
three columns spell its sequence), what the angle is; signs as in ANGLE_NAMES."""

# (proximal frame, distal frame) of every joint angle set; "thorax" is the global frame
_JOINTS = JOINT_SEGMENTS
_JOINT_NAMES = tuple(_JOINTS)
_SEQUENCE_GROUPS: dict[tuple[str, bool], list[int]] = {}
for _j, _name in enumerate(_JOINT_NAMES):  # HT: the middle angle <= 0
    _SEQUENCE_GROUPS.setdefault((ISB_SEQUENCES[_name], _name == "HT"), []).append(_j)

_AXES = {"X": 0, "Y": 1, "Z": 2}


# --------------------------------------------------------------------------------------------
# Euler / Cardan angles
# --------------------------------------------------------------------------------------------
def _parse_sequence(sequence: str) -> tuple[int, int, int]:
    letters = [ch for ch in str(sequence).upper() if ch in "XYZ"]
    rest = [ch for ch in str(sequence).upper() if ch not in "XYZ-' "]
    if len(letters) != 3 or rest or letters[0] == letters[1] or letters[1] == letters[2]:
        raise InputError(
            f"rotation sequence '{sequence}': expected three axes out of X, Y, Z with no axis repeated "
            f"in succession, e.g. 'YXZ', \"Y-X'-Z''\" or 'YXY'"
        )
    return _AXES[letters[0]], _AXES[letters[1]], _AXES[letters[2]]


def _basic_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about coordinate axis ``axis`` (0, 1, 2) by ``angle`` (...)."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (3, 3))
    u, v = (axis + 1) % 3, (axis + 2) % 3
    R[..., axis, axis] = 1.0
    R[..., u, u] = c
    R[..., v, v] = c
    R[..., v, u] = s
    R[..., u, v] = -s
    return R


def _wrap(a: np.ndarray) -> np.ndarray:
    """Angles in (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def rotation_from_euler(angles: np.ndarray, sequence: str, /) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from intrinsic angles (..., 3) in radians:
    R = R_a1(angles[..., 0]) R_a2(angles[..., 1]) R_a3(angles[..., 2])."""
    i, j, k = _parse_sequence(sequence)
    angles = np.asarray(angles, dtype=float)
    if angles.shape[-1:] != (3,):
        raise InputError(f"angles must have shape (..., 3), got {angles.shape}")
    return _basic_rotation(i, angles[..., 0]) @ _basic_rotation(j, angles[..., 1]) @ _basic_rotation(k, angles[..., 2])


def euler_unwrapped(R: np.ndarray, i: int, j: int, k: int, negative_middle: bool, gimbal_tol: float,
                    /) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three angles (a, b, c) of R (..., 3, 3) in the parsed sequence (i, j, k), before wrapping
    (``euler_angles``' rule; exubio.model.frame_angles uses it on one frame's rows)."""
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # parity of the axis order
    if i != k:  # Tait-Bryan
        b = np.arctan2(s * R[..., i, k], np.hypot(R[..., i, i], R[..., i, j]))
        a = np.arctan2(-s * R[..., j, k], R[..., k, k])
        locked = np.cos(b) < gimbal_tol
    else:  # proper Euler
        m = 3 - i - j
        sb = np.hypot(R[..., i, j], R[..., i, m])
        b = np.arctan2(sb, R[..., i, i])
        a = np.arctan2(R[..., j, i], -s * R[..., m, i])
        if negative_middle:
            b, a = -b, a + np.pi
        locked = sb < gimbal_tol
    a = np.where(locked, 0.0, a)
    # third angle from what the first two leave: R_k(c) = R_j(b)^T R_i(a)^T R
    M = np.swapaxes(_basic_rotation(i, a) @ _basic_rotation(j, b), -1, -2) @ R
    u, v = (k + 1) % 3, (k + 2) % 3
    c = np.arctan2(M[..., v, u] - M[..., u, v], M[..., u, u] + M[..., v, v])
    return a, b, c


def euler_angles(R: np.ndarray, sequence: str, /, *, negative_middle: bool = False,
                 gimbal_tol: float = 1e-9) -> np.ndarray:
    """Intrinsic angles (..., 3) in radians of rotation matrices R (..., 3, 3) in ``sequence``
    (see the module docstring for ranges and the gimbal-lock rule).

    negative_middle: proper Euler sequences only: take the branch with the middle angle in
        [-pi, 0] instead of [0, pi] (both describe the same rotation).
    gimbal_tol: |cos b| (Tait-Bryan) or |sin b| (proper Euler) below which the sequence is
        treated as locked: the first angle is then 0.
    """
    i, j, k = _parse_sequence(sequence)
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise InputError(f"rotation matrices must have shape (..., 3, 3), got {R.shape}")
    a, b, c = euler_unwrapped(R, i, j, k, negative_middle, gimbal_tol)
    return np.stack([_wrap(a), _wrap(b), _wrap(c)], axis=-1)


# --------------------------------------------------------------------------------------------
# Anatomical frames
# --------------------------------------------------------------------------------------------
def anatomical_frames(model: Model, /) -> dict[str, np.ndarray]:
    """ISB anatomical frames (Wu et al. 2005, module docstring) of thorax, clavicle, scapula and
    humerus as constant rotations A_s (3, 3) relative to each segment's model frame: the columns
    of A_s are the anatomical X, Y, Z axes in segment coordinates, so the anatomical frame at
    posture q is R_s(q) @ A_s. Built from the landmarks SC, AC (clavicle), AA, TS, AI (scapula),
    GH, EL, EM or EJC (humerus) in the reference posture (``exubio.model.anatomy``)."""
    where = model.source or model.name
    out = {}
    for name in ISB_FRAME_SEGMENTS:
        seg = model.segment(name) if name != "thorax" else None
        points = {} if seg is None else seg.points
        out[name] = isb_frame(name, points, fail=lambda msg, name=name: ModelError(
            f"{where}: cannot build the ISB {name} frame: {msg}"))
    return out


def segment_anatomical_rotations(model: Model, q: np.ndarray, /, *, kinematics: Kinematics | None = None,
                                 frames: Mapping[str, np.ndarray] | None = None,
                                 rotations: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Global orientation (..., 3, 3) of every anatomical frame at coordinates q (..., m);
    ``rotations``: the segment rotations of q (Kinematics.frames(q).R) where the caller has them."""
    kin = kinematics if kinematics is not None else Kinematics(model)
    frames = anatomical_frames(model) if frames is None else frames
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != model.n_coordinates:
        raise InputError(f"q must have {model.n_coordinates} coordinates in its last axis, got shape {q.shape}")
    R = kin.poses(q)[0] if rotations is None else rotations
    return {name: R[..., model.segment_index(name), :, :] @ A for name, A in frames.items()}


def isb_angles(model: Model, q: np.ndarray, /, *, kinematics: Kinematics | None = None,
               unwrap: bool = True, frames: Mapping[str, np.ndarray] | None = None,
               rotations: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """ISB angles (radians) of every frame of q (n, m) or (m,): a dict with "SC", "AC", "ST",
    "GH" (X-Z'-Y'') and "HT" (Y-X'-Y'', middle angle <= 0), each (n, 3) (or (3,)); signs in the
    module docstring. ``unwrap``: remove 2 pi jumps along the frames (for plotting). ``frames``:
    ``anatomical_frames(model)`` computed once by a caller that asks frame by frame (live), and
    ``rotations`` the segment rotations of q where it has them."""
    Rg = segment_anatomical_rotations(model, q, kinematics=kinematics, frames=frames, rotations=rotations)
    Rrel = (np.swapaxes(np.stack([Rg[prox] for prox, _ in _JOINTS.values()], axis=-3), -1, -2)
            @ np.stack([Rg[dist] for _, dist in _JOINTS.values()], axis=-3))  # (..., joints, 3, 3)
    out = {}
    for (sequence, negative), joints in _SEQUENCE_GROUPS.items():  # the joints of one sequence at once
        ang = euler_angles(Rrel[..., joints, :, :], sequence, negative_middle=negative)
        for n, j in enumerate(joints):
            out[_JOINT_NAMES[j]] = ang[..., n, :]
    for joint in _JOINT_NAMES:
        if unwrap and out[joint].ndim == 2 and out[joint].shape[0] > 1:
            out[joint] = np.unwrap(out[joint], axis=0)
    return {joint: out[joint] for joint in _JOINT_NAMES}


def humerothoracic_elevation(model: Model, q: np.ndarray, /, *, kinematics: Kinematics | None = None) -> np.ndarray:
    """Humerothoracic elevation (..., ) in radians, >= 0: the angle between the humerus long axis
    (ISB Y, elbow centre -> GH) and the thorax Y axis; equals minus the HT X' angle."""
    Rg = segment_anatomical_rotations(model, q, kinematics=kinematics)
    cos = np.clip(Rg["humerus"][..., 1, 1], -1.0, 1.0)  # thorax Y . humerus Y
    return np.arccos(cos)


def isb_table(model: Model, q: np.ndarray, /, *, kinematics: Kinematics | None = None,
              frames: Mapping[str, np.ndarray] | None = None,
              rotations: np.ndarray | None = None) -> tuple[tuple[str, ...], np.ndarray]:
    """The ISB angles of q (n, m) as one table: (column names of ISB_COLUMNS, angles (n, 15) rad),
    unwrapped along the frames; computed ISB_BLOCK_FRAMES frames at a time (the segment frames of a
    whole long trial would take ~2 kB per frame); ``rotations``: q's segment rotations, for one
    frame (m,) only."""
    names = tuple(c for joint in _JOINTS for c in ISB_COLUMNS[joint])
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:
        ang = isb_angles(model, q, kinematics=kinematics, frames=frames, rotations=rotations)
        return names, np.concatenate([ang[joint] for joint in _JOINTS], axis=-1)
    kin = kinematics or Kinematics(model)
    table = np.empty((q.shape[0], len(names)))
    for a in range(0, q.shape[0], ISB_BLOCK_FRAMES):
        ang = isb_angles(model, q[a:a + ISB_BLOCK_FRAMES], kinematics=kin, unwrap=False, frames=frames)
        table[a:a + ISB_BLOCK_FRAMES] = np.concatenate([ang[joint] for joint in _JOINTS], axis=-1)
    if q.shape[0] > 1:  # each joint's angles, as isb_angles unwraps them
        table = np.unwrap(table, axis=0)
    return names, table


ISB_BLOCK_FRAMES = 8192


def measured_isb_joints(model: Model, not_solved: set[str] | frozenset[str], /) -> list[str]:
    """The ISB angle sets the markers measure: a segment's orientation is not measured when a
    coordinate of its own joint is not solved (held by the protocol, or a segment no marker
    observes), nor are the segments below a locked one; a set is measured when both its frames are.
    (A held clavicle axial rotation leaves SC and AC unmeasured, while the scapula's free AC joint
    carries its measured orientation: ST, GH and HT stay measured.)"""
    measured = {"thorax": True}
    for seg in model.segments[1:]:
        own = set(seg.joint.coordinates) if seg.joint else set()
        measured[seg.name] = not (own & set(not_solved))
    return [joint for joint, (prox, dist) in _JOINTS.items() if measured.get(prox, False) and measured.get(dist, False)]


# --------------------------------------------------------------------------------------------
# Frames and angles of any study's definition (exubio.model.frame_definitions)
# --------------------------------------------------------------------------------------------
def _reference_landmarks(model: Model, segment: str) -> dict[str, np.ndarray]:
    """Every landmark of the model in the reference posture (q = 0), in global coordinates; a
    name on several segments resolves to ``segment``'s own, else to the first in model order."""
    R, p = Kinematics(model).poses(np.zeros(model.n_coordinates))
    out: dict[str, np.ndarray] = {}
    order = [model.segment(segment)] + [s for s in model.segments if s.name != segment]
    for seg in order:
        i = model.segment_index(seg.name)
        for name, local in seg.points.items():
            out.setdefault(name, p[i] + R[i] @ np.asarray(local, dtype=float))
    return out


def definition_frame(model: Model, defn: FrameDefinition, /) -> np.ndarray:
    """The frame of ``defn`` built on the model's landmarks in the reference posture (fixed to the
    bone from then on, as a digitised static posture is), as a constant rotation A (3, 3) in the
    segment's model frame: columns = the frame's x, y, z. Raises NotBuildable."""
    seg = model.segment(defn.segment) if defn.segment in {s.name for s in model.segments} else None
    if seg is None:
        raise NotBuildable(f"the model has no segment '{defn.segment}'")
    F = build_frame(defn, _reference_landmarks(model, defn.segment))
    R, _ = Kinematics(model).poses(np.zeros(model.n_coordinates))
    return R[model.segment_index(defn.segment)].T @ F


def joint_angles(model: Model, q: np.ndarray, definition: JointDefinition, /, *,
                 kinematics: Kinematics | None = None, unwrap: bool = True) -> np.ndarray:
    """The three angles (radians, (n, 3) or (3,)) of ``definition`` at coordinates q: the
    definition's distal frame relative to its proximal frame, decomposed in its intrinsic
    sequence without any sign change (the raw Euler angles, as Spartacus stores each study's)."""
    kin = kinematics if kinematics is not None else Kinematics(model)
    frames = {"parent": definition_frame(model, definition.parent), "child": definition_frame(model, definition.child)}
    q = np.asarray(q, dtype=float)
    R, _ = kin.poses(q)
    Rp = R[..., model.segment_index(definition.parent.segment), :, :] @ frames["parent"]
    Rc = R[..., model.segment_index(definition.child.segment), :, :] @ frames["child"]
    letters = definition.letters
    ang = euler_angles(np.swapaxes(Rp, -1, -2) @ Rc, letters, negative_middle=(letters[0] == letters[2]))
    if unwrap and ang.ndim == 2 and ang.shape[0] > 1:
        ang = np.unwrap(ang, axis=0)
    return ang


# --------------------------------------------------------------------------------------------
# The anatomical angles every output reports
# --------------------------------------------------------------------------------------------
ANATOMICAL_ANGLES: tuple[tuple[str, str, str], ...] = (
    # (column, definition, meaning with its sign for a right arm)
    ("SC_Y_protraction", "ISB SC Y-X'-Z'' (Wu 2005): clavicle to thorax", "+ protraction, - retraction"),
    ("SC_X_elevation", "ISB SC Y-X'-Z''", "- elevation, + depression"),
    ("SC_Z_posterior_rotation", "ISB SC Y-X'-Z''", "+ posterior (backward) axial rotation of the clavicle"),
    ("AC_Y_internal_rotation", "ISB AC Y-X'-Z'': scapula to clavicle", "+ internal rotation"),
    ("AC_X_upward_rotation", "ISB AC Y-X'-Z''", "- upward rotation, + downward"),
    ("AC_Z_posterior_tilt", "ISB AC Y-X'-Z''", "+ posterior tilt"),
    ("ST_Y_internal_rotation", "ISB ST Y-X'-Z'': scapula to thorax", "+ internal rotation"),
    ("ST_X_upward_rotation", "ISB ST Y-X'-Z''", "- upward rotation, + downward"),
    ("ST_Z_posterior_tilt", "ISB ST Y-X'-Z''", "+ posterior tilt"),
    ("GH_Y_plane_of_elevation", "ISB GH Y-X'-Y'' (Wu 2005): humerus to scapula", "plane of elevation in the scapula's frame (0 along its Z axis, + anterior)"),
    ("GH_X_elevation", "ISB GH Y-X'-Y''", "- elevation"),
    ("GH_Y_axial_rotation", "ISB GH Y-X'-Y''", "+ internal axial rotation"),
    ("GH_phadke_X_elevation", "GH X-Z'-Y'' (Phadke et al. 2011, as Ludewig et al. 2009)", "- elevation (abduction)"),
    ("GH_phadke_Z_flexion", "GH X-Z'-Y'' (Phadke)", "+ forward flexion"),
    ("GH_phadke_Y_internal_rotation", "GH X-Z'-Y'' (Phadke)", "+ internal, - external rotation"),
    ("HT_Y_plane_of_elevation", "ISB HT Y-X'-Y'': humerus to thorax", "0 abduction, 90 deg forward flexion"),
    ("HT_X_elevation", "ISB HT Y-X'-Y''", "- elevation"),
    ("HT_Y_axial_rotation", "ISB HT Y-X'-Y''", "+ internal axial rotation"),
    ("elbow_flexion", "ulna to humerus about the epicondyle axis EM->EL (Wu 2005 part II flexion axis)", "+ flexion from the extended reference posture"),
    ("forearm_pronation", "radius to ulna about the axis ulnar head -> radial head (Wu 2005 part II)", "+ pronation from full supination"),
    ("wrist_flexion", "hand to radius, Z-X' cardan about the model's wrist axes", "+ flexion"),
    ("wrist_radial_deviation", "hand to radius, Z-X' cardan", "+ radial deviation"),
)
"""The anatomical angles of every output (CSV, .mot, DataFrame, summary, report, viewer): the ISB
joint angles of the shoulder from the segments' ISB frames (module docstring), GH in both
sequences the literature uses (ISB's Y-X'-Y'' and Phadke's X-Z'-Y''), and the elbow, forearm and
wrist angles, which are the model's own coordinates because its joints sit on those anatomical
axes. Radians inside; degrees at the file edges. Signs are the raw decompositions' (no flip)."""

ANATOMICAL_COLUMNS: tuple[str, ...] = tuple(a[0] for a in ANATOMICAL_ANGLES)

_DISTAL = {"elbow_flexion": "elbow_flexion", "forearm_pronation": "pronation", "wrist_flexion": "wrist_flexion",
           "wrist_radial_deviation": "wrist_radial_deviation"}
"""Anatomical angle -> the model coordinate it is."""


_FRAME_ANGLE_SETS: dict[str, tuple[str, str, bool]] = {
    # angle set: (joint, sequence, middle angle <= 0), in ANATOMICAL_ANGLES' order
    "SC": ("SC", "YXZ", False), "AC": ("AC", "YXZ", False), "ST": ("ST", "YXZ", False),
    "GH": ("GH", "YXY", True), "GH_phadke": ("GH", "XZY", False), "HT": ("HT", "YXY", True),
}


def angles_of_frames(Rg: Mapping[str, np.ndarray], /) -> dict[str, np.ndarray]:
    """The shoulder's anatomical angle sets (ANATOMICAL_ANGLES: SC, AC, ST, GH in ISB's and Phadke's
    sequences, HT; each (..., 3) rad) of global ISB frames ``Rg`` (segment -> (..., 3, 3); "thorax"
    is the identity where absent). A set whose two frames are not both given is left out, so bone
    truth with a scapula and a humerus gives ST, GH, GH_phadke and HT."""
    frames = dict(Rg)
    if "thorax" not in frames:
        frames["thorax"] = np.eye(3)
    out = {}
    for key, (joint, sequence, negative) in _FRAME_ANGLE_SETS.items():
        prox, dist = _JOINTS[joint]
        if prox in frames and dist in frames:
            rel = np.swapaxes(frames[prox], -1, -2) @ frames[dist]
            out[key] = euler_angles(rel, sequence, negative_middle=negative)
    return out


def distal_only_coordinates(model: Model, kinematics: Kinematics, /) -> dict[int, int]:
    """The coordinates that move none of the ISB frames (ISB_FRAME_SEGMENTS), each with its column
    of :func:`anatomical_table` (where it is one of the distal angles, _DISTAL): a change of one
    changes that column alone, and every other column not even by a rounding (the frames are
    computed from the same numbers), which lets a finite difference skip the frames for it."""
    names = model.coordinate_names
    frames = [model.segment_index(s) for s in ISB_FRAME_SEGMENTS]
    moves_a_frame = kinematics.affects[frames].any(axis=0)
    first = len(ANATOMICAL_COLUMNS) - len(_DISTAL)
    columns = {names.index(c): first + i for i, c in enumerate(_DISTAL.values())}
    return {j: columns[j] for j in range(model.n_coordinates) if not moves_a_frame[j] and j in columns}


def anatomical_table(model: Model, q: np.ndarray, /, *, kinematics: Kinematics | None = None,
                     unwrap: bool = True) -> tuple[tuple[str, ...], np.ndarray]:
    """The anatomical angles (ANATOMICAL_ANGLES) of q (n, m) or (m,): (column names, angles
    (n, 22) or (22,) in radians), unwrapped along the frames when ``unwrap``."""
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    qq = q[None, :] if single else q
    kin = kinematics if kinematics is not None else Kinematics(model)
    frames = anatomical_frames(model)
    out = np.empty((qq.shape[0], len(ANATOMICAL_COLUMNS)))
    names = model.coordinate_names
    for a in range(0, qq.shape[0], ISB_BLOCK_FRAMES):
        part = qq[a:a + ISB_BLOCK_FRAMES]
        Rg = segment_anatomical_rotations(model, part, kinematics=kin, frames=frames)
        cols = angles_of_frames(Rg)
        distal = np.stack([part[:, names.index(c)] for c in _DISTAL.values()], axis=-1)
        out[a:a + ISB_BLOCK_FRAMES] = np.concatenate([cols[j] for j in _FRAME_ANGLE_SETS] + [distal], axis=-1)
    if unwrap and out.shape[0] > 1:  # a column at a time: np.unwrap makes ~6 temporaries of its input's size
        for j in range(out.shape[1]):
            out[:, j] = np.unwrap(out[:, j])
    return ANATOMICAL_COLUMNS, (out[0] if single else out)
