"""Helpers the model writers share: number formatting, names, the ellipsoid note, atomic writing."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from exubio.errors import InputError, ModelError
from exubio.io.results import atomic_write
from exubio.types import Model

UNLIMITED_RAD = 2.0 * np.pi  # written for a side of a range exubio leaves unlimited (clamped false: no limit)


def fmt(x: float) -> str:
    """A float printed so that it reads back exactly (shortest round-trip repr)."""
    return repr(float(x))


def vec(v) -> str:
    return " ".join(fmt(x) for x in np.asarray(v, dtype=float).ravel())


def write_text(path, text: str, *, overwrite: bool) -> Path:
    path = Path(path)
    if path.exists() and not overwrite:
        raise InputError(f"{path}: the file already exists; pass overwrite=True (--overwrite) to replace it")

    def writer(tmp: Path) -> None:
        tmp.write_text(text, encoding="utf-8")

    return atomic_write(path, writer)


def ellipsoid_note(model: Model, fmt_name: str, *, free_thorax: bool = False) -> list[str]:
    """Lines (no comment marks) saying what the file cannot express: the thorax ellipsoid; with
    ``free_thorax``, how the thorax's free joint places it (exubio.export.thorax)."""
    ell = model.ellipsoid
    points = ", ".join(f"{pt} on {seg}" for seg, pt in ell.contact_points)
    root = (["Units: m, kg, kg m^2; angles rad. The first segment (thorax) is fixed: the global frame is",
             "exubio's thorax frame. Segment frames are exubio's (at the joint centre, parallel to the"]
            if not free_thorax else
            ["Units: m, kg, kg m^2; angles rad. The first segment (thorax) moves on a free joint to the ground",
             "(thorax_tilt about Z, thorax_list about X', thorax_rotation about Y'', thorax_tx/ty/tz along the",
             "ground's axes; all 0: the ground is exubio's thorax frame, gravity -Y). Its mass: "
             f"{model.segments[0].mass_kg:.6g} kg",
             "(exubio.export.thorax). Segment frames are exubio's (at the joint centre, parallel to the"])
    return [
        f"exubio model '{model.name}' exported by exubio.export ({fmt_name}).",
        f"Source: {model.source or model.name}.",
        *root,
        "thorax frame when every coordinate is 0); markers are exubio's model points.",
        "NOT EXPRESSED: the scapulothoracic constraint of exubio. The two scapula points",
        f"({points}) are held on the thorax ellipsoid",
        f"  centre {vec(ell.centre_m)} m, radii {vec(ell.radii_m)} m (thorax frame, axis-aligned),",
        "  g = sum(((r - centre) / radii)^2) - 1 = 0.",
        "This file has no such constraint: the exported model is an open chain with every coordinate free.",
        "Postures exubio reconstructed satisfy it already, so replaying them is exact; new postures",
        "(e.g. inverse kinematics in another tool) are not held on the ellipsoid.",
    ]


def check_names(model: Model, extra: list[str] = ()) -> None:
    """Every name the file will hold (segments, joints, coordinates, points, ``extra``) must be a
    single word of letters, digits, ``_ . -`` (both formats use names as paths or tokens), and
    segment, joint and coordinate names unique; a ModelError names the offenders otherwise."""
    segments = [s.name for s in model.segments] + list(extra)
    joints = [s.joint.name for s in model.segments if s.joint is not None]
    names = segments + joints + list(model.coordinate_names) + [p for s in model.segments for p in s.points]
    bad = sorted({n for n in names if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", n)})
    if bad:
        raise ModelError(f"{model.source or model.name}: names {bad} cannot be exported "
                         "(use letters, digits, '_', '.', '-')")
    coords = list(model.coordinate_names)
    dup = sorted({n for group in (segments, joints, coords) for n in group if group.count(n) > 1})
    if dup:
        raise ModelError(f"{model.source or model.name}: names {dup} would not be unique in the exported file")


def complete_basis(axes: np.ndarray) -> np.ndarray:
    """Three orthonormal rows whose first rows are ``axes`` (k <= 3 orthonormal unit vectors), right
    handed when k < 3; with k == 3, the axes as they are."""
    axes = np.asarray(axes, dtype=float).reshape(-1, 3)
    if len(axes) == 3:
        return axes.copy()
    if len(axes) == 1:
        a = axes[0]
        helper = np.eye(3)[int(np.argmin(np.abs(a)))]
        b = np.cross(a, helper)
        b /= np.linalg.norm(b)
        return np.array([a, b, np.cross(a, b)])
    c = np.cross(axes[0], axes[1])
    return np.array([axes[0], axes[1], c / np.linalg.norm(c)])


def marker_table(model: Model) -> list[tuple[str, str, str]]:
    """(marker name, segment, point) for every model point, in segment then point order. A point
    name found on one segment is the marker's name; one found on several segments (a joint centre
    such as AC on the clavicle and the scapula) becomes ``<point>_<segment>`` on each of them, since
    both formats want marker names to be unique."""
    count: dict[str, int] = {}
    for seg in model.segments:
        for name in seg.points:
            count[name] = count.get(name, 0) + 1
    table = [(name if count[name] == 1 else f"{name}_{seg.name}", seg.name, name)
             for seg in model.segments for name in seg.points]
    names = [t[0] for t in table]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise ModelError(f"{model.source or model.name}: cannot give the model points unique marker names: {clash}")
    return table
