"""One marker of a protocol: its keys checked (segment, point or local position, landmark, cluster,
weight, aliases, optional), its place on the model's segment, and the landmarks a protocol
declares checked against the model's points. Each error names the file and the key."""
from __future__ import annotations

import difflib
from typing import Any, Mapping

import numpy as np

from exubio.errors import ProtocolError
from exubio.io.yaml import _kind, check_keys, finite_float
from exubio.protocol.keys import _MARKER_KEYS, THORAX_SEGMENT
from exubio.types import MarkerSpec, Protocol



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
    landmark = spec.get("landmark")
    if landmark is not None:
        if not isinstance(landmark, str) or not landmark:
            raise ProtocolError(f"{src}: {where}.landmark must name a model point of '{segment}', got {_kind(landmark)}")
    offset = spec.get("landmark_offset_mm")
    if offset is not None:
        if landmark is None:
            raise ProtocolError(f"{src}: {where}.landmark_offset_mm accepts a distance from the marker's landmark; "
                                f"give its landmark too")
        offset = _number(offset, f"{where}.landmark_offset_mm", src, minimum=0.0, strict=True)
        if offset < METRES_BELOW_MM:
            raise ProtocolError(f"{src}: {where}.landmark_offset_mm is {offset:g}: that looks like metres (below "
                                f"{METRES_BELOW_MM:g} mm); write millimetres, e.g. {offset * 1000.0:g}")
    cluster = spec.get("cluster")
    if cluster is not None and (not isinstance(cluster, str) or not cluster):
        raise ProtocolError(f"{src}: {where}.cluster must be a name shared by the markers of one rigid cluster, "
                            f"got {_kind(cluster)}")
    if landmark is not None and cluster is not None:
        raise ProtocolError(f"{src}: {where} is both a landmark and in cluster '{cluster}'; a cluster marker is "
                            f"not placed over a landmark, give one of them")

    return MarkerSpec(
        name=name,
        segment=segment,
        local_position_m=local_m,
        aliases=tuple(aliases),
        stiffness_n_per_m=stiffness,
        damping_ns_per_m=damping,
        optional=optional,
        landmark=landmark,
        cluster=cluster,
        landmark_offset_mm=offset,
        point=spec["point"] if has_point else None,
    )


def check_landmarks(protocol: Protocol, model_points: Mapping[str, Mapping[str, Any]], /) -> None:
    """ProtocolError naming the file and marker when a marker's ``landmark`` is not a point of its
    segment in the model (checked against the model a protocol is used with)."""
    for m in protocol.markers:
        if m.landmark is not None and m.landmark not in model_points.get(m.segment, {}):
            raise ProtocolError(f"{protocol.source or protocol.name}: markers.{m.name}.landmark '{m.landmark}' is not a "
                                f"point of segment '{m.segment}' of the model; its points are "
                                f"{sorted(model_points.get(m.segment, {}))}")


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


METRES_BELOW_MM = 1.0
"""A ``_mm`` value whose largest component is above 0 and below this looks like metres: no marker
sits within a millimetre of its segment's joint centre, nor is a landmark offset that small."""


def _local_position(raw: Any, where: str, src: str) -> np.ndarray:
    ok = isinstance(raw, list) and len(raw) == 3 and all(finite_float(v) is not None for v in raw)
    if not ok:
        raise ProtocolError(
            f"{src}: {where}.local_position_mm must be a list of 3 numbers [x, y, z] in mm, finite, got "
            f"{repr(raw) if isinstance(raw, list) else _kind(raw)}"
        )
    value = np.array(raw, dtype=float)
    if 0.0 < np.abs(value).max() < METRES_BELOW_MM:
        raise ProtocolError(
            f"{src}: {where}.local_position_mm is {raw}: that looks like metres (every value below {METRES_BELOW_MM:g} "
            f"mm); write millimetres, e.g. {[round(float(v) * 1000.0, 1) for v in value]}")
    return value / 1000.0


def _number(value: Any, where: str, src: str, *, minimum: float, strict: bool) -> float:
    if finite_float(value) is None:
        raise ProtocolError(f"{src}: {where} must be a finite number, got {_kind(value)}")
    if (strict and value <= minimum) or (not strict and value < minimum):
        need = f"> {minimum:g}" if strict else f">= {minimum:g}"
        raise ProtocolError(f"{src}: {where} is {value}; expected a number {need}")
    return float(value)
