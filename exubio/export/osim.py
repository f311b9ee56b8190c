"""exubio Model -> OpenSim model file (.osim, OpenSim 4 format).

Mapping (exact, checked against ``exubio.kinematics`` by tests/test_export.py):
- every segment is a Body with its mass, centre of mass and inertia about the centre of mass
  (``Ixx Iyy Izz Ixy Ixz Iyz``: the entries of exubio's tensor); the body frame is exubio's segment
  frame. The thorax is welded to ground (the thorax frame is exubio's global frame).
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
from exubio.kinematics import Kinematics
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


def _custom_joint(seg) -> str:
    joint = seg.joint
    offset = f"{seg.parent}_offset"
    coords = "".join(
        f"\t\t\t\t\t\t<Coordinate name={quoteattr(name)}>\n"
        "\t\t\t\t\t\t\t<default_value>0</default_value>\n"
        f"\t\t\t\t\t\t\t<range>{_range(rng)}</range>\n"
        "\t\t\t\t\t\t\t<clamped>false</clamped>\n"
        "\t\t\t\t\t\t\t<locked>false</locked>\n"
        "\t\t\t\t\t\t</Coordinate>\n"
        for name, rng in zip(joint.coordinates, joint.ranges_rad))
    basis = complete_basis(joint.axes)
    names = list(joint.coordinates) + [None] * (3 - len(joint.coordinates))
    axes = "".join(_transform_axis(f"rotation{i + 1}", basis[i], names[i]) for i in range(3))
    axes += "".join(_transform_axis(f"translation{i + 1}", np.eye(3)[i], None) for i in range(3))
    return (f"\t\t\t\t<CustomJoint name={quoteattr(joint.name)}>\n"
            f"\t\t\t\t\t<socket_parent_frame>{escape(offset)}</socket_parent_frame>\n"
            f"\t\t\t\t\t<socket_child_frame>/bodyset/{escape(seg.name)}</socket_child_frame>\n"
            f"\t\t\t\t\t<coordinates>\n{coords}\t\t\t\t\t</coordinates>\n"
            "\t\t\t\t\t<frames>\n"
            f"\t\t\t\t\t\t<PhysicalOffsetFrame name={quoteattr(offset)}>\n"
            f"\t\t\t\t\t\t\t<socket_parent>/bodyset/{escape(seg.parent)}</socket_parent>\n"
            f"\t\t\t\t\t\t\t<translation>{vec(joint.centre_m)}</translation>\n"
            "\t\t\t\t\t\t\t<orientation>0 0 0</orientation>\n"
            "\t\t\t\t\t\t</PhysicalOffsetFrame>\n"
            "\t\t\t\t\t</frames>\n"
            f"\t\t\t\t\t<SpatialTransform>\n{axes}\t\t\t\t\t</SpatialTransform>\n"
            "\t\t\t\t</CustomJoint>\n")


def osim_text(model: Model) -> str:
    """The .osim document for ``model`` (see the module docstring)."""
    Kinematics(model)  # the structure exubio can compute with (fixed root, orthogonal axes)
    check_names(model)
    root = model.segments[0]
    note = "\n".join("  " + line.replace("--", "- -") for line in ellipsoid_note(model, "OpenSim .osim"))
    weld = (f"\t\t\t\t<WeldJoint name={quoteattr('ground_' + root.name)}>\n"
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
            + weld + "".join(_custom_joint(seg) for seg in model.segments[1:])
            + "\t\t\t</objects>\n\t\t</JointSet>\n"
            '\t\t<MarkerSet name="markerset">\n\t\t\t<objects>\n'
            + markers
            + "\t\t\t</objects>\n\t\t</MarkerSet>\n"
            "\t</Model>\n</OpenSimDocument>\n")


def write_osim(model: Model, path: str | Path, *, overwrite: bool = False) -> Path:
    """Write ``model`` as an OpenSim 4 model file at ``path`` (atomically); an existing file is
    replaced only with ``overwrite`` (otherwise InputError naming it). Returns the path."""
    return write_text(path, osim_text(model), overwrite=overwrite)
