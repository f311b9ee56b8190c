"""The protocol key ``analog_loads``: external loads read from a C3D's analog channels for the joint
moments (exubio.prep.loads.analog_load reads them). A list, one mapping per load:

    analog_loads:
      - force: [Fx1, Fy1, Fz1]        # the analog channels (ANALOG:LABELS) of the force's x, y, z, N
        moment: [Mx1, My1, Mz1]       # optional: the free moment's (N m, or N mm by ANALOG:UNITS)
        segment: hand                 # the segment the point of application is fixed in
        point_mm: [0, -80, 0]         # that point in the segment's model frame, mm (default 0)
        frame: lab                    # the vectors' frame: lab | thorax | segment

Every problem is a ProtocolError naming the file and the key."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from exubio.errors import ProtocolError
from exubio.io.yaml import _kind, check_keys, finite_float

__all__ = ["AnalogLoadSpec", "parse_analog_loads"]

@dataclass(frozen=True)
class AnalogLoadSpec:
    """An external load a protocol maps from a C3D's analog channels (``analog_loads``): the
    channels of the force's x, y, z (N) and optionally of the free moment's (N m or N mm, by the
    channel's ANALOG:UNITS), applied at ``point_m`` fixed in ``segment``, vectors in ``frame``
    (lab | thorax | segment; exubio.dynamics.loads)."""

    force: tuple[str, str, str]
    segment: str
    frame: str
    point_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    moment: tuple[str, str, str] | None = None


_KEYS = ("force", "moment", "segment", "point_mm", "frame")
_FRAMES = ("lab", "thorax", "segment")


def _channels(value: Any, where: str) -> tuple[str, str, str]:
    if not (isinstance(value, list) and len(value) == 3 and all(isinstance(c, str) and c.strip() for c in value)):
        raise ProtocolError(f"{where}: expected a list of 3 analog channel labels (x, y, z), got {_kind(value)}")
    return tuple(c.strip() for c in value)  # type: ignore[return-value]


def parse_analog_loads(raw: Any, src: str, segments: Sequence[str], /) -> tuple[AnalogLoadSpec, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise ProtocolError(f"{src}: analog_loads must be a list of loads, got {_kind(raw)}")
    out = []
    for i, item in enumerate(raw):
        where = f"{src}: analog_loads[{i}]"
        if not isinstance(item, dict):
            raise ProtocolError(f"{where}: expected a mapping with keys {list(_KEYS)}, got {_kind(item)}")
        check_keys(item, _KEYS, where=f"analog_loads[{i}]", source=src)
        for key in ("force", "segment", "frame"):
            if key not in item:
                raise ProtocolError(f"{where}: missing key '{key}'")
        force = _channels(item["force"], f"{where}.force")
        moment = _channels(item["moment"], f"{where}.moment") if item.get("moment") is not None else None
        segment, frame = item["segment"], item["frame"]
        arm = [s for s in segments if s != "thorax"]
        if segment not in arm:
            raise ProtocolError(f"{where}.segment: unknown segment {segment!r}; expected one of {arm}")
        if frame not in _FRAMES:
            raise ProtocolError(f"{where}.frame: unknown frame {frame!r}; expected one of {list(_FRAMES)}")
        point = item.get("point_mm", [0, 0, 0])
        values = [finite_float(v) for v in point] if isinstance(point, list) and len(point) == 3 else None
        if values is None or any(v is None for v in values):
            raise ProtocolError(f"{where}.point_mm: expected 3 finite numbers (mm), got {_kind(point)}")
        out.append(AnalogLoadSpec(force=force, moment=moment, segment=segment, frame=frame,
                                  point_m=tuple(1e-3 * v for v in values)))  # type: ignore[arg-type]
    return tuple(out)
