"""Read a marker-protocol YAML into a validated :class:`~exubio.types.Protocol`, and match a
trial's marker labels to it.

YAML is parsed by :mod:`exubio.config`, the one place that calls ``yaml.safe_load``. The file format is documented at
the top of ``protocols/upper_limb_21.yaml``.
"""
from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

import difflib

from exubio.config import _kind, check_keys, read_yaml
from exubio.errors import InputError, ProtocolError
from exubio.types import MarkerSpec, Protocol, ThoraxFrameSpec

__all__ = [
    "SCHEMA_VERSION",
    "THORAX_SEGMENT",
    "LabelMatch",
    "check_keys",
    "load_protocol",
    "read_yaml",
    "resolve_labels",
]

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1
THORAX_SEGMENT = "thorax"  # the fixed segment: its markers only build the thorax frame

_TOP_KEYS = ("schema_version", "name", "description", "thorax_frame", "filter", "defaults", "markers", "hold")
_FRAME_KEYS = ("ij", "px", "c7", "t8")
_MIDPOINT_FRAME_KEYS = ("ij", "ij_c7_midpoint", "px_t8_midpoint")
_FILTER_KEYS = ("cutoff_hz", "order")
_DEFAULT_KEYS = ("stiffness_n_per_m", "damping_ns_per_m")
_MARKER_KEYS = (
    "segment",
    "point",
    "local_position_mm",
    "aliases",
    "stiffness_n_per_m",
    "damping_ns_per_m",
    "optional",
)
_FALLBACK_STIFFNESS = 1500.0
_FALLBACK_DAMPING = 300.0
_FALLBACK_CUTOFF = 2.0
_FALLBACK_ORDER = 2


# --------------------------------------------------------------------------------------------
# Protocol loading
# --------------------------------------------------------------------------------------------
def load_protocol(
    path: str | os.PathLike[str],
    /,
    *,
    segments: Sequence[str],
    model_points: Mapping[str, Mapping[str, np.ndarray]] | None = None,
    coordinates: Sequence[str] | None = None,
) -> Protocol:
    """Load and validate a protocol YAML (format: see ``protocols/upper_limb_21.yaml``).

    segments:     the model's segment names (``thorax`` first); every marker must sit on one.
    model_points: segment -> {point name -> local position (m)}, used by markers that give
                  ``point:`` instead of ``local_position_mm``.
    coordinates:  the model's coordinate names, to check ``hold`` against (unchecked if None).

    Markers on the thorax are validated but not tracked (the thorax is fixed; its landmarks only
    build the thorax frame, named by trial label in ``thorax_frame``). Every problem raises a
    ProtocolError naming the file and the offending key.
    """
    src = str(path)
    data = read_yaml(path, error=ProtocolError)
    check_keys(data, _TOP_KEYS, where="", source=src)
    seg_names = tuple(segments)

    if "schema_version" not in data:
        raise ProtocolError(f"{src}: missing key 'schema_version'; expected 'schema_version: {SCHEMA_VERSION}'")
    version = data["schema_version"]
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        raise ProtocolError(
            f"{src}: schema_version is {version!r}; this exubio reads schema_version {SCHEMA_VERSION}"
        )

    name = data.get("name", Path(src).stem)
    if not isinstance(name, str) or not name:
        raise ProtocolError(f"{src}: 'name' must be a non-empty string, got {_kind(name)}")
    description = data.get("description", "")
    if description is not None and not isinstance(description, str):
        raise ProtocolError(f"{src}: 'description' must be a string, got {_kind(description)}")

    frame = _parse_thorax_frame(data, src)
    cutoff, order = _parse_filter(data, src)
    stiffness0, damping0 = _parse_defaults(data, src)

    raw_markers = data.get("markers")
    if not isinstance(raw_markers, dict) or not raw_markers:
        raise ProtocolError(
            f"{src}: 'markers' must be a non-empty mapping of marker name -> settings, got {_kind(raw_markers)}"
        )

    tracked: list[MarkerSpec] = []
    label_owner: dict[str, str] = {}  # every name and alias -> the marker it belongs to
    for mname, spec in raw_markers.items():
        if not isinstance(mname, str) or not mname:
            raise ProtocolError(f"{src}: marker names must be non-empty strings, got {_kind(mname)} under 'markers'")
        marker = _parse_marker(
            mname, spec, src,
            segments=seg_names, model_points=model_points, stiffness0=stiffness0, damping0=damping0,
        )
        for label in (marker.name, *marker.aliases):
            if label in label_owner:
                other = label_owner[label]
                raise ProtocolError(
                    f"{src}: label '{label}' of marker '{mname}' is already used by marker '{other}' "
                    f"(as its name or an alias); every name and alias must be unique"
                )
            label_owner[label] = mname
        if marker.segment == THORAX_SEGMENT:
            log.debug("%s: marker '%s' is on the thorax: not tracked", src, mname)
            continue
        tracked.append(marker)

    if not tracked:
        raise ProtocolError(
            f"{src}: no tracked marker; 'markers' must list at least one marker on a segment other "
            f"than '{THORAX_SEGMENT}'"
        )
    if not frame.is_identity:
        tracked_labels = {lab: m.name for m in tracked for lab in (m.name, *m.aliases)}
        for key in _FRAME_KEYS:
            label = getattr(frame, key)
            if label in tracked_labels:
                seg = next(m.segment for m in tracked if m.name == tracked_labels[label])
                raise ProtocolError(
                    f"{src}: thorax_frame.{key} is '{label}', which is tracked marker "
                    f"'{tracked_labels[label]}' on segment '{seg}'; thorax landmarks must be on the thorax"
                )

    held = data.get("hold", []) or []
    if not isinstance(held, list) or not all(isinstance(h, str) for h in held):
        raise ProtocolError(f"{src}: 'hold' must be a list of model coordinate names, got {_kind(held)}")
    if coordinates is not None:
        for h in held:
            if h not in coordinates:
                hint = difflib.get_close_matches(h, list(coordinates), n=1)
                did = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise ProtocolError(f"{src}: hold: unknown coordinate '{h}'{did}; the model has {list(coordinates)}")
    return Protocol(
        held_coordinates=tuple(held),
        name=name,
        markers=tuple(tracked),
        thorax_frame=frame,
        cutoff_hz=cutoff,
        filter_order=order,
        default_stiffness_n_per_m=stiffness0,
        default_damping_ns_per_m=damping0,
        source=src,
    )


def _parse_thorax_frame(data: Mapping[str, Any], src: str) -> ThoraxFrameSpec:
    if "thorax_frame" not in data:
        raise ProtocolError(
            f"{src}: missing key 'thorax_frame'; expected a mapping {{ij, px, c7, t8}} of trial labels, "
            f"or 'thorax_frame: identity' for data already in a thorax-fixed frame"
        )
    raw = data["thorax_frame"]
    if isinstance(raw, str):
        if raw.strip().lower() == "identity":
            return ThoraxFrameSpec()
        raise ProtocolError(
            f"{src}: thorax_frame is '{raw}'; expected 'identity' or a mapping {{ij, px, c7, t8}} of trial labels"
        )
    if not isinstance(raw, dict):
        raise ProtocolError(
            f"{src}: thorax_frame must be 'identity' or a mapping {{ij, px, c7, t8}}, got {_kind(raw)}"
        )
    keys = _MIDPOINT_FRAME_KEYS if ("ij_c7_midpoint" in raw or "px_t8_midpoint" in raw) else _FRAME_KEYS
    check_keys(raw, keys, where="thorax_frame", source=src)
    labels: dict[str, str] = {}
    for key in keys:
        if key not in raw:
            raise ProtocolError(
                f"{src}: thorax_frame.{key} is missing; the ISB thorax frame needs all of {list(keys)} "
                f"(or {list(_FRAME_KEYS) if keys != _FRAME_KEYS else list(_MIDPOINT_FRAME_KEYS)})"
            )
        value = raw[key]
        if not isinstance(value, str) or not value:
            raise ProtocolError(f"{src}: thorax_frame.{key} must be a trial marker label, got {_kind(value)}")
        labels[key] = value
    if len(set(labels.values())) != len(labels):
        raise ProtocolError(f"{src}: thorax_frame needs {['', '', '', 'three', 'four'][len(keys)]} different labels, got {labels}")
    return ThoraxFrameSpec(**labels)


def _parse_filter(data: Mapping[str, Any], src: str) -> tuple[float | str | None, int]:
    """(cutoff, order) of the 'filter' key: cutoff a number > 0 (Hz), "auto" (Winter's residual
    analysis per marker, exubio.preprocess.residual_cutoffs) or None ('filter: none')."""
    if "filter" not in data:
        return _FALLBACK_CUTOFF, _FALLBACK_ORDER
    raw = data["filter"]
    if raw is None or (isinstance(raw, str) and raw.strip().lower() == "none"):
        return None, _FALLBACK_ORDER
    if not isinstance(raw, dict):
        raise ProtocolError(
            f"{src}: filter must be a mapping {{cutoff_hz, order}} or 'none', got {_kind(raw)}"
        )
    check_keys(raw, _FILTER_KEYS, where="filter", source=src)
    cutoff = _parse_cutoff(raw.get("cutoff_hz", _FALLBACK_CUTOFF), src)
    order = raw.get("order", _FALLBACK_ORDER)
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise ProtocolError(f"{src}: filter.order must be a whole number >= 1, got {_kind(order)}")
    return cutoff, order


def _parse_cutoff(value: Any, src: str) -> float | str:
    expected = "expected a number > 0 (Hz) or 'auto' (a cut-off per marker by Winter's residual analysis)"
    if isinstance(value, str):
        if value.strip().lower() == "auto":
            return "auto"
        raise ProtocolError(f"{src}: filter.cutoff_hz is '{value}'; {expected}")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProtocolError(f"{src}: filter.cutoff_hz is {_kind(value)}; {expected}")
    if value <= 0:
        raise ProtocolError(f"{src}: filter.cutoff_hz is {value}; {expected}")
    return float(value)


def _parse_defaults(data: Mapping[str, Any], src: str) -> tuple[float, float]:
    raw = data.get("defaults", {})
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ProtocolError(
            f"{src}: defaults must be a mapping {{stiffness_n_per_m, damping_ns_per_m}}, got {_kind(raw)}"
        )
    check_keys(raw, _DEFAULT_KEYS, where="defaults", source=src)
    k = _number(raw.get("stiffness_n_per_m", _FALLBACK_STIFFNESS), "defaults.stiffness_n_per_m", src,
                minimum=0.0, strict=True)
    c = _number(raw.get("damping_ns_per_m", _FALLBACK_DAMPING), "defaults.damping_ns_per_m", src,
                minimum=0.0, strict=False)
    return k, c


def _parse_marker(
    name: str,
    spec: Any,
    src: str,
    *,
    segments: tuple[str, ...],
    model_points: Mapping[str, Mapping[str, np.ndarray]] | None,
    stiffness0: float,
    damping0: float,
) -> MarkerSpec:
    where = f"markers.{name}"
    if not isinstance(spec, dict):
        raise ProtocolError(
            f"{src}: {where} must be a mapping with at least 'segment', got {_kind(spec)}"
        )
    check_keys(spec, _MARKER_KEYS, where=where, source=src)

    if "segment" not in spec:
        raise ProtocolError(f"{src}: {where}.segment is missing; valid segments are {list(segments)}")
    segment = spec["segment"]
    if not isinstance(segment, str) or segment not in segments:
        hint = difflib.get_close_matches(str(segment), segments, n=1)
        did = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise ProtocolError(
            f"{src}: {where}.segment is {segment!r}{did}; valid segments are {list(segments)}"
        )

    has_point, has_local = "point" in spec, "local_position_mm" in spec
    if has_point and has_local:
        raise ProtocolError(f"{src}: {where} gives both 'point' and 'local_position_mm'; give exactly one")
    if has_point:
        local_m = _model_point(spec["point"], segment, where, src, model_points)
    elif has_local:
        local_m = _local_position(spec["local_position_mm"], where, src)
    elif segment == THORAX_SEGMENT:
        local_m = np.full(3, np.nan)  # thorax landmarks need no position: they are not tracked
    else:
        raise ProtocolError(
            f"{src}: {where} needs its position on '{segment}': give 'point: <model point name>' or "
            f"'local_position_mm: [x, y, z]'"
        )

    aliases = spec.get("aliases", [])
    if aliases is None:
        aliases = []
    if isinstance(aliases, str) or not isinstance(aliases, list) or not all(
        isinstance(a, str) and a for a in aliases
    ):
        raise ProtocolError(f"{src}: {where}.aliases must be a list of trial labels, got {_kind(aliases)}")
    if len(set(aliases)) != len(aliases) or name in aliases:
        raise ProtocolError(f"{src}: {where}.aliases repeats a label: {aliases} (marker name '{name}')")

    stiffness = _number(spec.get("stiffness_n_per_m", stiffness0), f"{where}.stiffness_n_per_m", src,
                        minimum=0.0, strict=True)
    damping = _number(spec.get("damping_ns_per_m", damping0), f"{where}.damping_ns_per_m", src,
                      minimum=0.0, strict=False)
    optional = spec.get("optional", False)
    if not isinstance(optional, bool):
        raise ProtocolError(f"{src}: {where}.optional must be true or false, got {_kind(optional)}")

    return MarkerSpec(
        name=name,
        segment=segment,
        local_position_m=local_m,
        aliases=tuple(aliases),
        stiffness_n_per_m=stiffness,
        damping_ns_per_m=damping,
        optional=optional,
    )


def _model_point(
    point: Any,
    segment: str,
    where: str,
    src: str,
    model_points: Mapping[str, Mapping[str, np.ndarray]] | None,
) -> np.ndarray:
    if not isinstance(point, str) or not point:
        raise ProtocolError(f"{src}: {where}.point must be a model point name, got {_kind(point)}")
    if model_points is None:
        raise ProtocolError(
            f"{src}: {where}.point is '{point}', but no model points were given to load_protocol; "
            f"pass model_points= (from the model) or give 'local_position_mm'"
        )
    points = model_points.get(segment, {})
    if not points:
        raise ProtocolError(
            f"{src}: {where}.point is '{point}', but segment '{segment}' has no model points; "
            f"segments with model points are {sorted(s for s, p in model_points.items() if p)}"
        )
    if point not in points:
        hint = difflib.get_close_matches(point, list(points), n=1)
        did = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise ProtocolError(
            f"{src}: {where}.point '{point}' is not a model point of segment '{segment}'{did}; "
            f"its points are {sorted(points)}"
        )
    value = np.array(points[point], dtype=float)
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ProtocolError(
            f"{src}: {where}.point '{point}' of segment '{segment}' has position {value!r}; expected 3 finite numbers (m)"
        )
    return value


def _local_position(raw: Any, where: str, src: str) -> np.ndarray:
    ok = isinstance(raw, list) and len(raw) == 3 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in raw
    )
    if not ok:
        raise ProtocolError(
            f"{src}: {where}.local_position_mm must be a list of 3 numbers [x, y, z] in mm, got {_kind(raw)}"
        )
    return np.array(raw, dtype=float) / 1000.0


def _number(value: Any, where: str, src: str, *, minimum: float, strict: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProtocolError(f"{src}: {where} must be a finite number, got {_kind(value)}")
    if (strict and value <= minimum) or (not strict and value < minimum):
        need = f"> {minimum:g}" if strict else f">= {minimum:g}"
        raise ProtocolError(f"{src}: {where} is {value}; expected a number {need}")
    return float(value)


# --------------------------------------------------------------------------------------------
# Matching trial labels
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LabelMatch:
    """Where each protocol marker is in a trial.

    columns:        protocol marker name -> trial column (None: optional marker not in the trial),
                    in protocol order.
    thorax_columns: thorax-frame landmark key (ij, px, c7, t8) -> trial column; empty when the
                    protocol's thorax frame is the identity.
    unused:         trial labels neither tracked nor used for the thorax frame, in trial order.
    """

    columns: dict[str, int | None]
    thorax_columns: dict[str, int]
    unused: tuple[str, ...]


def resolve_labels(protocol: Protocol, labels: Sequence[str], /, *, source: str = "") -> LabelMatch:
    """Find each protocol marker among a trial's ``labels`` (by its name, then its aliases in
    order) and the thorax-frame landmarks (by label).

    A missing non-optional marker or thorax landmark raises an InputError naming them, the file
    (``source``) and the labels the trial has. Missing optional markers map to None.
    """
    where = source or "trial"
    labels = tuple(labels)
    index = {lab: i for i, lab in enumerate(labels)}
    columns: dict[str, int | None] = {}
    owner: dict[int, str] = {}
    missing: list[str] = []
    for m in protocol.markers:
        col = None
        for lab in (m.name, *m.aliases):
            if lab in index:
                if col is None:
                    col = index[lab]
                else:
                    log.warning(
                        "%s: marker '%s' found as '%s' and also as '%s'; using '%s'",
                        where, m.name, labels[col], lab, labels[col],
                    )
        if col is not None and col in owner:
            raise ProtocolError(
                f"{protocol.source or protocol.name}: trial label '{labels[col]}' matches both marker "
                f"'{owner[col]}' and marker '{m.name}'; names and aliases must be unique"
            )
        if col is None and not m.optional:
            alias = f" (aliases {list(m.aliases)})" if m.aliases else ""
            missing.append(f"'{m.name}'{alias}")
        if col is not None:
            owner[col] = m.name
        columns[m.name] = col

    thorax: dict[str, int] = {}
    frame = protocol.thorax_frame
    if not frame.is_identity:
        for key in frame.keys:
            lab = getattr(frame, key)
            if lab not in index:
                missing.append(f"'{lab}' (thorax_frame.{key})")
            else:
                thorax[key] = index[lab]
    if missing:
        raise InputError(
            f"{where}: protocol '{protocol.name}' needs marker(s) {', '.join(missing)}, not in the trial; "
            f"the trial has {list(labels)}"
        )
    used = set(owner) | set(thorax.values())
    unused = tuple(lab for i, lab in enumerate(labels) if i not in used)
    return LabelMatch(columns=columns, thorax_columns=thorax, unused=unused)
