"""Skin-marker placement of the lab's biorbd model, read without biorbd.

Reads a biorbd ``.bioMod`` text file (the subset that
``../shared/data/models/bioptim_exo_wu_converted_definitif.bioMod`` uses), computes every segment's
global transform and every marker's global position at any joint configuration ``q``, and reports
where the model puts its skin markers relative to its bones, in the ISB thorax frame (Wu et al.
2005) built from the model's own thorax markers.

Source of the numbers (not of any text or code): Ipuch/bioptim_exo @
b4a33b4e79753059725c9ffee5c7749a6cf87858, models/wu_converted_definitif.bioMod, MIT licence,
"Copyright (c) 2022 Pierre".

Conventions (read from biorbd's own source, github.com/pyomeca/biorbd: src/ModelReader.cpp,
src/Utils/Rotation.cpp, src/Utils/RotoTrans.cpp, src/RigidBody/Segment.cpp, src/Utils/IfStream.cpp):

* The file is a stream of whitespace-separated tokens. A token beginning with ``//`` starts a
  comment to the end of its line; a token beginning with ``/*`` starts a comment that ends with the
  first token beginning or ending with ``*/``. Keywords are case-insensitive.
* ``RTinMatrix`` defaults to 0 for version >= 3 (1 for older files). With ``RTinMatrix 1``, ``RT``
  is followed by 16 numbers, a 4x4 homogeneous matrix row by row (rotation in the upper-left block,
  translation in the last column). With ``RTinMatrix 0``, ``RT`` is followed by three angles (rad),
  a sequence string and three translations: ``RT a1 a2 a3 seq tx ty tz``; the rotation is
  ``R = R_seq[0](a1) @ R_seq[1](a2) @ R_seq[2](a3)`` (``Rotation::fromEulerAngles`` right-multiplies
  the elementary matrices in sequence order), i.e. an intrinsic (body-fixed, moving-axes) sequence,
  the same as the extrinsic sequence taken in reverse order.
* A segment's ``RT`` places it in its parent's frame. Its degrees of freedom are applied after the
  ``RT``, translations first (along the axes of the RT frame, in the order of the ``translations``
  string), then rotations in the order of the ``rotations`` string, each about an axis of the
  frame already rotated by the previous ones (biorbd adds one RBDL body per DoF, the first placed
  by the RT, the following ones by identity transforms):
  ``T_global(seg) = T_global(parent) @ RT @ Trans(q_t...) @ Rot_a1(q_r1) @ Rot_a2(q_r2) ...``.
  The generalised coordinates are numbered in file order of the segments, translations before
  rotations within a segment.
* ``ranges``/``rangesQ`` (and ``rangesQdot``/``rangesQddot``) read two numbers per DoF declared
  *before* them; any other unknown token inside a segment is ignored (so the bare inertia numbers
  after ``mass`` in the scapula and the ``ranges`` of the DoF-less ``radius_rotation3`` segment are
  skipped, as biorbd skips them).
* A parent name that is not a segment (here ``ground``) is the world frame (biorbd falls back to
  the RBDL root for an unknown parent).
* ``marker NAME ... endmarker``: ``parent SEG`` and ``position x y z``, the position in the parent
  segment's frame (metres). ``variables ... endvariables`` defines ``$name value``; numbers may be
  ``$name``, ``pi`` or a plain arithmetic expression of those.
* Blocks this script does not need (musclegroup, muscle, viapoint, imu, customrt, contact, ...)
  are skipped up to their ``end<tag>``; ``mesh``/``meshfile``/``com``/``mass``/``inertia`` are read
  past but not kept.

Run: ``.venv/bin/python models/sources/biomod_markers.py [path.bioMod]`` from the project root;
it prints the tables and writes ``models/sources/biomod_markers.json`` next to this file.
"""
from __future__ import annotations

import ast
import itertools
import json
import math
import operator
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PROJECT = HERE.parents[1]
SHARED = PROJECT.parent / "shared"
DEFAULT_BIOMOD = SHARED / "data" / "models" / "bioptim_exo_wu_converted_definitif.bioMod"
STATIC_TRIALS = {
    "martin_statique": SHARED / "data" / "c3d" / "bioptim_exo_martin_statique.c3d",
    "kinova_martin_statique": SHARED / "data" / "c3d" / "bioptim_exo_kinova_martin_statique.c3d",
}
# A movement trial of another subject, used only as a contrast for "is the bioMod this subject?".
CONTRAST_TRIALS = {
    "F0_boire_05 (movement, other subject)": SHARED / "data" / "c3d" / "bioptim_exo_F0_boire_05.c3d",
}
OUT_JSON = HERE / "biomod_markers.json"

SOURCE = (
    "Ipuch/bioptim_exo @ b4a33b4e79753059725c9ffee5c7749a6cf87858, "
    "models/wu_converted_definitif.bioMod (shared copy: "
    "../shared/data/models/bioptim_exo_wu_converted_definitif.bioMod), MIT licence, "
    "Copyright (c) 2022 Pierre. Numbers only; read by exubio's models/sources/biomod_markers.py."
)

MARKER_SET = (
    "MAN", "XYP", "C7", "T10", "CLAV_SC", "CLAV_AC", "SCAP_Cor", "SCAP_AA", "SCAP_AC", "SCAP_IA",
    "SCAP_BACK", "SCAP_FRONT", "ARM", "DELT", "EPI_lat", "EPI_med", "ELB", "ULNA", "RADIUS", "MET2",
    "MET5", "SEML",
)
WORLD_NAMES = ("root", "ground", "base")

# Origins of the true segments read as joint centres (name of the joint, segment whose origin it is).
JOINT_CENTRES = (
    ("SC (sternoclavicular)", "clavicle"),
    ("AC (acromioclavicular, scapula origin)", "scapula"),
    ("GH (glenohumeral)", "humerus"),
    ("elbow (humero-ulnar, ulna origin)", "ulna"),
    ("proximal radio-ulnar (radius origin)", "radius"),
    ("wrist (hand origin)", "hand_r"),
)


# ---------------------------------------------------------------------------------------------
# Model
# ---------------------------------------------------------------------------------------------
@dataclass
class Segment:
    name: str
    parent: str | None          # None: the world
    rt: np.ndarray              # 4x4, in the parent's frame
    translations: str = ""
    rotations: str = ""
    has_mass: bool = False      # a "true" segment (carries inertia)
    q_index: int = 0            # index of its first generalised coordinate

    @property
    def ndof(self) -> int:
        return len(self.translations) + len(self.rotations)


@dataclass
class Marker:
    name: str
    parent: str
    position: np.ndarray        # (3,), metres, in the parent's frame


@dataclass
class BioModel:
    version: int
    segments: dict[str, Segment] = field(default_factory=dict)   # file order
    markers: dict[str, Marker] = field(default_factory=dict)     # file order
    gravity: np.ndarray | None = None

    @property
    def nq(self) -> int:
        return sum(s.ndof for s in self.segments.values())

    @property
    def dof_names(self) -> list[str]:
        names = []
        for s in self.segments.values():
            names += [f"{s.name}:Trans{c.upper()}" for c in s.translations]
            names += [f"{s.name}:Rot{c.upper()}" for c in s.rotations]
        return names

    @property
    def true_segments(self) -> list[str]:
        return [n for n, s in self.segments.items() if s.has_mass]


# ---------------------------------------------------------------------------------------------
# Reader
# ---------------------------------------------------------------------------------------------
def _scan(text: str):
    """(token, block_number) pairs: block_number is None for model tokens, else the index of the
    ``/* ... */`` comment the token is in. Line comments are dropped (biorbd's IfStream::read: a
    token beginning with ``//`` discards the rest of its line; a token beginning with ``/*`` opens a
    comment closed by the next token beginning or ending with ``*/``)."""
    block, n_blocks = None, 0
    for line in text.splitlines():
        for tok in line.split():
            if block is not None:
                if tok.startswith("*/") or tok.endswith("*/"):
                    inner = tok[:-2] if tok.endswith("*/") else ""
                    if inner and not inner.startswith("*/"):
                        yield inner, block
                    block = None
                else:
                    yield tok, block
                continue
            if tok.startswith("//"):
                break
            if tok.startswith("/*"):
                block, n_blocks = n_blocks, n_blocks + 1
                if tok[2:]:
                    yield tok[2:], block
                continue
            yield tok, None


def tokenize(text: str) -> list[str]:
    """The model's whitespace tokens, comments removed (see the module docstring)."""
    return [tok for tok, block in _scan(text) if block is None]


def block_comments(text: str) -> list[list[str]]:
    """The tokens of each ``/* ... */`` comment."""
    blocks: dict[int, list[str]] = {}
    for tok, block in _scan(text):
        if block is not None:
            blocks.setdefault(block, []).append(tok)
    return [blocks[k] for k in sorted(blocks)]


_BINOPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: operator.pow}
_UNOPS = {ast.USub: operator.neg, ast.UAdd: operator.pos}


def _evaluate(expr: str, variables: dict[str, float]) -> float:
    """A number, ``pi``, a ``$variable`` or +-*/^ arithmetic of those (biorbd's Equation subset)."""
    try:
        return float(expr)
    except ValueError:
        pass
    src = expr.replace("^", "**")
    for name in sorted(variables, key=len, reverse=True):
        src = src.replace(name, f"({variables[name]!r})")
    tree = ast.parse(src, mode="eval")

    def ev(node):
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return float(node.value)
        if isinstance(node, ast.Name) and node.id.lower() == "pi":
            return math.pi
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return _BINOPS[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _UNOPS:
            return _UNOPS[type(node.op)](ev(node.operand))
        raise ValueError(f"cannot evaluate '{expr}'")

    return ev(tree)


def rotation_from_angles(angles, seq: str) -> np.ndarray:
    """biorbd's Rotation::fromEulerAngles: R = R_seq0(a0) @ R_seq1(a1) @ ... (intrinsic)."""
    if len(angles) != len(seq):
        raise ValueError(f"{len(angles)} angles for the sequence '{seq}'")
    out = np.eye(3)
    for a, axis in zip(angles, seq.lower()):
        out = out @ elementary_rotation(axis, a)
    return out


def elementary_rotation(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)
    if axis == "z":
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)
    raise ValueError(f"rotation axis '{axis}' not recognised")


def homogeneous(rot: np.ndarray, trans) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = trans
    return out


class _Tokens:
    def __init__(self, tokens: list[str], variables: dict[str, float]):
        self.toks, self.i, self.vars = tokens, 0, variables

    def more(self) -> bool:
        return self.i < len(self.toks)

    def word(self) -> str:
        if not self.more():
            raise ValueError("unexpected end of the bioMod file")
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def number(self) -> float:
        tok = self.word()
        try:
            return _evaluate(tok, self.vars)
        except (ValueError, SyntaxError) as exc:
            raise ValueError(f"expected a number, read '{tok}' (token {self.i})") from exc

    def numbers(self, n: int) -> np.ndarray:
        return np.array([self.number() for _ in range(n)], dtype=float)

    def skip_to(self, end_tag: str) -> None:
        while self.more():
            if self.word().lower() == end_tag:
                return
        raise ValueError(f"'{end_tag}' not found")


# Tags of a segment this reader reads past: number of numeric arguments (None: one word).
_SEGMENT_SKIP = {"mass": 1, "inertia": 9, "inertiamatrix": 9, "inertia_xxyyzz": 3, "com": 3,
                 "centerofmass": 3, "mesh": 3, "patch": 3, "meshscale": 3, "meshcolor": 3,
                 "forceplate": None, "externalforceindex": None, "meshfile": None}


def parse_biomod(text: str) -> BioModel:
    """A BioModel from bioMod text (segments, markers, variables; see the module docstring)."""
    variables: dict[str, float] = {}
    t = _Tokens(tokenize(text), variables)
    version = None
    while t.more():
        tag = t.word().lower()
        if tag == "version":
            version = int(t.word())
            break
    if version is None:
        raise ValueError("no 'version' tag in the bioMod text")
    model = BioModel(version=version)
    q_index = 0
    while t.more():
        tag = t.word().lower()
        if tag == "segment":
            seg = _parse_segment(t, model, version)
            seg.q_index = q_index
            q_index += seg.ndof
            if seg.name in model.segments:
                raise ValueError(f"segment '{seg.name}' defined twice")
            model.segments[seg.name] = seg
        elif tag == "marker":
            mk = _parse_marker(t, model)
            model.markers[mk.name] = mk
        elif tag == "variables":
            while True:
                tok = t.word()
                if tok.lower() == "endvariables":
                    break
                if tok.startswith("$"):
                    if tok in variables:
                        raise ValueError(f"variable {tok} defined twice")
                    variables[tok] = t.number()
        elif tag == "gravity":
            model.gravity = t.numbers(3)
        elif tag in ("musclegroup", "muscle", "viapoint", "imu", "customrt", "contact",
                     "loopconstraint", "actuator", "softcontact", "wrapping", "ligament",
                     "passivetorque", "rangeofmotion"):
            t.skip_to("end" + tag)
        # any other token at the top level is ignored, as biorbd does
    return model


def _parse_segment(t: _Tokens, model: BioModel, version: int) -> Segment:
    name = t.word()
    parent: str | None = None
    rt = np.eye(4)
    rt_in_matrix = version < 3
    rt_set = False
    trans = rot = ""
    has_mass = False
    while True:
        tag = t.word()
        low = tag.lower()
        if low == "endsegment":
            break
        if low == "parent":
            p = t.word()
            if p in model.segments:
                parent = p
            elif p.lower() in WORLD_NAMES:
                parent = None
            else:
                raise ValueError(f"segment '{name}': parent '{p}' is not a segment defined before it")
        elif low == "rtinmatrix":
            if rt_set:
                raise ValueError(f"segment '{name}': RTinMatrix after RT")
            rt_in_matrix = int(t.word()) != 0
        elif low == "rt":
            rt = read_rt(t, rt_in_matrix)
            rt_set = True
        elif low == "translations":
            trans = t.word().lower()
        elif low == "rotations":
            rot = t.word().lower()
            if rot == "q":
                raise ValueError(f"segment '{name}': quaternion rotations are not supported")
        elif low in ("ranges", "rangesq", "rangesqdot", "rangesqddot"):
            t.numbers(2 * (len(trans) + len(rot)))
        elif low == "meshrt":
            read_rt(t, False)
        elif low in _SEGMENT_SKIP:
            n = _SEGMENT_SKIP[low]
            if n is None:
                t.word()
            else:
                t.numbers(n)
            if low == "mass":
                has_mass = True
        # anything else: ignored (biorbd ignores unknown tags inside a segment)
    for c in trans + rot:
        if c not in "xyz":
            raise ValueError(f"segment '{name}': DoF axis '{c}' not recognised")
    return Segment(name=name, parent=parent, rt=rt, translations=trans, rotations=rot, has_mass=has_mass)


def read_rt(t: _Tokens, in_matrix: bool) -> np.ndarray:
    if in_matrix:
        rt = t.numbers(16).reshape(4, 4)
    else:
        angles = t.numbers(3)
        seq = t.word().lower()
        trans = t.numbers(3)
        rt = homogeneous(rotation_from_angles(angles, seq), trans)
    r = rt[:3, :3]
    if abs(float(np.sum(r * r)) - 3.0) > 1e-4:       # biorbd's checkUnitary tolerance
        raise ValueError(f"RT rotation is not unitary (squared norm {np.sum(r * r):.6f}, expected 3)")
    return rt


def _parse_marker(t: _Tokens, model: BioModel) -> Marker:
    name = t.word()
    parent, pos = None, np.zeros(3)
    while True:
        tag = t.word().lower()
        if tag == "endmarker":
            break
        if tag == "parent":
            parent = t.word()
            if parent not in model.segments:
                raise ValueError(f"marker '{name}': parent '{parent}' is not a segment")
        elif tag == "position":
            pos = t.numbers(3)
        elif tag in ("technical", "anatomical", "axestoremove"):
            t.word()
    if parent is None:
        raise ValueError(f"marker '{name}' has no parent")
    return Marker(name=name, parent=parent, position=pos)


def load_biomod(path) -> BioModel:
    """Read a .bioMod file (see the module docstring for what is read and how)."""
    return parse_biomod(Path(path).read_text(encoding="utf-8", errors="replace"))


def commented_out_markers(path_or_text, model: BioModel) -> dict[str, Marker]:
    """Markers written inside ``/* ... */`` blocks (not part of the model biorbd builds). Takes a
    ``pathlib.Path`` or the bioMod text itself."""
    text = path_or_text.read_text(encoding="utf-8") if isinstance(path_or_text, Path) else str(path_or_text)
    out: dict[str, Marker] = {}
    for toks in block_comments(text):
        t = _Tokens(toks, {})
        while t.more():
            if t.word().lower() == "marker":
                try:
                    mk = _parse_marker(t, model)
                except ValueError:
                    break
                out[mk.name] = mk
    return out


# ---------------------------------------------------------------------------------------------
# Kinematics
# ---------------------------------------------------------------------------------------------
def local_transform(seg: Segment, q_seg) -> np.ndarray:
    """RT @ translations @ rotations (intrinsic) of one segment, its own coordinates q_seg."""
    out = seg.rt.copy()
    k = 0
    for axis in seg.translations:
        step = np.eye(4)
        step["xyz".index(axis), 3] = q_seg[k]
        out = out @ step
        k += 1
    for axis in seg.rotations:
        out = out @ homogeneous(elementary_rotation(axis, q_seg[k]), np.zeros(3))
        k += 1
    return out


def global_frames(model: BioModel, q=None) -> dict[str, np.ndarray]:
    """Every segment's 4x4 global transform at q (all zeros by default)."""
    q = np.zeros(model.nq) if q is None else np.asarray(q, dtype=float)
    if q.shape != (model.nq,):
        raise ValueError(f"q has shape {q.shape}, the model has {model.nq} coordinates")
    out: dict[str, np.ndarray] = {}
    for name, seg in model.segments.items():       # parents are defined before children
        parent = np.eye(4) if seg.parent is None else out[seg.parent]
        out[name] = parent @ local_transform(seg, q[seg.q_index: seg.q_index + seg.ndof])
    return out


def marker_positions(model: BioModel, q=None, markers: dict[str, Marker] | None = None) -> dict[str, np.ndarray]:
    """Global marker positions (m) at q (zeros by default)."""
    frames = global_frames(model, q)
    markers = model.markers if markers is None else markers
    return {n: frames[m.parent][:3, :3] @ m.position + frames[m.parent][:3, 3] for n, m in markers.items()}


def rigid_groups(model: BioModel) -> list[list[str]]:
    """True segments joined by no DoF (they move as one rigid body), in file order. A segment is
    rigid in an ancestor's frame when no segment on the way up (the ancestor excluded) has a DoF."""
    def body_root(name: str) -> str:
        root, cur = name, model.segments[name]
        while cur.ndof == 0 and cur.parent is not None:
            cur = model.segments[cur.parent]
            if cur.has_mass:
                root = cur.name
        return root

    groups: dict[str, list[str]] = {}
    for name in model.true_segments:
        groups.setdefault(body_root(name), []).append(name)
    return list(groups.values())


# ---------------------------------------------------------------------------------------------
# ISB thorax frame
# ---------------------------------------------------------------------------------------------
def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v)
    if n < 1e-12:
        raise ValueError("zero-length axis")
    return v / n


def isb_thorax_frame(ij, c7, px, t8) -> np.ndarray:
    """Wu et al. 2005 thorax frame (4x4, columns X Y Z origin): origin IJ; Y from mid(PX,T8) to
    mid(IJ,C7); Z normal to the plane IJ, C7, mid(PX,T8), pointing right; X = Y x Z (anterior)."""
    ij, c7, px, t8 = (np.asarray(p, dtype=float) for p in (ij, c7, px, t8))
    y = _unit((ij + c7) / 2 - (px + t8) / 2)
    # IJ - C7 points anterior and lies in the plane; so does Y: anterior x superior = right.
    z = _unit(np.cross(ij - c7, y))
    x = np.cross(y, z)
    return homogeneous(np.column_stack([x, y, z]), ij)


def to_frame(frame: np.ndarray, point) -> np.ndarray:
    return frame[:3, :3].T @ (np.asarray(point, dtype=float) - frame[:3, 3])


def rotation_angle_deg(r: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2))))


def angle_deg(a, b) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(_unit(a), _unit(b)))))))


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------
def _mm(v) -> list[float]:
    return [round(float(x) * 1000.0, 1) for x in v]


def _r(x, nd=1) -> float:
    return round(float(x), nd)


def analyse(model: BioModel, commented: dict[str, Marker] | None = None) -> dict:
    """Everything of the report except the trial comparison (lengths in mm)."""
    commented = commented or {}
    frames = global_frames(model)
    mk = marker_positions(model)
    thorax_iso = isb_thorax_frame(mk["MAN"], mk["C7"], mk["XYP"], mk["T10"])
    true = model.true_segments
    by_seg = {s: [n for n, m in model.markers.items() if m.parent == s] for s in true}

    res: dict = {"source": SOURCE, "units": "mm (lengths), deg (angles)"}
    res["reader_conventions"] = __doc__.split("Conventions", 1)[1].split("Run:", 1)[0].strip()
    res["model_summary"] = {
        "version": model.version,
        "segments": list(model.segments),
        "true_segments": true,
        "dof_names": model.dof_names,
        "rigid_groups_of_true_segments": rigid_groups(model),
        "markers_in_model": list(model.markers),
        "markers_commented_out": {n: m.parent for n, m in commented.items()},
        "marker_set_absent": [n for n in MARKER_SET if n not in model.markers],
    }
    # (a)
    res["a_markers_in_segment_frame"] = {s: {n: _mm(model.markers[n].position) for n in by_seg[s]} for s in true}
    res["a_commented_out_markers_in_segment_frame"] = {
        n: {"segment": m.parent, "position": _mm(m.position)} for n, m in commented.items()
    }
    # (b)
    res["b_isb_thorax_frame_global"] = {
        "definition": "Wu et al. 2005 from the model's markers at q = 0: IJ = MAN, PX = XYP, C7 = C7, "
                      "T8 stand-in = T10; origin MAN; Y = unit(mid(MAN,C7) - mid(XYP,T10)); Z normal to "
                      "the plane MAN, C7, mid(XYP,T10), pointing right; X = Y x Z",
        "origin": _mm(thorax_iso[:3, 3]),
        "x_axis": [_r(v, 4) for v in thorax_iso[:3, 0]],
        "y_axis": [_r(v, 4) for v in thorax_iso[:3, 1]],
        "z_axis": [_r(v, 4) for v in thorax_iso[:3, 2]],
    }
    seg_frames = {}
    for s in true:
        f = np.linalg.inv(thorax_iso) @ frames[s]
        seg_frames[s] = {
            "origin": _mm(f[:3, 3]),
            "x_axis": [_r(v, 4) for v in f[:3, 0]],
            "y_axis": [_r(v, 4) for v in f[:3, 1]],
            "z_axis": [_r(v, 4) for v in f[:3, 2]],
            "rotation_from_isb_thorax_deg": _r(rotation_angle_deg(f[:3, :3])),
        }
    res["b_true_segment_frames_q0_in_isb_thorax"] = seg_frames
    res["b_markers_q0_in_isb_thorax"] = {n: _mm(to_frame(thorax_iso, p)) for n, p in mk.items()}
    if commented:
        res["b_commented_out_markers_q0_in_isb_thorax"] = {
            n: _mm(to_frame(thorax_iso, p)) for n, p in marker_positions(model, None, commented).items()
        }
    # (c)
    jc = {}
    for label, seg in JOINT_CENTRES:
        if seg in frames:
            jc[label] = _mm(to_frame(thorax_iso, frames[seg][:3, 3]))
    res["c_joint_centres_q0_in_isb_thorax"] = jc
    axes = {}
    for name, seg in model.segments.items():
        if not seg.rotations:
            continue
        parent = np.eye(4) if seg.parent is None else frames[seg.parent]
        running = parent @ seg.rt              # translations do not turn the frame; q = 0 here
        for a in seg.rotations:
            axis_global = running[:3, "xyz".index(a)]
            axes[f"{name}:Rot{a.upper()}"] = [_r(v, 4) for v in thorax_iso[:3, :3].T @ axis_global]
    res["c_rotation_axes_q0_in_isb_thorax"] = axes
    res["c_joint_centre_distances"] = _joint_centre_distances(frames)
    # (d)
    res["d_frame_assessment"] = d = _assess_frames(model, frames, mk, thorax_iso)
    if {"thorax", "humerus", "clavicle", "scapula", "ulna"} <= set(d):
        res["d_conclusion"] = (
            "At q = 0 every true segment's frame is parallel to the model's thorax frame (each is "
            f"{max(v['rotation_from_isb_thorax_deg'] for v in seg_frames.values()):.1f} deg "
            "from the ISB thorax, as the thorax frame itself): the OpenSim convention of the source model, whose "
            "'reset_axis' segments cancel the joint-axis bases. So no frame is a Wu et al. 2005 "
            "anatomical frame by construction. Close to it: the thorax frame is "
            f"{d['thorax']['angle_thorax_frame_vs_isb_thorax_deg']} deg from the marker-built ISB thorax "
            f"(origin {d['thorax']['origin_to_MAN_mm']} mm from MAN, posterior); the humerus has its origin at "
            f"GH and its Y axis {d['humerus']['angle_Y_vs_mid(EPI_lat,EPI_med)_to_GH_deg']} deg from "
            "mid-epicondyles-to-GH (Wu's Y), but its Z is "
            f"{d['humerus']['angle_Z_vs_EPI_med_to_EPI_lat_deg']} deg from the epicondyle line (Wu's frame is "
            "this one turned about Y). The clavicle origin is the SC joint (Wu's origin) but its Z is "
            f"{d['clavicle']['angle_Z_vs_SC_to_AC_joint_deg']} deg from SC-to-AC; the scapula origin is the "
            "model's AC joint, not AA; the ulna/radius/hand origins are the elbow, the radial head region "
            "and the wrist, with Y "
            f"{d['ulna']['angle_Y_vs_wrist_to_elbow_joint_deg']} deg from the wrist-to-elbow line (carrying angle)."
        )
    # (e)
    within, to_origin = {}, {}
    for s in true:
        names = by_seg[s]
        within[s] = {f"{a}-{b}": _r(1000 * np.linalg.norm(model.markers[a].position - model.markers[b].position))
                     for a, b in itertools.combinations(names, 2)}
        to_origin[s] = {n: _r(1000 * np.linalg.norm(model.markers[n].position)) for n in names}
    res["e_distances_within_segment"] = within
    res["e_distances_to_segment_origin"] = to_origin
    res["e_distances_within_rigid_group"] = {
        "+".join(g): _pair_distances({n: mk[n] for s in g for n in by_seg[s]})
        for g in rigid_groups(model) if len(g) > 1
    }
    if commented:
        res["e_commented_out_markers_distances"] = {
            n: {o: _r(1000 * np.linalg.norm(m.position - model.markers[o].position))
                for o in by_seg.get(m.parent, [])}
            for n, m in commented.items()
        }
    return res


def _pair_distances(points: dict[str, np.ndarray]) -> dict[str, float]:
    return {f"{a}-{b}": _r(1000 * np.linalg.norm(points[a] - points[b]))
            for a, b in itertools.combinations(points, 2)}


def _joint_centre_distances(frames) -> dict[str, float]:
    pairs = [("clavicle", "scapula", "SC-AC"), ("scapula", "humerus", "AC-GH"),
             ("clavicle", "humerus", "SC-GH"), ("humerus", "ulna", "GH-elbow (humerus length)"),
             ("ulna", "radius", "elbow-radius origin"), ("radius", "hand_r", "radius origin-wrist"),
             ("ulna", "hand_r", "elbow-wrist (forearm length)")]
    return {label: _r(1000 * np.linalg.norm(frames[a][:3, 3] - frames[b][:3, 3]))
            for a, b, label in pairs if a in frames and b in frames}


def _assess_frames(model, frames, mk, thorax_iso) -> dict:
    """Compare each true segment's frame at q = 0 with the Wu et al. 2005 definitions, as far as
    the model's own joint centres and markers allow (skin markers stand in for bony landmarks)."""
    out = {}
    R = {s: frames[s][:3, :3] for s in model.true_segments}
    o = {s: frames[s][:3, 3] for s in model.true_segments}
    if "thorax" in R:
        out["thorax"] = {
            "angle_thorax_frame_vs_isb_thorax_deg": _r(rotation_angle_deg(thorax_iso[:3, :3].T @ R["thorax"])),
            "angle_Y_vs_isb_Y_deg": _r(angle_deg(R["thorax"][:, 1], thorax_iso[:3, 1])),
            "angle_X_vs_isb_X_deg": _r(angle_deg(R["thorax"][:, 0], thorax_iso[:3, 0])),
            "angle_Z_vs_isb_Z_deg": _r(angle_deg(R["thorax"][:, 2], thorax_iso[:3, 2])),
            "origin_to_MAN_mm": _r(1000 * np.linalg.norm(o["thorax"] - mk["MAN"])),
            "origin_in_isb_thorax_mm": _mm(to_frame(thorax_iso, o["thorax"])),
        }
    if "clavicle" in R and "scapula" in R:
        sc_ac = o["scapula"] - o["clavicle"]
        out["clavicle"] = {
            "isb_definition": "origin SC; Z from SC to AC; X perpendicular to Z and thorax Y, anterior",
            "origin_is_SC_joint": True,
            "angle_Z_vs_SC_to_AC_joint_deg": _r(angle_deg(R["clavicle"][:, 2], sc_ac)),
            "angle_Z_vs_CLAV_SC_to_CLAV_AC_deg": _r(angle_deg(R["clavicle"][:, 2], mk["CLAV_AC"] - mk["CLAV_SC"])),
            "angle_X_vs_isb_X_(X = thorax_Y x Z)_deg": _r(angle_deg(R["clavicle"][:, 0],
                                                                   np.cross(thorax_iso[:3, 1], _unit(sc_ac)))),
        }
    if "scapula" in R:
        out["scapula"] = {
            "isb_definition": "origin AA; Z from TS to AA; X normal to the plane AI, AA, TS, anterior; "
                              "Y = Z x X",
            "origin": "the AC joint of the model (scapula_parent_offset), not AA",
            "origin_to_SCAP_AC_marker_mm": _r(1000 * np.linalg.norm(o["scapula"] - mk["SCAP_AC"])),
            "angle_scapula_frame_vs_clavicle_frame_deg": _r(rotation_angle_deg(R["clavicle"].T @ R["scapula"]), 2),
            "note": "SCAP_AC, SCAP_BACK and SCAP_FRONT keep their distances within 0.1-0.3 mm (SD) "
                    "through movement trials: a rigid acromion cluster, not landmarks; only SCAP_IA "
                    "(about AI) is a Wu landmark, so Wu's scapula frame cannot be built from the "
                    "model's markers",
        }
    if "humerus" in R and "ulna" in R:
        ejc = o["ulna"]
        epi_mid = (mk["EPI_lat"] + mk["EPI_med"]) / 2
        out["humerus"] = {
            "isb_definition": "origin GH; Y from mid(EL,EM) to GH; X normal to the plane EL, EM, GH, "
                              "anterior; Z = X x Y (right, lateral)",
            "origin_is_GH_joint": True,
            "angle_Y_vs_elbow_joint_to_GH_deg": _r(angle_deg(R["humerus"][:, 1], o["humerus"] - ejc)),
            "angle_Y_vs_mid(EPI_lat,EPI_med)_to_GH_deg": _r(angle_deg(R["humerus"][:, 1], o["humerus"] - epi_mid)),
            "angle_Z_vs_EPI_med_to_EPI_lat_deg": _r(angle_deg(R["humerus"][:, 2], mk["EPI_lat"] - mk["EPI_med"])),
            "angle_X_vs_normal(EPI_lat,EPI_med,GH)_anterior_deg": _r(angle_deg(
                R["humerus"][:, 0], np.cross(o["humerus"] - epi_mid, mk["EPI_lat"] - mk["EPI_med"]))),
            "angle_humerus_frame_vs_isb_thorax_deg": _r(rotation_angle_deg(thorax_iso[:3, :3].T @ R["humerus"])),
        }
        if "ulna_elbow_flexion" in frames and "ulna_elbow_flexion" in model.segments:
            seg = model.segments["ulna_elbow_flexion"]
            axis = (frames[seg.parent] @ seg.rt)[:3, "xyz".index(seg.rotations[0])]
            out["humerus"]["angle_elbow_flexion_axis_vs_EPI_med_to_EPI_lat_deg"] = _r(
                angle_deg(axis, mk["EPI_lat"] - mk["EPI_med"]))
    if "ulna" in R and "hand_r" in R:
        out["ulna"] = {
            "isb_definition (forearm)": "origin US; Y from US to mid(EL,EM); X normal to the plane US, RS, "
                                        "mid(EL,EM), anterior; Z = X x Y",
            "angle_Y_vs_wrist_to_elbow_joint_deg": _r(angle_deg(R["ulna"][:, 1], o["ulna"] - o["hand_r"])),
            "angle_ulna_frame_vs_humerus_frame_deg": _r(rotation_angle_deg(R["humerus"].T @ R["ulna"])),
        }
    if "radius_pro_sup" in model.segments and "radius" in R:
        seg = model.segments["radius_pro_sup"]
        axis = (frames[seg.parent] @ seg.rt)[:3, "xyz".index(seg.rotations[0])]
        out["pronation_axis"] = {
            "angle_vs_ULNA_marker_to_radius_origin_deg": _r(angle_deg(axis, o["radius"] - mk["ULNA"])),
            "angle_vs_wrist_to_radius_origin_deg": _r(angle_deg(axis, o["radius"] - o["hand_r"])),
        }
    if "radius" in R and "hand_r" in R:
        out["radius"] = {
            "angle_Y_vs_wrist_to_radius_origin_deg": _r(angle_deg(R["radius"][:, 1], o["radius"] - o["hand_r"])),
            "angle_radius_frame_vs_ulna_frame_deg": _r(rotation_angle_deg(R["ulna"].T @ R["radius"])),
        }
        out["hand_r"] = {
            "angle_hand_frame_vs_radius_frame_deg": _r(rotation_angle_deg(R["radius"].T @ R["hand_r"])),
            "angle_Y_vs_mid(MET2,MET5)_to_wrist_deg": _r(angle_deg(R["hand_r"][:, 1],
                                                                   o["hand_r"] - (mk["MET2"] + mk["MET5"]) / 2)),
        }
    out["posture_q0"] = _posture(frames, mk, thorax_iso)
    return out


def _posture(frames, mk, thorax_iso) -> dict:
    """The model's q = 0 posture in the ISB thorax frame (arm, elbow, forearm, hand)."""
    def iso(v):
        return thorax_iso[:3, :3].T @ v

    out = {}
    if {"humerus", "ulna"} <= set(frames):
        arm = iso(frames["ulna"][:3, 3] - frames["humerus"][:3, 3])
        out["humerus_GH_to_elbow_angle_from_minus_Y_deg"] = _r(angle_deg(arm, [0, -1, 0]))
    if {"humerus", "ulna", "hand_r"} <= set(frames):
        arm = frames["ulna"][:3, 3] - frames["humerus"][:3, 3]
        fore = frames["hand_r"][:3, 3] - frames["ulna"][:3, 3]
        out["elbow_angle_between_upper_arm_and_forearm_deg"] = _r(angle_deg(arm, fore))
        f = iso(fore)
        out["forearm_lateral_deviation_(carrying)_deg"] = _r(math.degrees(math.atan2(f[2], -f[1])))
    if {"MET2", "MET5"} <= set(mk):
        v = iso(mk["MET2"] - mk["MET5"])
        out["MET5_to_MET2_in_transverse_plane_deg_from_+Z_toward_+X"] = _r(math.degrees(math.atan2(v[0], v[2])))
    if {"ULNA", "RADIUS"} <= set(mk):
        v = iso(mk["RADIUS"] - mk["ULNA"])
        out["ULNA_to_RADIUS_in_transverse_plane_deg_from_+Z_toward_+X"] = _r(math.degrees(math.atan2(v[0], v[2])))
    out["note"] = ("0 deg for the two transverse-plane directions is the anatomical position (palm "
                   "forward: MET2 and RADIUS lateral); 90 deg is thumb forward (neutral forearm)")
    return out


# ---------------------------------------------------------------------------------------------
# Comparison with static trials
# ---------------------------------------------------------------------------------------------
def compare_with_trial(model: BioModel, trial_path, commented: dict[str, Marker] | None = None,
                       swap: dict[str, str] | None = None) -> dict:
    """Per rigid group of the model: every marker pair's distance in the trial (mean and SD over the
    frames where both are present) against the model's. ``swap`` relabels trial markers first."""
    sys.path.insert(0, str(PROJECT))
    from exubio.io.trial import read_trial

    traj = read_trial(trial_path)
    labels = [swap.get(l, l) if swap else l for l in traj.labels]
    pos = {l: traj.positions_m[:, i, :] for i, l in enumerate(labels)}
    mk = marker_positions(model)
    all_model = dict(model.markers)
    if commented:
        for n, m in commented.items():
            all_model.setdefault(n, m)
        mk.update({n: p for n, p in marker_positions(model, None, commented).items() if n not in mk})
    # rigid groups: marker -> group
    group_of_seg = {}
    for g in rigid_groups(model):
        for s in g:
            group_of_seg[s] = "+".join(g)
    groups: dict[str, list[str]] = {}
    for n, m in all_model.items():
        groups.setdefault(group_of_seg.get(m.parent, m.parent), []).append(n)
    out = {"file": str(trial_path), "units_in_file": traj.units_in_file, "n_frames": int(traj.positions_m.shape[0]),
           "labels": list(traj.labels), "relabel": swap or {}, "groups": {}}
    for g, names in groups.items():
        rows = {}
        for a, b in itertools.combinations(names, 2):
            d_model = 1000 * float(np.linalg.norm(mk[a] - mk[b]))
            row = {"model": _r(d_model),
                   "model_marker_commented_out": bool(commented and (a in commented or b in commented))}
            if a in pos and b in pos:
                d = 1000 * np.linalg.norm(pos[a] - pos[b], axis=1)
                d = d[np.isfinite(d)]
                if d.size:
                    row.update(trial_mean=_r(np.mean(d)), trial_sd=_r(np.std(d)),
                               diff=_r(np.mean(d) - d_model))
            rows[f"{a}-{b}"] = row
        out["groups"][g] = rows
    diffs = [abs(r["diff"]) for g in out["groups"].values() for r in g.values()
             if "diff" in r and not r["model_marker_commented_out"]]
    out["summary"] = {"n_pairs": len(diffs),
                      "mean_abs_diff_mm": _r(np.mean(diffs)) if diffs else None,
                      "median_abs_diff_mm": _r(np.median(diffs)) if diffs else None,
                      "max_abs_diff_mm": _r(np.max(diffs)) if diffs else None}
    return out


# ---------------------------------------------------------------------------------------------
# Printing
# ---------------------------------------------------------------------------------------------
def _fmt3(v) -> str:
    return "[" + ", ".join(f"{x:8.1f}" for x in v) + "]"


def print_report(res: dict) -> None:
    p = print
    p(f"source: {res['source']}\n")
    ms = res["model_summary"]
    p(f"bioMod version {ms['version']}, {len(ms['segments'])} segments, {len(ms['dof_names'])} coordinates")
    p(f"true segments: {', '.join(ms['true_segments'])}")
    p(f"rigid groups (no DoF between): {ms['rigid_groups_of_true_segments']}")
    p(f"markers in the model ({len(ms['markers_in_model'])}): {', '.join(ms['markers_in_model'])}")
    p(f"commented out in the file: {ms['markers_commented_out']}")
    p(f"of the marker set, absent from the model: {ms['marker_set_absent']}\n")

    p("(a) markers in their own segment's frame (mm)")
    for s, d in res["a_markers_in_segment_frame"].items():
        for n, v in d.items():
            p(f"  {s:9s} {n:11s} {_fmt3(v)}")
    for n, d in res["a_commented_out_markers_in_segment_frame"].items():
        p(f"  {d['segment']:9s} {n:11s} {_fmt3(d['position'])}   (commented out)")

    f = res["b_isb_thorax_frame_global"]
    p("\n(b) ISB thorax frame in the model's global frame at q = 0: origin "
      f"{_fmt3(f['origin'])} mm, X {f['x_axis']}, Y {f['y_axis']}, Z {f['z_axis']}")
    p("    true segment frames at q = 0 in the ISB thorax frame (origin mm; axes unit vectors)")
    for s, d in res["b_true_segment_frames_q0_in_isb_thorax"].items():
        p(f"  {s:9s} origin {_fmt3(d['origin'])}  X {d['x_axis']}  Y {d['y_axis']}  Z {d['z_axis']}"
          f"  rot from thorax {d['rotation_from_isb_thorax_deg']} deg")
    p("    markers at q = 0 in the ISB thorax frame (mm)")
    for n, v in res["b_markers_q0_in_isb_thorax"].items():
        p(f"  {n:11s} {_fmt3(v)}")
    for n, v in res.get("b_commented_out_markers_q0_in_isb_thorax", {}).items():
        p(f"  {n:11s} {_fmt3(v)}   (commented out)")

    p("\n(c) joint centres (segment origins) at q = 0 in the ISB thorax frame (mm)")
    for n, v in res["c_joint_centres_q0_in_isb_thorax"].items():
        p(f"  {n:40s} {_fmt3(v)}")
    for n, v in res["c_joint_centre_distances"].items():
        p(f"  |{n}| = {v} mm")
    p("    rotation DoF axes at q = 0 in the ISB thorax frame")
    for n, v in res["c_rotation_axes_q0_in_isb_thorax"].items():
        p(f"  {n:40s} {v}")

    p("\n(d) segment frames against Wu et al. 2005")
    for s, d in res["d_frame_assessment"].items():
        p(f"  {s}:")
        for k, v in d.items():
            p(f"      {k}: {v}")
    if "d_conclusion" in res:
        p(f"  conclusion: {res['d_conclusion']}")

    p("\n(e) distances within each segment (mm)")
    for s, d in res["e_distances_within_segment"].items():
        if d:
            p(f"  {s}: " + ", ".join(f"{k} {v}" for k, v in d.items()))
    p("    marker to segment origin (mm)")
    for s, d in res["e_distances_to_segment_origin"].items():
        p(f"  {s}: " + ", ".join(f"{k} {v}" for k, v in d.items()))
    for g, d in res["e_distances_within_rigid_group"].items():
        p(f"  rigid group {g}: " + ", ".join(f"{k} {v}" for k, v in d.items()))
    for n, d in res.get("e_commented_out_markers_distances", {}).items():
        p(f"  commented-out {n} to its segment's markers: " + ", ".join(f"{k} {v}" for k, v in d.items()))

    for name, cmp in res.get("trial_comparison", {}).items():
        p(f"\nTrial {name}: {cmp['n_frames']} frames, file units {cmp['units_in_file']}, relabel {cmp['relabel']}")
        p(f"  {'pair':24s} {'bioMod':>7s} {'trial':>7s} {'SD':>5s} {'diff':>7s}")
        for g, rows in cmp["groups"].items():
            p(f"  [{g}]")
            for k, r in rows.items():
                flag = " (model marker commented out)" if r["model_marker_commented_out"] else ""
                if "trial_mean" in r:
                    p(f"  {k:24s} {r['model']:7.1f} {r['trial_mean']:7.1f} {r['trial_sd']:5.1f} {r['diff']:+7.1f}{flag}")
                else:
                    p(f"  {k:24s} {r['model']:7.1f}     (not in trial){flag}")
        p(f"  summary (pairs with both markers in the model): {cmp['summary']}")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else DEFAULT_BIOMOD
    model = load_biomod(path)
    commented = commented_out_markers(path, model)
    res = analyse(model, commented)
    res["trial_comparison"] = {}
    trials = dict(STATIC_TRIALS)
    trials.update(CONTRAST_TRIALS)
    for name, tp in trials.items():
        if not tp.is_file():
            continue
        res["trial_comparison"][name] = compare_with_trial(model, tp, commented)
        if name.startswith("kinova"):
            # the session protocol protocols/examples/kinova_martin_session.yaml reads these two swapped
            res["trial_comparison"][name + " (RADIUS<->ULNA swapped)"] = compare_with_trial(
                model, tp, commented, swap={"RADIUS": "ULNA", "ULNA": "RADIUS"})
    print_report(res)
    OUT_JSON.write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    print(f"\nwritten {OUT_JSON}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
