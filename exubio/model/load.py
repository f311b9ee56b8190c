"""Model YAML -> Model: segments, joints, inertia from anthropometric tables, the thorax ellipsoid.

The file format is documented at the top of ``models/upper_extremity.yaml``. Positions in the file
are millimetres in the ISB thorax frame, in the model's reference posture (all coordinates zero);
here they become metres, local to each segment (segment frames sit at their origin point and are
parallel to the thorax frame in the reference posture).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from exubio.model.anatomy import isb_frame
from exubio.io.yaml import check_keys as _check_keys
from exubio.io.yaml import finite_float, read_yaml
from exubio.io.resources import resolve, shipped_file
from exubio.errors import ModelError
from exubio.types import Ellipsoid, Joint, JointKind, Model, Segment

SCHEMA_VERSION = 1
DEFAULT_MODEL = shipped_file("exubio.models", "upper_extremity.yaml", "models")

_TOP_KEYS = {"schema_version", "name", "side", "body_mass_kg", "segments", "ellipsoid", "calibration"}
_SEGMENT_KEYS = {"name", "parent", "origin", "joint", "inertia", "points_mm"}
_JOINT_KEYS = {"name", "type", "coordinates", "axes_frame"}
_AXES_FRAMES = ("isb",)
_COORD_KEYS = {"name", "axis", "range_deg"}
_INERTIA_KEYS = {
    "mass_fraction",
    "com_between",
    "com_fraction",
    "com_mm",
    "principal_kgm2_per_kg",
    "inertia_kgm2_per_kg",
    "radius_of_gyration_fraction",
    "axial_radius_of_gyration_fraction",
    "long_axis",
}
_ELLIPSOID_KEYS = {"centre_mm", "radii_mm", "contact_points"}
_NAMED_AXES = {
    "+X": (1.0, 0.0, 0.0), "-X": (-1.0, 0.0, 0.0),
    "+Y": (0.0, 1.0, 0.0), "-Y": (0.0, -1.0, 0.0),
    "+Z": (0.0, 0.0, 1.0), "-Z": (0.0, 0.0, -1.0),
}  # fmt: skip


def check_keys(mapping: Any, allowed: set[str], where: str, *, error: type[Exception], required: set[str] = frozenset()) -> None:
    """Unknown keys (see exubio.io.yaml.check_keys), plus: must be a mapping with the required keys."""
    if not isinstance(mapping, Mapping):
        raise error(f"{where}: expected a mapping, got {type(mapping).__name__}")
    _check_keys(mapping, sorted(allowed), where="", source=where, error=error)
    missing = sorted(required - set(mapping))
    if missing:
        raise error(f"{where}: missing required key(s) {missing}")


def _number(value: Any, where: str, *, positive: bool = False) -> float:
    """A finite number from a YAML value (True/False are not numbers); ModelError naming the key."""
    number = finite_float(value)
    if number is None or (positive and not number > 0):
        raise ModelError(f"{where}: expected a finite number{' > 0' if positive else ''}, got {value!r}")
    return number


def _vec3(value: Any, where: str, *, positive: bool = False) -> np.ndarray:
    numbers = [finite_float(v) for v in value] if isinstance(value, (list, tuple)) else []
    if len(numbers) != 3 or None in numbers or (positive and not all(x > 0 for x in numbers)):
        raise ModelError(f"{where}: expected three finite numbers{' > 0' if positive else ''}, got {value!r}")
    return np.array(numbers)


def _point_pair(value: Any, where: str) -> tuple[str, str]:
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(v, str) for v in value)):
        raise ModelError(f"{where}: expected two point names [A, B], got {value!r}")
    return value[0], value[1]


def load_model(path: str | Path = DEFAULT_MODEL, /, *, body_mass_kg: float | None = None) -> Model:
    """Read a model YAML: a path, or the name of a shipped model ("upper_extremity").
    ``body_mass_kg`` overrides the file's body mass (inertia scales)."""
    path = resolve(path, "exubio.models", "models", "upper_extremity.yaml")
    return model_from_mapping(read_yaml(path, error=ModelError), str(path), name=path.stem, body_mass_kg=body_mass_kg)


def model_from_mapping(data: Any, src: str, /, *, name: str, body_mass_kg: float | None = None) -> Model:
    """The Model a model YAML's mapping describes (``src``: where it came from, named in errors and
    kept as ``Model.source``; ``name``: the model's name when the mapping has none)."""
    check_keys(data, _TOP_KEYS, src, error=ModelError, required={"schema_version", "segments", "ellipsoid"})
    if isinstance(data["schema_version"], bool) or data["schema_version"] != SCHEMA_VERSION:
        raise ModelError(f"{src}: schema_version {data['schema_version']!r} is not supported (expected {SCHEMA_VERSION})")
    if body_mass_kg is not None:
        mass = _number(body_mass_kg, "--body-mass (kg)", positive=True)
    else:
        mass = _number(data.get("body_mass_kg", 75.0), f"{src}: body_mass_kg", positive=True)

    raw_segments = data["segments"]
    if not isinstance(raw_segments, list) or not raw_segments:
        raise ModelError(f"{src}: 'segments' must be a non-empty list")

    # Global reference-posture positions of every named point, per segment (m).
    global_points: dict[str, dict[str, np.ndarray]] = {}
    for i, raw in enumerate(raw_segments):
        where = f"{src}: segments[{i}]"
        check_keys(raw, _SEGMENT_KEYS, where, error=ModelError, required={"name"})
        pts = raw.get("points_mm", {}) or {}
        if not isinstance(pts, Mapping):
            raise ModelError(f"{where}.points_mm: expected a mapping of name -> [x, y, z]")
        global_points[raw["name"]] = {k: _vec3(v, f"{where}.points_mm.{k}") / 1000.0 for k, v in pts.items()}

    def find_point(name: str, where: str, prefer: str | None = None) -> np.ndarray:
        if prefer is not None and name in global_points.get(prefer, {}):
            return global_points[prefer][name]
        for pts in global_points.values():
            if name in pts:
                return pts[name]
        known = sorted({p for pts in global_points.values() for p in pts})
        raise ModelError(f"{where}: unknown point '{name}'; known points are {known}")

    segments: list[Segment] = []
    origins: dict[str, np.ndarray] = {}
    for i, raw in enumerate(raw_segments):
        name = raw["name"]
        where = f"{src}: segment '{name}'"
        parent = raw.get("parent")
        if parent is None:
            origin = np.zeros(3)
            joint = None
            if i != 0:
                raise ModelError(f"{where}: only the first segment (the fixed thorax) may have no parent")
        else:
            if parent not in origins:
                raise ModelError(f"{where}: parent '{parent}' must be defined before it; defined: {sorted(origins)}")
            if "origin" not in raw or "joint" not in raw:
                raise ModelError(f"{where}: a moving segment needs 'origin' and 'joint'")
            origin = find_point(raw["origin"], f"{where}.origin", prefer=name)
            joint = _parse_joint(raw["joint"], f"{where}.joint", centre=origin - origins[parent], find_point=find_point,
                                 frame_of=lambda w, name=name: _segment_isb_frame(name, global_points[name], w))
        origins[name] = origin
        local_points = {k: v - origin for k, v in global_points[name].items()}
        m, com, inertia = _parse_inertia(raw.get("inertia"), f"{where}.inertia", mass, origin, find_point)
        segments.append(Segment(name=name, parent=parent, joint=joint, mass_kg=m, com_m=com,
                                inertia_kgm2=inertia, points=local_points))

    _check_unique_names(raw_segments, segments, src)
    ell = data["ellipsoid"]
    check_keys(ell, _ELLIPSOID_KEYS, f"{src}: ellipsoid", error=ModelError, required=_ELLIPSOID_KEYS)
    if not isinstance(ell["contact_points"], list):
        raise ModelError(f"{src}: ellipsoid.contact_points: expected a list of [segment, point], "
                         f"got {ell['contact_points']!r}")
    contacts = []
    for j, cp in enumerate(ell["contact_points"]):
        if not (isinstance(cp, (list, tuple)) and len(cp) == 2):
            raise ModelError(f"{src}: ellipsoid.contact_points[{j}]: expected [segment, point], got {cp!r}")
        seg_name, pt_name = str(cp[0]), str(cp[1])
        seg = next((s for s in segments if s.name == seg_name), None)
        if seg is None:
            raise ModelError(f"{src}: ellipsoid.contact_points[{j}]: unknown segment '{seg_name}'; valid: {[s.name for s in segments]}")
        if pt_name not in seg.points:
            raise ModelError(f"{src}: ellipsoid.contact_points[{j}]: segment '{seg_name}' has no point '{pt_name}'; it has {sorted(seg.points)}")
        contacts.append((seg_name, pt_name))
    radii = _vec3(ell["radii_mm"], f"{src}: ellipsoid.radii_mm", positive=True) / 1000.0
    ellipsoid = Ellipsoid(centre_m=_vec3(ell["centre_mm"], f"{src}: ellipsoid.centre_mm") / 1000.0,
                          radii_m=radii, contact_points=tuple(contacts))
    if not isinstance(data.get("calibration") or {}, Mapping):
        raise ModelError(f"{src}: calibration: expected a mapping (what a calibration recorded), "
                         f"got {type(data['calibration']).__name__}")
    side = data.get("side", "right")
    if side not in ("right", "left"):
        raise ModelError(f"{src}: side: expected 'right' or 'left' (the arm the model's segments describe), "
                         f"got {side!r}")
    metadata = {"side": side, "calibration": data.get("calibration")}
    return Model(name=str(data.get("name", name)), segments=tuple(segments), ellipsoid=ellipsoid,
                 body_mass_kg=mass, source=src, metadata=metadata)


def _check_unique_names(raw_segments: list, segments: list[Segment], src: str) -> None:
    """Segment and coordinate names each name one thing: a repeated one is refused naming both
    places (the coordinates are columns of every result; a repeated name was a traceback later)."""
    seen: dict[str, str] = {}
    for i, raw in enumerate(raw_segments):
        where = f"segments[{i}].name"
        if raw["name"] in seen:
            raise ModelError(f"{src}: {where}: segment '{raw['name']}' is defined twice ({seen[raw['name']]} and "
                             f"{where}); each segment name must be unique")
        seen[raw["name"]] = where
    seen = {}
    for i, segment in enumerate(segments):
        for k, coordinate in enumerate(segment.joint.coordinates if segment.joint is not None else ()):
            where = f"segments[{i}].joint.coordinates[{k}].name"
            if coordinate in seen:
                raise ModelError(f"{src}: {where}: coordinate '{coordinate}' is named twice ({seen[coordinate]} and "
                                 f"{where}); each coordinate name must be unique")
            seen[coordinate] = where


def _segment_isb_frame(segment: str, points: Mapping[str, np.ndarray], where: str) -> np.ndarray:
    """The ISB frame of ``segment`` from its reference-posture landmarks (exubio.model.anatomy)."""
    return isb_frame(segment, points, fail=lambda msg: ModelError(f"{where}: axes_frame isb: {msg}"))


def _parse_axis(value: Any, where: str, find_point, frame: np.ndarray | None = None) -> np.ndarray:
    if isinstance(value, str):
        if value not in _NAMED_AXES:
            raise ModelError(f"{where}: unknown axis '{value}'; use one of {sorted(_NAMED_AXES)}, [x, y, z] or {{from: P, to: Q}}")
        named = np.array(_NAMED_AXES[value])
        return named if frame is None else frame @ named
    if isinstance(value, Mapping):
        check_keys(value, {"from", "to"}, where, error=ModelError, required={"from", "to"})
        vec = find_point(value["to"], where) - find_point(value["from"], where)
    else:
        vec = _vec3(value, where)
    norm = np.linalg.norm(vec)
    if norm < 1e-9:
        raise ModelError(f"{where}: axis has zero length")
    return vec / norm


def _parse_joint(raw: Any, where: str, *, centre: np.ndarray, find_point, frame_of) -> Joint:
    check_keys(raw, _JOINT_KEYS, where, error=ModelError, required=_JOINT_KEYS - {"axes_frame"})
    axes_frame = raw.get("axes_frame")
    if axes_frame is not None and axes_frame not in _AXES_FRAMES:
        raise ModelError(f"{where}.axes_frame: expected one of {list(_AXES_FRAMES)} (the segment's ISB frame, "
                         f"Wu et al. 2005, in the reference posture), got {axes_frame!r}")
    frame = None if axes_frame is None else frame_of(f"{where}.axes_frame")
    try:
        kind = JointKind(raw["type"])
    except ValueError:
        raise ModelError(f"{where}.type: unknown joint type '{raw['type']}'; valid: {[k.value for k in JointKind]}") from None
    coords = raw["coordinates"]
    if not isinstance(coords, list) or len(coords) != kind.n_coordinates:
        raise ModelError(f"{where}.coordinates: a {kind.value} joint needs {kind.n_coordinates} coordinates, got {coords!r}")
    names, axes, ranges = [], [], []
    for k, c in enumerate(coords):
        check_keys(c, _COORD_KEYS, f"{where}.coordinates[{k}]", error=ModelError, required={"name", "axis"})
        names.append(str(c["name"]))
        axes.append(_parse_axis(c["axis"], f"{where}.coordinates[{k}].axis", find_point, frame))
        ranges.append(_parse_range(c.get("range_deg"), f"{where}.coordinates[{k}].range_deg"))
    axes_arr = np.array(axes)
    for a in range(len(axes_arr) - 1):
        if abs(axes_arr[a] @ axes_arr[a + 1]) > 0.999:
            raise ModelError(f"{where}: consecutive axes {a} and {a + 1} are parallel; the sequence would be singular")
    return Joint(name=str(raw["name"]), kind=kind, coordinates=tuple(names), axes=axes_arr, centre_m=centre,
                 ranges_rad=np.radians(np.array(ranges)), axes_frame=axes_frame)


def _parse_range(value: Any, where: str) -> tuple[float, float]:
    """[lower, upper] in degrees (null for no limit on that side); absent: no limits."""
    if value is None:
        return (-np.inf, np.inf)
    ok = isinstance(value, (list, tuple)) and len(value) == 2
    if ok:
        lo, hi = (finite_float(v) for v in value)
        ok = (lo is not None or value[0] is None) and (hi is not None or value[1] is None)
        lo, hi = (-np.inf if lo is None else lo), (np.inf if hi is None else hi)
    if not ok or not lo < hi:
        raise ModelError(f"{where}: expected [lower, upper], finite degrees with lower < upper (null: no limit on "
                         f"that side), got {value!r}")
    return (lo, hi)


def _parse_inertia(raw: Any, where: str, body_mass: float, origin: np.ndarray, find_point):
    """Mass (kg), local centre of mass (m) and inertia about it (kg m^2) from table fractions."""
    if raw is None:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    check_keys(raw, _INERTIA_KEYS, where, error=ModelError, required={"mass_fraction"})
    mass = _number(raw["mass_fraction"], f"{where}.mass_fraction", positive=True) * body_mass
    if "com_mm" in raw:  # explicit centre of mass (files written by save_model)
        if "com_between" in raw or "com_fraction" in raw:
            raise ModelError(f"{where}: give either 'com_mm' or 'com_between' + 'com_fraction', not both")
        com_global = _vec3(raw["com_mm"], f"{where}.com_mm") / 1000.0
    else:
        missing = sorted({"com_between", "com_fraction"} - set(raw))
        if missing:
            raise ModelError(f"{where}: missing required key(s) {missing} (or give 'com_mm')")
        a_name, b_name = _point_pair(raw["com_between"], f"{where}.com_between")
        a, b = find_point(a_name, where), find_point(b_name, where)
        com_global = a + _number(raw["com_fraction"], f"{where}.com_fraction") * (b - a)
    if "inertia_kgm2_per_kg" in raw:  # full 3x3 about the centre of mass, per kg of segment mass
        rows = raw["inertia_kgm2_per_kg"]
        square = isinstance(rows, list) and len(rows) == 3 and all(isinstance(r, list) and len(r) == 3 for r in rows)
        values = [finite_float(x) for r in rows for x in r] if square else [None]
        tensor = np.array(values if None not in values else [np.nan] * 9, dtype=float).reshape(3, 3)
        if (not np.all(np.isfinite(tensor))
                or np.abs(tensor - tensor.T).max() > 1e-12 * max(np.abs(tensor).max(), 1e-300)
                or np.linalg.eigvalsh(tensor).min() <= 0):
            raise ModelError(f"{where}.inertia_kgm2_per_kg: expected a symmetric, positive definite 3x3 matrix of "
                             f"finite numbers, got {raw['inertia_kgm2_per_kg']!r}")
        inertia = tensor * mass
    elif "principal_kgm2_per_kg" in raw:
        inertia = np.diag(_vec3(raw["principal_kgm2_per_kg"], f"{where}.principal_kgm2_per_kg", positive=True)) * mass
    else:
        for key in ("radius_of_gyration_fraction", "axial_radius_of_gyration_fraction", "long_axis"):
            if key not in raw:
                raise ModelError(f"{where}: needs 'principal_kgm2_per_kg' or '{key}'")
        p, d = (find_point(n, where) for n in _point_pair(raw["long_axis"], f"{where}.long_axis"))
        length = float(np.linalg.norm(d - p))
        u = (d - p) / length
        k_t = _number(raw["radius_of_gyration_fraction"], f"{where}.radius_of_gyration_fraction", positive=True) * length
        k_a = _number(raw["axial_radius_of_gyration_fraction"], f"{where}.axial_radius_of_gyration_fraction",
                      positive=True) * length
        inertia = mass * (k_t**2 * (np.eye(3) - np.outer(u, u)) + k_a**2 * np.outer(u, u))
    if mass <= 0:
        raise ModelError(f"{where}: mass must be > 0")
    return mass, com_global - origin, inertia


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------
def _origin_point_name(seg: Segment, parent: Segment | None) -> str | None:
    """The name of a point of ``seg`` at its origin (local zero), preferring one the parent also
    has at the joint centre (e.g. GH on the humerus and on the scapula)."""
    at_zero = [n for n, v in seg.points.items() if np.linalg.norm(v) < 1e-12]
    if parent is not None and seg.joint is not None:
        for n in at_zero:
            if n in parent.points and np.linalg.norm(parent.points[n] - seg.joint.centre_m) < 1e-12:
                return n
    return at_zero[0] if at_zero else None


def _plain(value: Any) -> Any:
    """numpy scalars/arrays and tuples -> plain Python for yaml.safe_dump."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (np.integer, int)) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _mm(v: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=float) * 1000.0]


def _range_entry(rng: np.ndarray) -> dict[str, Any]:
    if not np.isfinite(rng).any():
        return {}
    return {"range_deg": [float(np.degrees(x)) if np.isfinite(x) else None for x in rng]}


def model_to_dict(model: Model, /, *, calibration: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The model as the mapping ``load_model`` reads (schema_version 1): every point, origin and
    centre of mass in mm in the thorax frame in the reference posture, joint axes as unit vectors,
    inertia as mass fraction + full tensor per kg, so the file does not depend on the tables or
    point names the generic file derived them from."""
    ref_origin: dict[str, np.ndarray] = {}
    segments = []
    for seg in model.segments:
        parent = model.segment(seg.parent) if seg.parent is not None else None
        origin = np.zeros(3) if parent is None else ref_origin[parent.name] + seg.joint.centre_m
        ref_origin[seg.name] = origin
        points = {name: _mm(origin + local) for name, local in seg.points.items()}
        raw: dict[str, Any] = {"name": seg.name}
        if parent is not None:
            name = _origin_point_name(seg, parent)
            if name is None:
                name = f"{seg.name}_origin"
                if name in points:
                    raise ModelError(f"{model.source or model.name}: cannot name the origin of segment '{seg.name}'")
                points[name] = _mm(origin)
            raw["parent"] = parent.name
            raw["origin"] = name
            raw["joint"] = {
                "name": seg.joint.name,
                "type": seg.joint.kind.value,
                # the axes below are vectors in the thorax frame (exact); axes_frame records where they came from
                **({"axes_frame": seg.joint.axes_frame} if seg.joint.axes_frame else {}),
                "coordinates": [{"name": c, "axis": [float(x) for x in a], **_range_entry(r)}
                                for c, a, r in zip(seg.joint.coordinates, seg.joint.axes, seg.joint.ranges_rad)],
            }
        if seg.mass_kg > 0:
            tensor = np.asarray(seg.inertia_kgm2, dtype=float) / seg.mass_kg
            tensor = 0.5 * (tensor + tensor.T)
            raw["inertia"] = {
                "mass_fraction": float(seg.mass_kg / model.body_mass_kg),
                "com_mm": _mm(origin + seg.com_m),
                "inertia_kgm2_per_kg": [[float(x) for x in row] for row in tensor],
            }
        raw["points_mm"] = points
        segments.append(raw)
    ell = model.ellipsoid
    out: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "name": model.name,
        "side": str(model.metadata.get("side", "right")),
        "body_mass_kg": float(model.body_mass_kg),
        "segments": segments,
        "ellipsoid": {
            "centre_mm": _mm(ell.centre_m),
            "radii_mm": _mm(ell.radii_m),
            "contact_points": [[s, p] for s, p in ell.contact_points],
        },
    }
    if calibration is not None:
        out["calibration"] = _plain(calibration)
    return out


def as_written(model: Model, /, *, calibration: Mapping[str, Any] | None, source: str | Path) -> Model:
    """``model`` exactly as ``load_model`` reads it back from the file ``save_model`` writes (points
    through mm, the calibration as plain data; YAML keeps every float exactly), with ``source``
    the file: what a run reconstructs with after it wrote the file, without reading it again."""
    return model_from_mapping(_plain(model_to_dict(model, calibration=calibration)), str(source),
                              name=Path(source).stem)


def save_model(model: Model, path: str | Path, *, calibration: Mapping[str, Any] | None) -> Path:
    """Write ``model`` as a model YAML that ``load_model`` reads back to the same geometry (points
    to well below 1e-9 m), atomically. ``calibration`` (plain data: what was fitted, the residual
    per marker, ...) is stored under the top-level key ``calibration`` and comes back as
    ``model.metadata["calibration"]``; pass None for a model that was not calibrated."""
    import yaml

    from exubio.io.results import atomic_write

    path = Path(path)
    data = model_to_dict(model, calibration=calibration)
    header = (
        f"# exubio model '{model.name}', written by exubio.model.load.save_model.\n"
        "# Format: see the top of models/upper_extremity.yaml (positions in mm in the ISB thorax frame in\n"
        "# the reference posture, all coordinates zero). Geometry sources: the generic model it was made\n"
        "# from" + (f" ({model.metadata.get('generic_source')})" if model.metadata.get("generic_source") else "")
        + "; what a calibration changed is recorded under 'calibration'.\n"
    )
    text = header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110)

    def writer(tmp: Path) -> None:
        tmp.write_text(text, encoding="utf-8")

    return atomic_write(path, writer)
