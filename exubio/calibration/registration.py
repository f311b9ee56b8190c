"""Marker <-> model point: which point each protocol marker is registered under, the registration
itself, and a protocol bound to a calibrated model."""
from __future__ import annotations

import dataclasses
from typing import Mapping, Sequence

import numpy as np

from exubio.model.kinematics import Kinematics
from exubio.types import Model, Protocol


def _declared_points(protocol: Protocol) -> dict[str, str]:
    """marker -> the ``point:`` its protocol file names (markers given by position: absent)."""
    return {m.name: m.point for m in protocol.markers if m.point}


def joint_centre_points(model: Model, segment: str, /) -> set[str]:
    """The points of ``segment`` that are joint centres: its own origin (local zero) and the
    joint centres of its children. Registration never moves them."""
    seg = model.segment(segment)
    out = {n for n, v in seg.points.items() if seg.parent is not None and np.linalg.norm(v) < 1e-12}
    for child in model.segments:
        if child.parent == segment:
            out |= {n for n, v in seg.points.items() if np.linalg.norm(v - child.joint.centre_m) < 1e-12}
    return out


def marker_point_names(protocol: Protocol, model: Model, /) -> dict[str, str]:
    """The model point each protocol marker is registered under: the ``point:`` its protocol
    file names (else a point of its segment at exactly its local position, else the marker's own
    name), except that a joint centre is never overwritten: a marker tied to one is registered as a
    point named after the marker (``<marker>_marker`` if the segment already has that name)."""
    declared = _declared_points(protocol)
    out = {}
    for m in protocol.markers:
        seg = model.segment(m.segment)
        if m.name in declared:
            name = declared[m.name]
        else:
            same = [n for n, v in seg.points.items() if np.allclose(v, m.local_position_m, rtol=0, atol=1e-12)]
            name = m.name if m.name in same or not same else same[0]
        if name in joint_centre_points(model, m.segment):
            name = m.name if m.name not in seg.points else f"{m.name}_marker"
        out[m.name] = name
    return out


def calibrated_protocol(protocol: Protocol, model: Model, /, *, point_names: Mapping[str, str] | None = None) -> Protocol:
    """``protocol`` with every marker's local position taken from the calibrated ``model``: from
    the point it was registered under (recorded in ``model.metadata["calibration"]``, else
    ``point_names``, else as ``marker_point_names`` finds it). Markers whose point the model lacks
    keep their position. Reconstructions with a calibrated model need it for the markers the
    protocol gives by ``local_position_mm`` and those tied to a joint centre (a protocol loaded
    with the calibrated model's points already has the others); it is idempotent."""
    if point_names is None:
        recorded = (model.metadata.get("calibration") or {}).get("markers") or {}
        point_names = {name: spec["point"] for name, spec in recorded.items()
                       if isinstance(spec, Mapping) and isinstance(spec.get("point"), str)}
        if not point_names:
            point_names = marker_point_names(protocol, model)
    markers = []
    for m in protocol.markers:
        pts = model.segment(m.segment).points
        p = point_names.get(m.name, m.name)
        markers.append(dataclasses.replace(m, local_position_m=np.array(pts[p], dtype=float)) if p in pts else m)
    return dataclasses.replace(protocol, markers=tuple(markers))


def _register(model: Model, q: np.ndarray, registrations: Sequence[tuple[str, str, np.ndarray]]) -> Model:
    """Set each named point (segment, point, global position at pose q) to that position, as a
    local position on its segment: l = R_seg(q)^T (x - p_seg(q)). Joints, other points and
    inertia are unchanged."""
    fr = Kinematics(model).frames(q)
    new_points = {s.name: dict(s.points) for s in model.segments}
    for seg_name, point, x in registrations:
        i = model.segment_index(seg_name)
        new_points[seg_name][point] = fr.R[i].T @ (np.asarray(x, dtype=float) - fr.p[i])
    return dataclasses.replace(model, segments=tuple(
        dataclasses.replace(s, points=new_points[s.name]) for s in model.segments))


