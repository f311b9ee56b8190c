"""Read a marker-protocol YAML into a validated :class:`~exubio.types.Protocol` (matching a trial's
labels to it is exubio.protocol.labels).

YAML is parsed by :mod:`exubio.io.yaml`, the one place that calls ``yaml.safe_load``. The file format is documented at
the top of ``protocols/upper_limb_21.yaml``.

Where the files are: exubio.protocol.files; one marker's keys: exubio.protocol.marker_spec.
"""
from __future__ import annotations

import difflib
import logging
import os
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from exubio.errors import ProtocolError
from exubio.io.yaml import _kind, check_keys, finite_float, read_yaml
from exubio.protocol.analog_loads import parse_analog_loads
from exubio.protocol.keys import (_DEFAULT_KEYS, _FILTER_KEYS, _FRAME_KEYS, _MARKER_KEYS,  # noqa: F401
                                  _MIDPOINT_FRAME_KEYS, _TOP_KEYS, SCHEMA_VERSION, THORAX_SEGMENT)
from exubio.protocol.files import (_find_base, _read_extended, find_other_arm, read_protocol_mapping,  # noqa: F401
                                   resolve_protocol, shipped_protocols)
from exubio.protocol.marker_spec import _number, _parse_marker, check_landmarks  # noqa: F401
from exubio.types import MarkerSpec, Protocol, ThoraxFrameSpec

__all__ = [
    "SCHEMA_VERSION",
    "THORAX_SEGMENT",
    "check_keys",
    "find_other_arm",
    "load_protocol",
    "read_protocol_mapping",
    "read_yaml",
]

log = logging.getLogger(__name__)

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

    A file with ``extends: <protocol file>`` starts from that file (found next to it, else among
    the shipped protocols by name) and replaces the keys it gives; errors name the file a key
    comes from. ``relabel`` renames trial labels before they are matched (see
    exubio.protocol.labels.resolve_labels).
    """
    path = resolve_protocol(path)
    src = str(path)
    data, origin = _read_extended(Path(path), ())
    seg_names = tuple(segments)

    def src_of(key: str) -> str:
        return origin.get(key, src)

    name = data.get("name", Path(src).stem)
    if not isinstance(name, str) or not name:
        raise ProtocolError(f"{src_of('name')}: 'name' must be a non-empty string, got {_kind(name)}")
    description = data.get("description", "")
    if description is not None and not isinstance(description, str):
        raise ProtocolError(f"{src_of('description')}: 'description' must be a string, got {_kind(description)}")

    frame = _parse_thorax_frame(data, src_of("thorax_frame"))
    cutoff, order = _parse_filter(data, src_of("filter"))
    stiffness0, damping0 = _parse_defaults(data, src_of("defaults"))
    pf_inertia = (data.get("defaults") or {}).get("pf_inertia_scale") if isinstance(data.get("defaults"), dict) else None
    if pf_inertia is not None:  # PF's inertia scale (exubio.run.moments_outputs.pf_options; --pf-inertia-scale wins)
        pf_inertia = _number(pf_inertia, "defaults.pf_inertia_scale", src_of("defaults"), minimum=0.0, strict=True)
    relabel = _parse_relabel(data.get("relabel"), src_of("relabel"))
    side = data.get("side", "right")
    if side not in ("right", "left"):
        raise ProtocolError(f"{src_of('side')}: side: expected 'right' or 'left', got {side!r}")
    signs = data.get("signs", "isb")
    if signs not in ("isb", "clinical"):  # exubio.model.signs.SIGNS
        raise ProtocolError(f"{src_of('signs')}: signs: expected 'isb' or 'clinical' (the sign convention of the written "
                            f"angles), got {signs!r}")
    src_markers = src_of("markers")

    raw_markers = data.get("markers")
    if not isinstance(raw_markers, dict) or not raw_markers:
        raise ProtocolError(
            f"{src_markers}: 'markers' must be a non-empty mapping of marker name -> settings, got {_kind(raw_markers)}"
        )

    other_arm = data.get("other_arm")
    if other_arm is not None and (not isinstance(other_arm, str) or not other_arm.strip()):
        raise ProtocolError(f"{src_of('other_arm')}: other_arm must name the protocol file of the other arm, got "
                            f"{_kind(other_arm)}")

    uncertainty_model = _uncertainty_model(data.get("uncertainty_model"), src_of("uncertainty_model"))

    tracked: list[MarkerSpec] = []
    thorax_aliases: dict[str, tuple[str, ...]] = {}  # a thorax marker's name -> its aliases
    label_owner: dict[str, str] = {}  # every name and alias -> the marker it belongs to
    for mname, spec in raw_markers.items():
        if not isinstance(mname, str) or not mname:
            raise ProtocolError(f"{src_markers}: marker names must be non-empty strings, got {_kind(mname)} under 'markers'")
        marker = _parse_marker(
            mname, spec, src_markers,
            segments=seg_names, model_points=model_points, stiffness0=stiffness0, damping0=damping0,
        )
        for label in (marker.name, *marker.aliases):
            if label in label_owner:
                other = label_owner[label]
                raise ProtocolError(
                    f"{src_markers}: label '{label}' of marker '{mname}' is already used by marker '{other}' "
                    f"(as its name or an alias); every name and alias must be unique"
                )
            label_owner[label] = mname
        if marker.segment == THORAX_SEGMENT:
            log.debug("%s: marker '%s' is on the thorax: not tracked", src_markers, mname)
            if marker.aliases:
                thorax_aliases[mname] = marker.aliases
            continue
        tracked.append(marker)

    if not tracked:
        raise ProtocolError(
            f"{src_markers}: no tracked marker; 'markers' must list at least one marker on a segment other "
            f"than '{THORAX_SEGMENT}'"
        )
    if not frame.is_identity:
        tracked_labels = {lab: m.name for m in tracked for lab in (m.name, *m.aliases)}
        for key in _FRAME_KEYS:
            label = getattr(frame, key)
            if label in tracked_labels:
                seg = next(m.segment for m in tracked if m.name == tracked_labels[label])
                raise ProtocolError(
                    f"{src_of('thorax_frame')}: thorax_frame.{key} is '{label}', which is tracked marker "
                    f"'{tracked_labels[label]}' on segment '{seg}'; thorax landmarks must be on the thorax"
                )

    clusters: dict[str, list[MarkerSpec]] = {}
    for m in tracked:
        if m.cluster is not None:
            clusters.setdefault(m.cluster, []).append(m)
    for cname, members in clusters.items():
        segs = sorted({m.segment for m in members})
        if len(members) < 3 or len(segs) > 1:
            raise ProtocolError(
                f"{src_markers}: cluster '{cname}' has {[m.name for m in members]} on {segs}; a rigid cluster needs "
                f"at least 3 markers, all on one segment")

    held = data.get("hold", []) or []
    if not isinstance(held, list) or not all(isinstance(h, str) for h in held):
        raise ProtocolError(f"{src_of('hold')}: 'hold' must be a list of model coordinate names, got {_kind(held)}")
    if coordinates is not None:
        for h in held:
            if h not in coordinates:
                hint = difflib.get_close_matches(h, list(coordinates), n=1)
                did = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise ProtocolError(f"{src_of('hold')}: hold: unknown coordinate '{h}'{did}; the model has {list(coordinates)}")
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
        relabel=relabel,
        side=side,
        thorax_aliases=MappingProxyType(thorax_aliases),
        pf_inertia_scale=pf_inertia,
        other_arm=other_arm.strip() if other_arm else None,
        analog_loads=parse_analog_loads(data.get("analog_loads"), src_of("analog_loads"), seg_names),
        signs=signs,
        uncertainty_model=uncertainty_model,
        files=tuple(dict.fromkeys([src, *origin.values()])),
    )


def _uncertainty_model(raw: Any, src: str) -> str | None:
    """``uncertainty_model: <file>``: a lab's STA amplitude model (the JSON ``exubio uncertainty-fit``
    writes), relative to the protocol file that gives the key; its absolute path. Read by the trust
    layer (exubio.trust.sta_amplitude.amplitude_of), which says what in it is wrong."""
    if raw is None:
        return None
    if not isinstance(raw, str) or not raw.strip():
        raise ProtocolError(f"{src}: uncertainty_model must name a JSON file (an STA amplitude model written by "
                            f"'exubio uncertainty-fit'), got {_kind(raw)}")
    path = (Path(src).parent / Path(raw.strip()).expanduser()).absolute()
    if not path.is_file():
        raise ProtocolError(f"{src}: uncertainty_model: {raw.strip()!r} not found (looked for {path}); it is resolved "
                            "against the protocol file's folder")
    return str(path.resolve())


def _parse_relabel(raw: Any, src: str) -> Mapping[str, str]:
    """``relabel: {trial label: label to read it as}``: a renaming of trial labels, applied before
    they are matched; no two labels may be read as the same one."""
    if raw is None:
        return MappingProxyType({})
    if not isinstance(raw, dict):
        raise ProtocolError(
            f"{src}: relabel must be a mapping of trial label -> the label to read it as, e.g. "
            f"{{RADIUS: ULNA, ULNA: RADIUS}}, got {_kind(raw)}"
        )
    out: dict[str, str] = {}
    read_as: dict[str, str] = {}
    for key, value in raw.items():
        if not isinstance(key, str) or not key or not isinstance(value, str) or not value:
            raise ProtocolError(
                f"{src}: relabel.{key}: trial labels and the labels they are read as must be non-empty "
                f"strings, got {_kind(key)} -> {_kind(value)}"
            )
        if key == value:
            raise ProtocolError(f"{src}: relabel.{key}: reads '{key}' as itself; remove the entry")
        if value in read_as:
            raise ProtocolError(
                f"{src}: relabel.{key}: '{key}' and '{read_as[value]}' would both be read as '{value}'; "
                f"a relabel must not make two markers of one label"
            )
        read_as[value] = key
        out[key] = value
    return MappingProxyType(out)


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
    analysis per marker, exubio.prep.filtering.residual_cutoffs) or None ('filter: none')."""
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
    if finite_float(value) is None:
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
