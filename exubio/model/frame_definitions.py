"""Segment frames and joint-angle definitions written as data, the way studies publish them.

A study builds each bone's frame from landmarks, e.g. Ludewig et al. 2009's scapula (as recorded
by the Spartacus dataset, Moissenet et al. 2025)::

    origin AC;  x = vec(AI>TS)^vec(AI>AC);  y = z^x;  z = vec(TS>AC)

Grammar of an axis expression (the Spartacus metadata's):

* ``vec(P>Q)``: the vector from point P to point Q; a point is a landmark name (``AC``) or a
  midpoint ``(A+B)/2``;
* ``x``, ``y``, ``z``: another axis of the same frame;
* ``u^v^w``: cross products, left to right;
* anything else (``imaging posteroanterior axis``, ``(spinal canal axis from T1 to T7)``, a glenoid
  landmark the model does not have) cannot be built from a model's landmarks: ``build_frame``
  raises ``NotBuildable`` with the reason.

``build_frame`` evaluates the three axes from landmark positions (any consistent frame), normalises
them and returns the nearest rotation (the columns are the frame's x, y, z); a definition whose
axes are not orthogonal on the given landmarks by more than ``MAX_SKEW_DEG`` is refused rather than
silently bent. Pure numpy: the model side (where the landmarks are) is ``exubio.model.angles``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Mapping

import numpy as np

__all__ = ["JOINT_SEGMENTS", "FrameDefinition", "JointDefinition", "NotBuildable", "build_frame", "sequence_letters",
           "ISB_WU2005", "MAX_SKEW_DEG"]

JOINT_SEGMENTS: dict[str, tuple[str, str]] = {
    "SC": ("thorax", "clavicle"),
    "AC": ("clavicle", "scapula"),
    "ST": ("thorax", "scapula"),
    "GH": ("scapula", "humerus"),
    "HT": ("thorax", "humerus"),
}
"""(proximal, distal) segment of every joint-angle set."""

MAX_SKEW_DEG = 1.0
"""Largest departure from orthogonality (deg) between two built axes that is still a frame."""


class NotBuildable(ValueError):
    """A frame definition that cannot be evaluated on the landmarks given (the message says why)."""


@dataclass(frozen=True)
class FrameDefinition:
    """How one segment's frame is built: three axis expressions (module docstring) and the
    study's correction method, if any (recorded, not applied: a comparison in the study's own
    frame must not apply it)."""

    segment: str
    x: str
    y: str
    z: str
    origin: str = ""
    correction: str = ""

    def landmarks(self) -> set[str]:
        """Landmark names the axes use (free-text axes contribute nothing)."""
        names: set[str] = set()
        for expr in (self.x, self.y, self.z):
            for term in _split_cross(expr or ""):
                m = re.fullmatch(r"vec\((.+)>(.+)\)", _norm(term))
                if m:
                    names.update(_point_names(m.group(1)) + _point_names(m.group(2)))
        return names

    def same_axes(self, other: "FrameDefinition") -> bool:
        """Same axis expressions (whatever the origin and correction)."""
        return (_norm(self.x), _norm(self.y), _norm(self.z)) == (_norm(other.x), _norm(other.y), _norm(other.z))


@dataclass(frozen=True)
class JointDefinition:
    """A joint-angle set as a study defines it: the proximal and distal frames and the intrinsic
    Euler sequence (as published, e.g. ``yx'z''``; ``sequence_letters`` gives ``"YXZ"``)."""

    joint: str
    parent: FrameDefinition
    child: FrameDefinition
    sequence: str
    source: str  # who defines it, e.g. "ISB (Wu et al. 2005)" or "Ludewig et al. 2009"

    @property
    def letters(self) -> str:
        return sequence_letters(self.sequence)

    def describe(self) -> str:
        return (f"{self.joint} in {self.source}'s frames: {self.parent.segment} "
                f"(x={self.parent.x}; y={self.parent.y}; z={self.parent.z}), {self.child.segment} "
                f"(x={self.child.x}; y={self.child.y}; z={self.child.z}); sequence {self.sequence}")


_MID = re.compile(r"^\(([A-Za-z0-9]+(?:\+[A-Za-z0-9]+)+)\)/(\d+)$")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9]*$")


def _norm(expr: str) -> str:
    return re.sub(r"\s+", "", expr or "")


def sequence_letters(sequence: str) -> str:
    """``"yx'z''"`` or ``"Y-X'-Z''"`` -> ``"YXZ"``."""
    letters = "".join(c for c in sequence.upper() if c in "XYZ")
    if len(letters) != 3:
        raise NotBuildable(f"Euler sequence '{sequence}' does not name three axes")
    return letters


def _point_names(point: str) -> list[str]:
    point = _norm(point)
    m = _MID.match(point)
    if m:
        return m.group(1).split("+")
    return [point]


def _split_cross(expr: str) -> list[str]:
    """Split at top-level '^' (not inside parentheses)."""
    parts, depth, cur = [], 0, ""
    for ch in expr:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        if ch == "^" and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    parts.append(cur)
    return [p.strip() for p in parts]


def _point(point: str, landmarks: Mapping[str, np.ndarray]) -> np.ndarray:
    point = _norm(point)
    m = _MID.match(point)
    if m:
        names = m.group(1).split("+")
        if int(m.group(2)) != len(names):
            raise NotBuildable(f"point '{point}' is not a mean of its landmarks")
        return np.mean([_landmark(n, landmarks) for n in names], axis=0)
    if not _NAME.match(point):
        raise NotBuildable(f"'{point}' is not a landmark or a midpoint")
    return _landmark(point, landmarks)


def _landmark(name: str, landmarks: Mapping[str, np.ndarray]) -> np.ndarray:
    if name not in landmarks:
        raise NotBuildable(f"landmark {name} is not in the model (it has {', '.join(sorted(landmarks))})")
    return np.asarray(landmarks[name], dtype=float)


def _term(term: str, axes: dict[str, np.ndarray], landmarks: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """A vector, or None when it needs an axis not evaluated yet."""
    t = _norm(term)
    if t in ("x", "y", "z"):
        return axes.get(t)
    m = re.fullmatch(r"vec\((.+)>(.+)\)", t)
    if m:
        return _point(m.group(2), landmarks) - _point(m.group(1), landmarks)
    raise NotBuildable(f"axis term '{term.strip()}' is not a landmark vector (vec(P>Q)) or an axis")


def build_frame(defn: FrameDefinition, landmarks: Mapping[str, np.ndarray], /) -> np.ndarray:
    """The frame (3, 3), columns x, y, z, in the coordinates of ``landmarks`` (positions of one
    posture in one frame). Raises NotBuildable (axis not from landmarks, landmark missing,
    degenerate or non-orthogonal axes, left-handed result)."""
    exprs = {"x": defn.x, "y": defn.y, "z": defn.z}
    for k, e in exprs.items():
        if not _norm(e):
            raise NotBuildable(f"{defn.segment} axis {k} is not defined")
    axes: dict[str, np.ndarray] = {}
    for _ in range(3):
        for k, e in exprs.items():
            if k in axes:
                continue
            vecs = [_term(t, axes, landmarks) for t in _split_cross(e)]
            if any(v is None for v in vecs):
                continue
            v = vecs[0]
            for w in vecs[1:]:
                v = np.cross(v, w)
            n = float(np.linalg.norm(v))
            if n < 1e-9:
                raise NotBuildable(f"{defn.segment} axis {k} = {e} has zero length on these landmarks")
            axes[k] = v / n
    if len(axes) < 3:
        raise NotBuildable(f"{defn.segment} axes refer to each other in a cycle: x={defn.x}; y={defn.y}; z={defn.z}")
    M = np.column_stack([axes["x"], axes["y"], axes["z"]])
    skew = np.degrees(np.arcsin(np.clip(np.abs([M[:, 0] @ M[:, 1], M[:, 1] @ M[:, 2], M[:, 0] @ M[:, 2]]), 0, 1)))
    if skew.max() > MAX_SKEW_DEG:
        raise NotBuildable(f"{defn.segment} axes are {skew.max():.1f} deg from orthogonal on these landmarks")
    if np.linalg.det(M) <= 0:
        raise NotBuildable(f"{defn.segment} axes form a left-handed frame on these landmarks (a left-side definition?)")
    u, _, vt = np.linalg.svd(M)
    return u @ vt


def _isb() -> dict[str, FrameDefinition]:
    """Wu et al. 2005 (J Biomech 38:981-992), right side, in the grammar above; the humerus is
    option 1 (elbow centre = midpoint of EL and EM)."""
    thorax_y = "vec((T8+PX)/2>(C7+IJ)/2)"
    return {
        "thorax": FrameDefinition("thorax", x="y^z", y=thorax_y, z="vec((T8+PX)/2>IJ)^vec((T8+PX)/2>C7)", origin="IJ"),
        "clavicle": FrameDefinition("clavicle", x=f"{thorax_y}^z", y="z^x", z="vec(SC>AC)", origin="SC"),
        "scapula": FrameDefinition("scapula", x="vec(AI>TS)^vec(AI>AA)", y="z^x", z="vec(TS>AA)", origin="AA"),
        "humerus": FrameDefinition("humerus", x="vec(GH>EL)^vec(GH>EM)", y="vec((EL+EM)/2>GH)", z="x^y", origin="GH"),
    }


ISB_WU2005: dict[str, FrameDefinition] = _isb()
"""The ISB frames (Wu et al. 2005) as definitions; exubio.model.angles.anatomical_frames is the hand
computation of the same frames that the tests compare them with."""
