"""exubio Model -> biorbd model file (.bioMod, version 4).

biorbd rotates a segment only about its own x, y and z axes (``rotations xyz``, a body-fixed
sequence), while an exubio joint turns about any orthonormal axes a1, a2, a3. Each moving segment
is therefore written as two biorbd segments:

- ``<segment>_<joint>``: the joint frame, at the joint centre in the parent with the rotation B
  whose columns carry the letters of the sequence onto exubio's axes (B e_x = a1, ... : ``xyz``;
  for a left-handed axis triple B e_y = a1, B e_x = a2, B e_z = a3: ``yxz``; a cardan or revolute
  joint's missing axes complete a right-handed basis). Its rotations are exubio's coordinates, in
  exubio's order, with ``rangesQ`` in radians (an unlimited side: +-2 pi); massless (``mass 0``:
  not biorbd's default 1e-8 kg, so that the model's mass is exubio's).
- ``<segment>``: the segment itself, the rotation B^T back from the joint frame, so that its frame
  is exubio's segment frame (Rot(a1, q1) Rot(a2, q2) Rot(a3, q3) = B R_seq(q) B^T), with mass,
  centre of mass, inertia and the model points as markers.

The generalized coordinates are exactly exubio's, in exubio's order (biorbd names them after the
joint segments and axes, e.g. ``humerus_gh_RotY``; the file's comments give exubio's names).
The comments at the top state the thorax ellipsoid, which a bioMod cannot hold as a constraint
on the scapula: the model is an open chain.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from exubio.export.common import UNLIMITED_RAD, check_names, complete_basis, ellipsoid_note, marker_table, vec, write_text
from exubio.export.thorax import THORAX_COORDINATES, THORAX_TRANSLATIONS, with_thorax_inertia
from exubio.model.kinematics import Kinematics
from exubio.types import Model


def joint_frame(axes: np.ndarray) -> tuple[np.ndarray, str]:
    """(B, letters): the rotation B (3x3) and the biorbd sequence with B e_letter(i) = a_i."""
    basis = complete_basis(axes)
    if np.linalg.det(basis) > 0:
        cols, letters = basis, "xyz"
    else:  # left-handed triple: swap the first two letters
        cols, letters = basis[[1, 0, 2]], "yxz"
    u, _, vt = np.linalg.svd(cols.T)  # the nearest rotation: exact for orthonormal axes
    return u @ vt, letters[: len(axes)]


def _rt(rotation: np.ndarray, translation) -> str:
    rows = np.eye(4)
    rows[:3, :3] = rotation
    rows[:3, 3] = translation
    return "\tRTinMatrix 1\n\tRT\n" + "".join(f"\t\t{vec(r)}\n" for r in rows)


def _ranges(rng: np.ndarray) -> str:
    lo = np.where(np.isfinite(rng[:, 0]), rng[:, 0], -UNLIMITED_RAD)
    hi = np.where(np.isfinite(rng[:, 1]), rng[:, 1], UNLIMITED_RAD)
    return "\trangesQ\n" + "".join(f"\t\t{vec([a, b])}\n" for a, b in zip(lo, hi))


def _inertial(seg) -> str:
    inertia = "".join(f"\t\t{vec(r)}\n" for r in np.asarray(seg.inertia_kgm2, dtype=float))
    return f"\tmass {vec([seg.mass_kg])}\n\tcom {vec(seg.com_m)}\n\tinertia\n{inertia}"


def biomod_text(model: Model, *, thorax: str = "weld") -> str:
    """The .bioMod document for ``model`` (see the module docstring); ``thorax``: "weld" (fixed:
    q is exubio's) or "free" (exubio.export.thorax: the thorax's mass, and a free joint, its six
    coordinates first in q: thorax_tx, thorax_ty, thorax_tz (m), thorax_tilt, thorax_list,
    thorax_rotation (rad), then exubio's)."""
    if thorax not in ("free", "weld"):
        raise ValueError(f"thorax: expected 'free' or 'weld', got {thorax!r}")
    Kinematics(model)  # the structure exubio can compute with (fixed root, orthogonal axes)
    check_names(model, [f"{s.name}_{s.joint.name}" for s in model.segments[1:]])
    free = thorax == "free"
    if free:
        model = with_thorax_inertia(model)
    lines = [f"// {line}" for line in ellipsoid_note(model, "biorbd .bioMod", free_thorax=free)]
    names = ([*THORAX_TRANSLATIONS, *THORAX_COORDINATES[:3]] if free else []) + list(model.coordinate_names)
    lines.append(f"// Generalized coordinates q (biorbd order = {'the thorax, then ' if free else ''}exubio order): "
                 + ", ".join(f"{i}: {n}" for i, n in enumerate(names)))
    out = "\n".join(lines) + "\n\nversion 4\n\ngravity 0 -9.80665 0\n\n"
    root = model.segments[0]
    dof = ("\ttranslations xyz\n\trotations zxy\n\trangesQ\n" + "\t\t-10 10\n" * 3
           + f"\t\t{vec([-UNLIMITED_RAD, UNLIMITED_RAD])}\n" * 3) if free else ""
    out += f"segment {root.name}\n{dof}{_inertial(root)}endsegment\n\n"
    for seg in model.segments[1:]:
        joint = seg.joint
        B, letters = joint_frame(joint.axes)
        frame = f"{seg.name}_{joint.name}"
        about = ", ".join(f"{n} about {letter} = exubio axis [{vec(a)}]"
                          for n, letter, a in zip(joint.coordinates, letters, joint.axes))
        out += (f"// joint '{joint.name}' ({joint.kind.value}, parent {seg.parent}): {about}\n"
                f"segment {frame}\n\tparent {seg.parent}\n{_rt(B, joint.centre_m)}"
                f"\trotations {letters}\n{_ranges(joint.ranges_rad)}\tmass 0\nendsegment\n\n"
                f"segment {seg.name}\n\tparent {frame}\n{_rt(B.T, np.zeros(3))}{_inertial(seg)}endsegment\n\n")
    for name, seg, point in marker_table(model):
        out += (f"marker {name}\n\tparent {seg}\n\tposition {vec(model.segment(seg).points[point])}\n"
                "\ttechnical 1\n\tanatomical 0\nendmarker\n")
    return out


def write_biomod(model: Model, path: str | Path, *, overwrite: bool = False, thorax: str = "weld") -> Path:
    """Write ``model`` as a biorbd model file (version 4) at ``path`` (atomically); an existing
    file is replaced only with ``overwrite`` (otherwise InputError naming it); ``thorax``: see
    ``biomod_text``. Returns the path."""
    return write_text(path, biomod_text(model, thorax=thorax), overwrite=overwrite)
