"""Short reprs for the API's data types (a notebook prints a Reconstruction or a Trajectories in a
few lines): arrays as their dtype and shape, long sequences and mappings counted, long values cut."""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

__all__ = ["short_repr"]

MAX_ITEMS = 6
MAX_CHARS = 80


def _item(x: Any) -> str:
    """An element of a long sequence: a named dataclass by its name, else its short value."""
    if dataclasses.is_dataclass(x) and isinstance(getattr(x, "name", None), str):
        return x.name
    return _value(x)[:30]


def _value(v: Any) -> str:
    if isinstance(v, np.ndarray):
        return f"<{v.dtype} array {'x'.join(map(str, v.shape)) or 'scalar'}>"
    if isinstance(v, (tuple, list)) and len(v) > MAX_ITEMS:
        head = ", ".join(_item(x) for x in v[:3])
        return f"<{len(v)} items: {head}, ...>"
    if isinstance(v, Mapping) and len(v) > MAX_ITEMS:
        return f"<{len(v)} entries: {', '.join(map(str, list(v)[:3]))}, ...>"
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return f"<{type(v).__name__}>"
    s = repr(v)
    return s if len(s) <= MAX_CHARS else s[:MAX_CHARS - 3] + "..."


def short_repr(obj: Any) -> str:
    """``Name(field=value, ...)`` of a dataclass, each value short (module docstring)."""
    parts = [f"{f.name}={_value(getattr(obj, f.name))}" for f in dataclasses.fields(obj) if f.repr]
    return f"{type(obj).__name__}({', '.join(parts)})"
