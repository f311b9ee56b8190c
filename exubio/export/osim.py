"""exubio Model -> OpenSim model file (.osim, OpenSim 4 format).

Mapping (exact, checked against ``exubio.model.kinematics`` by tests/export/test_export.py):
- every segment is a Body with its mass, centre of mass and inertia about the centre of mass
  (``Ixx Iyy Izz Ixy Ixz Iyz``: the entries of exubio's tensor); the body frame is exubio's segment
  frame. The thorax moves on a free joint to the ground with its mass (exubio.export.thorax: all six
  coordinates 0 = exubio's thorax-fixed model, ground = the thorax frame, gravity -Y), or, with
  ``thorax="weld"``, is welded to the ground.
- every joint is a CustomJoint named as exubio's joint: parent frame = a PhysicalOffsetFrame on
  the parent body at the joint centre (no rotation), child frame = the child body itself. Its
  SpatialTransform rotation1..k turn about exubio's joint axes with the coordinates (LinearFunction
  1 x + 0), in exubio's order: R = Rot(a1, q1) Rot(a2, q2) Rot(a3, q3), the axes written in the
  parent frame at q = 0, as exubio defines them. Rotations a revolute or cardan joint lacks turn
  about the axes that complete an orthonormal basis, with a Constant 0; translations are Constant 0.
- coordinates keep exubio's names, ``default_value`` 0, ``range`` in radians (an unlimited side:
  +-2 pi, one turn), ``clamped`` false.
- model points are Markers on their bodies (names: ``exubio.export.marker_table``).
- an XML comment before ``<OpenSimDocument>`` states the thorax ellipsoid (centre, radii, the
  scapula points held on it), which has no place here: the model is an open chain. (OpenSim's
  ScapulothoracicJoint parametrises the scapula differently and is not used.) The document says
  ``Version="40000"``: readable by OpenSim 4.0 and later (newer ones update it on loading).
"""
from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from exubio.export.common import UNLIMITED_RAD, check_names, complete_basis, ellipsoid_note, fmt, marker_table, vec, write_text
from exubio.export.thorax import THORAX_COORDINATES, THORAX_ROTATION_AXES, THORAX_TRANSLATIONS, with_thorax_inertia
from exubio.model.kinematics import Kinematics
from exubio.types import Model


def _range(rng: np.ndarray) -> str:
    lo, hi = (float(x) for x in rng)
    return vec([lo if np.isfinite(lo) else -UNLIMITED_RAD, hi if np.isfinite(hi) else UNLIMITED_RAD])


def _inertia(tensor: np.ndarray) -> str:
    t = np.asarray(tensor, dtype=float)
    return vec([t[0, 0], t[1, 1], t[2, 2], t[0, 1], t[0, 2], t[1, 2]])


def _body(seg) -> str:
    return (f"\t\t\t\t<Body name={quoteattr(seg.name)}>\n"
            f"\t\t\t\t\t<mass>{fmt(seg.mass_kg)}</mass>\n"
            f"\t\t\t\t\t<mass_center>{vec(seg.com_m)}</mass_center>\n"
            f"\t\t\t\t\t<inertia>{_inertia(seg.inertia_kgm2)}</inertia>\n"
            "\t\t\t\t</Body>\n")


def _transform_axis(name: str, axis, coordinate: str | None) -> str:
    function = ('<LinearFunction name="function"><coefficients>1 0</coefficients></LinearFunction>'
                if coordinate else '<Constant name="function"><value>0</value></Constant>')
    return (f'\t\t\t\t\t\t<TransformAxis name="{name}">\n'
            f"\t\t\t\t\t\t\t<coordinates>{escape(coordinate or '')}</coordinates>\n"
            f"\t\t\t\t\t\t\t<axis>{vec(axis)}</axis>\n"
            f"\t\t\t\t\t\t\t{function}\n"
            "\t\t\t\t\t\t</TransformAxis>\n")


def _coordinate(name: str, default: str, rng: str) -> str:
    return (f"\t\t\t\t\t\t<Coordinate name={quoteattr(name)}>\n"
            f"\t\t\t\t\t\t\t<default_value>{default}</default_value>\n"
            f"\t\t\t\t\t\t\t<range>{rng}</range>\n"
            "\t\t\t\t\t\t\t<clamped>false</clamped>\n"
            "\t\t\t\t\t\t\t<locked>false</locked>\n"
            "\t\t\t\t\t\t</Coordinate>\n")


def _joint_xml(name: str, parent_frame: str, child_frame: str, coords: str, frames: str, axes: str) -> str:
    """A CustomJoint element: its sockets, coordinates, offset frames and spatial transform."""
    return (f"\t\t\t\t<CustomJoint name={quoteattr(name)}>\n"
            f"\t\t\t\t\t<socket_parent_frame>{escape(parent_frame)}</socket_parent_frame>\n"
            f"\t\t\t\t\t<socket_child_frame>{escape(child_frame)}</socket_child_frame>\n"
            f"\t\t\t\t\t<coordinates>\n{coords}\t\t\t\t\t</coordinates>\n"
            f"\t\t\t\t\t<frames>\n{frames}\t\t\t\t\t</frames>\n"
            f"\t\t\t\t\t<SpatialTransform>\n{axes}\t\t\t\t\t</SpatialTransform>\n"
            "\t\t\t\t</CustomJoint>\n")


def _custom_joint(seg, anatomical: dict | None = None) -> str:
    """A CustomJoint on exubio's joint axes with its coordinates; with ``anatomical`` (the joint's
    entry of _anatomical_joints), on the two segments' ISB frames with the anatomical angles as
    coordinates instead."""
    joint = seg.joint
    offset = f"{seg.parent}_offset"
    if anatomical is not None:
        return _anatomical_joint(seg, offset, **anatomical)
    coords = "".join(_coordinate(name, "0", _range(rng)) for name, rng in zip(joint.coordinates, joint.ranges_rad))
    basis = complete_basis(joint.axes)
    names = list(joint.coordinates) + [None] * (3 - len(joint.coordinates))
    axes = "".join(_transform_axis(f"rotation{i + 1}", basis[i], names[i]) for i in range(3))
    axes += "".join(_transform_axis(f"translation{i + 1}", np.eye(3)[i], None) for i in range(3))
    frames = (f"\t\t\t\t\t\t<PhysicalOffsetFrame name={quoteattr(offset)}>\n"
              f"\t\t\t\t\t\t\t<socket_parent>/bodyset/{escape(seg.parent)}</socket_parent>\n"
              f"\t\t\t\t\t\t\t<translation>{vec(joint.centre_m)}</translation>\n"
              "\t\t\t\t\t\t\t<orientation>0 0 0</orientation>\n"
              "\t\t\t\t\t\t</PhysicalOffsetFrame>\n")
    return _joint_xml(joint.name, offset, f"/bodyset/{seg.name}", coords, frames, axes)


def _offset(name: str, body: str, translation, R: np.ndarray) -> str:
    from exubio.model.angles import euler_angles

    xyz = euler_angles(R, "XYZ")  # OpenSim's orientation: body-fixed X-Y-Z angles
    return (f"\t\t\t\t\t\t<PhysicalOffsetFrame name={quoteattr(name)}>\n"
            f"\t\t\t\t\t\t\t<socket_parent>/bodyset/{escape(body)}</socket_parent>\n"
            f"\t\t\t\t\t\t\t<translation>{vec(translation)}</translation>\n"
            f"\t\t\t\t\t\t\t<orientation>{vec(xyz)}</orientation>\n"
            "\t\t\t\t\t\t</PhysicalOffsetFrame>\n")


def _anatomical_joint(seg, offset: str, *, parent_frame: np.ndarray, child_frame: np.ndarray, sequence: str,
                      names: tuple[str, ...], defaults: np.ndarray, signs: np.ndarray) -> str:
    """The joint between the parent's and the child's ISB frames: rotation1..3 about the frame axes
    of ``sequence`` (intrinsic) with the anatomical angles ``names`` as coordinates, so the
    coordinates are exactly the published angles (default: their values in the reference posture).
    ``signs`` (+-1 per angle, exubio.model.signs): an angle written with the sign reversed turns
    about the reversed axis (the same rotation), so a .mot of that convention plays on it."""
    joint = seg.joint
    child = f"{seg.name}_isb"
    coords = "".join(_coordinate(name, fmt(d * f), vec([-UNLIMITED_RAD, UNLIMITED_RAD]))
                     for name, d, f in zip(names, defaults, signs))
    unit = {"X": np.eye(3)[0], "Y": np.eye(3)[1], "Z": np.eye(3)[2]}
    axes = "".join(_transform_axis(f"rotation{i + 1}", unit[sequence[i]] * signs[i], names[i]) for i in range(3))
    axes += "".join(_transform_axis(f"translation{i + 1}", np.eye(3)[i], None) for i in range(3))
    frames = _offset(offset, seg.parent, joint.centre_m, parent_frame) + _offset(child, seg.name, np.zeros(3), child_frame)
    return _joint_xml(joint.name, offset, child, coords, frames, axes)


ANATOMICAL_JOINTS = {"clavicle": ("YXZ", ("SC_Y_protraction", "SC_X_elevation", "SC_Z_posterior_rotation")),
                     "scapula": ("YXZ", ("AC_Y_internal_rotation", "AC_X_upward_rotation", "AC_Z_posterior_tilt")),
                     "humerus": ("XZY", ("GH_phadke_X_elevation", "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation"))}
"""Segment -> (sequence, anatomical angles) of the joints written on ISB frames in an anatomical
.osim: SC and AC in ISB's Y-X'-Z''; GH in Phadke's X-Z'-Y'' (ISB's Y-X'-Y'' repeats an axis, which a
CustomJoint cannot take, and is in gimbal lock with the arm hanging)."""

DISTAL_NAMES = {"elbow_flexion": "elbow_flexion", "pronation": "forearm_pronation", "wrist_flexion": "wrist_flexion",
                "wrist_radial_deviation": "wrist_radial_deviation"}
"""Model coordinate -> its anatomical angle name (exubio.model.angles.ANATOMICAL_ANGLES)."""


def _anatomical_joints(model: Model, signs: str = "isb") -> dict[str, dict]:
    from exubio.model.angles import anatomical_frames, anatomical_table
    from exubio.model.signs import factors

    frames = anatomical_frames(model)
    names, ref = anatomical_table(model, np.zeros(model.n_coordinates))
    out = {}
    for seg_name, (sequence, angle_names) in ANATOMICAL_JOINTS.items():
        seg = model.segment(seg_name)
        out[seg_name] = {"parent_frame": frames[seg.parent], "child_frame": frames[seg_name], "sequence": sequence,
                         "names": angle_names, "defaults": np.array([ref[names.index(n)] for n in angle_names]),
                         "signs": factors(angle_names, signs)}
    return out


def _free_joint(root: str) -> str:
    """The thorax's free joint to the ground (exubio.export.thorax)."""
    coords = "".join(_coordinate(n, "0", vec([-UNLIMITED_RAD, UNLIMITED_RAD]) if n not in THORAX_TRANSLATIONS
                                 else "-10 10") for n in THORAX_COORDINATES)
    axes = "".join(_transform_axis(f"rotation{i + 1}", THORAX_ROTATION_AXES[i], THORAX_COORDINATES[i]) for i in range(3))
    axes += "".join(_transform_axis(f"translation{i + 1}", np.eye(3)[i], THORAX_COORDINATES[3 + i]) for i in range(3))
    return _joint_xml(f"ground_{root}", "/ground", f"/bodyset/{root}", coords, "", axes)


def osim_text(model: Model, *, coordinates: str = "anatomical", thorax: str = "free", signs: str = "isb") -> str:
    """The .osim document for ``model`` (see the module docstring). ``coordinates``: "anatomical"
    (SC, AC and GH between the ISB frames with the anatomical angles as coordinates, elbow, forearm
    and wrist named as the anatomical angles: exubio's .mot plays on it) or "model" (exubio's own
    joint coordinates: its .npz q plays on it). ``thorax``: "free" (a 6-DOF joint to the ground
    and the thorax's mass, exubio.export.thorax: OpenSim's ID tool runs on the .mot with the trunk's
    motion) or "weld" (fixed to the ground: the ground is exubio's thorax frame). ``signs``: the sign
    convention of the .mot it is to play (exubio.model.signs; anatomical coordinates only)."""
    if coordinates not in ("anatomical", "model"):
        raise ValueError(f"coordinates: expected 'anatomical' or 'model', got {coordinates!r}")
    if thorax not in ("free", "weld"):
        raise ValueError(f"thorax: expected 'free' or 'weld', got {thorax!r}")
    Kinematics(model)  # the structure exubio can compute with (fixed root, orthogonal axes)
    check_names(model, list(THORAX_COORDINATES) if thorax == "free" else [])
    if thorax == "free":
        model = with_thorax_inertia(model)
    anatomical = _anatomical_joints(model, signs) if coordinates == "anatomical" else {}
    root = model.segments[0]
    note = "\n".join("  " + line.replace("--", "- -")
                     for line in ellipsoid_note(model, "OpenSim .osim", free_thorax=thorax == "free"))
    weld = _free_joint(root.name) if thorax == "free" else (
        f"\t\t\t\t<WeldJoint name={quoteattr('ground_' + root.name)}>\n"
        "\t\t\t\t\t<socket_parent_frame>/ground</socket_parent_frame>\n"
        f"\t\t\t\t\t<socket_child_frame>/bodyset/{escape(root.name)}</socket_child_frame>\n"
        "\t\t\t\t</WeldJoint>\n")
    markers = "".join(
        f"\t\t\t\t<Marker name={quoteattr(name)}>\n"
        f"\t\t\t\t\t<socket_parent_frame>/bodyset/{escape(seg)}</socket_parent_frame>\n"
        f"\t\t\t\t\t<location>{vec(model.segment(seg).points[point])}</location>\n"
        "\t\t\t\t\t<fixed>true</fixed>\n"
        "\t\t\t\t</Marker>\n"
        for name, seg, point in marker_table(model))
    return ('<?xml version="1.0" encoding="UTF-8" ?>\n'
            f"<!--\n{escape(note)}\n-->\n"
            '<OpenSimDocument Version="40000">\n'
            f"\t<Model name={quoteattr(model.name)}>\n"
            "\t\t<gravity>0 -9.8066499999999994 0</gravity>\n"
            "\t\t<length_units>meters</length_units>\n"
            "\t\t<force_units>N</force_units>\n"
            '\t\t<Ground name="ground" />\n'
            '\t\t<BodySet name="bodyset">\n\t\t\t<objects>\n'
            + "".join(_body(seg) for seg in model.segments)
            + "\t\t\t</objects>\n\t\t</BodySet>\n"
            '\t\t<JointSet name="jointset">\n\t\t\t<objects>\n'
            + weld + "".join(_custom_joint(_renamed(seg) if anatomical else seg, anatomical.get(seg.name))
                             for seg in model.segments[1:])
            + "\t\t\t</objects>\n\t\t</JointSet>\n"
            '\t\t<MarkerSet name="markerset">\n\t\t\t<objects>\n'
            + markers
            + "\t\t\t</objects>\n\t\t</MarkerSet>\n"
            "\t</Model>\n</OpenSimDocument>\n")


def _renamed(seg):
    """The segment with its distal joint's coordinates named as the anatomical angles."""
    import dataclasses

    if seg.joint is None or not any(c in DISTAL_NAMES for c in seg.joint.coordinates):
        return seg
    joint = dataclasses.replace(seg.joint, coordinates=tuple(DISTAL_NAMES.get(c, c) for c in seg.joint.coordinates))
    return dataclasses.replace(seg, joint=joint)


def write_osim(model: Model, path: str | Path, *, overwrite: bool = False, coordinates: str = "anatomical",
               thorax: str = "free", signs: str = "isb") -> Path:
    """Write ``model`` as an OpenSim 4 model file at ``path`` (atomically); an existing file is
    replaced only with ``overwrite`` (otherwise InputError naming it); ``coordinates``, ``thorax``
    and ``signs``: see ``osim_text``. Returns the path."""
    return write_text(path, osim_text(model, coordinates=coordinates, thorax=thorax, signs=signs), overwrite=overwrite)
