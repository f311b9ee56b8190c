"""A content digest of plain data (frozen dataclasses, arrays, mappings, sequences, enums and plain
values): the key of the per-process caches of what is computed from a model or a protocol, so that
a model loaded afresh for every trial of a study (another object, the same content) hits the cache."""
from __future__ import annotations

import dataclasses
import enum
import hashlib
from typing import Mapping

import numpy as np

__all__ = ["content_digest"]


def content_digest(*objs) -> bytes:
    """A digest of the content of frozen dataclasses, arrays, mappings, sequences and plain values
    (TypeError for anything else): equal digests, equal content (the same inputs of
    exubio.trust.label_expectations.model_expectations, the same geometry of a model)."""
    h = hashlib.sha256()

    def walk(o) -> None:
        if isinstance(o, np.ndarray):
            if o.dtype.hasobject:
                raise TypeError("object array")
            h.update(b"A" + str(o.dtype).encode() + repr(o.shape).encode())
            h.update(np.ascontiguousarray(o).tobytes())
        elif dataclasses.is_dataclass(o) and not isinstance(o, type):
            h.update(b"D" + type(o).__module__.encode() + b"." + type(o).__qualname__.encode())
            for f in dataclasses.fields(o):
                h.update(b"F" + f.name.encode())
                walk(getattr(o, f.name))
        elif isinstance(o, enum.Enum):
            h.update(b"E" + repr(o).encode() + b"\0")
        elif isinstance(o, Mapping):
            h.update(b"M%d" % len(o))
            for key, value in o.items():
                walk(key)
                walk(value)
        elif isinstance(o, (tuple, list)):
            h.update(b"T%d" % len(o))
            for x in o:
                walk(x)
        elif o is None or isinstance(o, (bool, int, float, str, np.generic)):
            h.update(b"V" + type(o).__name__.encode() + b":" + repr(o).encode() + b"\0")
        else:
            raise TypeError(f"no content digest for {type(o).__name__}")

    for o in objs:
        walk(o)
    return h.digest()
