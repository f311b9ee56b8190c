"""Frozen dataclasses <-> JSON objects and npz archives: the one serialisation scheme of exubio.
A record becomes a JSON object (its fields in order, as keys of the same name) and its arrays
become entries of an npz archive; both are read back into the same record. The dataclass fields
are the only description of the files: a trial's summary.json (exubio.run.summary_record) and the
validation's files are written and read through it. Enums are written as their values and read
back; ``Mapping`` fields are written as objects and read as dicts.

Field options (``dataclasses.field`` metadata, set with the helpers below):

* ``optional()``: the key is left out of the JSON object when the value is None (``empty=True``:
  also when empty); a key that is present with the value null is a plain ``X | None`` field;
* ``flat()``: a ``dict`` field whose items sit in the parent object beside the other fields (an
  object that mixes fixed keys with, e.g., one key per trial);
* ``array()``: an ``np.ndarray`` stored in the npz archive (and, with ``json=True``, also as a
  JSON list); a ``dict`` of arrays stores one entry per key;
* ``npz_name()``: the npz segment (template) of a record, ``dict`` or ``tuple`` field;
* ``converted(write=, read=, digits=)``: each number of the field (alone or in a list, tuple,
  array, dict; None passes) is written as ``round(write(v), digits)`` and read as ``read(v)``
  (e.g. ``write=np.degrees, read=np.radians, digits=4``: rad in memory, deg to 4 decimals in the
  file); a rounded file reads back to the rounded value, which writes the same bytes again;
* ``internal()``: a field kept in memory only (neither written nor read; it takes its default).

A dataclass whose file form is a computation over its fields, not a mapping of them (medians
over frames, a fixed definition, keys grouped otherwise), keeps a hand-written ``to_dict()``; the
codec writes it through that and reads it through its static ``from_dict(data)`` if it has one
(else a field holding it is typed as plain data). Each such ``to_dict`` says why in its docstring.

npz names follow the records' nesting: segments joined by ``__``; a field's segment is its
``npz`` name (default: the field name; "" adds none); a ``dict`` or ``tuple`` field's ``npz`` is
a template with ``{}`` for the key or index (default ``<field name>__{}``). E.g. the record at
``agr__abduction`` with an array field ``determined`` is stored as ``agr__abduction__determined``.

NaN is a float in memory and null in the JSON files (``write_json``); null read into a ``float``
field becomes NaN again. Records compare equal when they would write the same files.
"""
from __future__ import annotations

import collections.abc
import dataclasses
import enum
import json
import re
import types
import typing
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

__all__ = ["Record", "SchemaError", "array", "canonical", "converted", "decode", "encode_arrays", "flat", "internal",
           "nan_to_none", "npz_name", "optional", "to_json", "write_json"]

_OPTIONAL, _FLAT, _NPZ, _JSON, _CONVERT, _INTERNAL = "optional", "flat", "npz", "json", "convert", "internal"
_DICTS = (dict, collections.abc.Mapping)


class SchemaError(ValueError):
    """A file (or a dict handed to ``decode``) does not match the records: a missing or unknown
    key, a value of the wrong shape, an npz entry no field reads."""


def optional(*, empty: bool = False, **kw: Any) -> Any:
    """A field whose key is omitted from the JSON object when the value is None (default None),
    or also when it is empty (``empty``: a ``{}`` or ``()``)."""
    return dataclasses.field(default=None, metadata={_OPTIONAL: "empty" if empty else True}, **kw)


@dataclasses.dataclass(frozen=True)
class Conversion:
    """How a field's numbers are written (``round(write(v), digits)``) and read (``read(v)``)."""

    write: Callable[[Any], Any] | None = None
    read: Callable[[Any], Any] | None = None
    digits: int | None = None

    def to_file(self, v: Any) -> Any:
        v = _each(v, self.write) if self.write is not None else v
        return v if self.digits is None else _each(v, lambda x: round(x, self.digits))

    def from_file(self, v: Any) -> Any:
        return v if self.read is None else _each(v, self.read)


def _each(value: Any, fn: Callable[[Any], Any]) -> Any:
    """``fn`` of every number in ``value`` (containers kept: an array stays an array)."""
    if value is None or isinstance(value, (str, bool, np.bool_)):
        return value
    if isinstance(value, Mapping):
        return {k: _each(v, fn) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        out = [_each(v, fn) for v in value]
        return np.asarray(out) if isinstance(value, np.ndarray) else type(value)(out)
    return fn(value)


def converted(*, write: Callable[[Any], Any] | None = None, read: Callable[[Any], Any] | None = None,
              digits: int | None = None, **kw: Any) -> Any:
    """A field written as ``round(write(v), digits)``, read as ``read(v)``; ``kw``: a default."""
    return dataclasses.field(metadata={_CONVERT: Conversion(write, read, digits)}, **kw)


def internal(**kw: Any) -> Any:
    """A field kept in memory only: not written, not read (it takes its default, given in ``kw``)."""
    return dataclasses.field(metadata={_INTERNAL: True, _JSON: False}, **kw)


def npz_name(npz: str) -> Any:
    """A record, ``dict`` or ``tuple`` field whose npz segment (template) is ``npz``."""
    return dataclasses.field(metadata={_NPZ: npz})


def flat(*, npz: str = "{}") -> Any:
    """A ``dict`` field whose items are keys of the parent JSON object (after the fields before it)."""
    return dataclasses.field(metadata={_FLAT: True, _NPZ: npz})


def array(*, npz: str | None = None, json: bool = False, optional: bool = False) -> Any:
    """An ``np.ndarray`` (or ``dict`` of them) stored in the npz archive under ``npz`` (default
    the field name), also written to JSON as a list when ``json``; ``optional``: may be None
    (absent from the archive)."""
    meta: dict[str, Any] = {_JSON: json}
    if npz is not None:
        meta[_NPZ] = npz
    if optional:
        return dataclasses.field(default=None, metadata=meta)
    return dataclasses.field(metadata=meta)


def _in_json(f: dataclasses.Field) -> bool:
    return f.metadata.get(_JSON, True)


class Record:
    """Base of the result records: ``to_json`` and equality by file content."""

    def to_json(self) -> dict[str, Any]:
        """The record as its JSON object (NaN kept as float('nan'); ``write_json`` writes null)."""
        return to_json(self)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return canonical(self) == canonical(other)

    __hash__ = None  # type: ignore[assignment]


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------
def to_json(obj: Any, /) -> Any:
    """``obj`` as JSON-ready Python data: records as dicts in field order (npz-only fields left
    out), tuples as lists, arrays as lists, numpy scalars as Python numbers; NaN stays NaN."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if hasattr(obj, "to_dict"):  # a documented exception: its file form is a computation
            return to_json(obj.to_dict())
        out: dict[str, Any] = {}
        for f in dataclasses.fields(obj):
            if not _in_json(f):
                continue
            value = getattr(obj, f.name)
            omit = f.metadata.get(_OPTIONAL)
            if omit and (value is None or (omit == "empty" and not value)):
                continue
            if _CONVERT in f.metadata:
                value = f.metadata[_CONVERT].to_file(value)
            if f.metadata.get(_FLAT):
                for k, v in value.items():
                    if k in out:
                        raise SchemaError(f"{type(obj).__name__}.{f.name}: key {k!r} clashes with a field")
                    out[k] = to_json(v)
                continue
            out[f.name] = to_json(value)
        return out
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, Mapping):
        return {k: to_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def nan_to_none(obj: Any, /) -> Any:
    """JSON-ready data with every non-finite float as None (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {k: nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [nan_to_none(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_json(path: Path, data: Any, /) -> None:
    """Write JSON-ready ``data`` to ``path`` (NaN as null, indent 2), through a temporary file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(nan_to_none(data), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    tmp.replace(path)


def _join(path: tuple[str, ...]) -> str:
    return "__".join(p for p in path if p)


def _template(f: dataclasses.Field) -> str:
    t = f.metadata.get(_NPZ, f.name + "__{}")
    return t if "{}" in t else (t + "__{}" if t else "{}")


def encode_arrays(obj: Any, /, path: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Every array of the record ``obj`` by its npz name (see the module docstring)."""
    out: dict[str, np.ndarray] = {}
    _collect(obj, path, out)
    return out


def _collect(value: Any, path: tuple[str, ...], out: dict[str, np.ndarray], template: str = "{}") -> None:
    if value is None:
        return
    if isinstance(value, np.ndarray):
        key = _join(path)
        if key in out:
            raise SchemaError(f"two arrays named {key}")
        out[key] = value
    elif dataclasses.is_dataclass(value) and not isinstance(value, type) and not hasattr(value, "to_dict"):
        for f in dataclasses.fields(value):
            if f.metadata.get(_INTERNAL) or _CONVERT in f.metadata:  # in memory only; in the JSON
                continue
            v = getattr(value, f.name)
            if isinstance(v, (Mapping, tuple, list)):
                _collect(v, path, out, _template(f))
            else:
                _collect(v, path + (f.metadata.get(_NPZ, f.name),), out)
    elif isinstance(value, Mapping):
        for k, v in value.items():
            _collect(v, path + (template.format(k),), out)
    elif isinstance(value, (tuple, list)):
        for i, v in enumerate(value):
            _collect(v, path + (template.format(i),), out)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def decode(tp: Any, data: Any, /, arrays: Mapping[str, np.ndarray] | None = None, *,
           path: tuple[str, ...] = ()) -> Any:
    """``data`` (parsed JSON, or the same layout in memory) as type ``tp``, the records' arrays
    taken from ``arrays`` (npz entries named relative to ``path``; None: no arrays, the array
    fields must allow None). Raises SchemaError on a key the records do not know or miss, a
    missing array, or an entry of ``arrays`` no field reads."""
    reader = _Reader(arrays or {})
    out = reader.value(tp, data, path, "{}", where=tp.__name__ if isinstance(tp, type) else str(tp))
    if arrays is not None:
        left = sorted(set(arrays) - reader.used)
        if left:
            raise SchemaError(f"arrays no field reads: {left[:8]}{' ...' if len(left) > 8 else ''}")
    return out


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def _is_union(tp: Any) -> bool:
    return typing.get_origin(tp) in (typing.Union, types.UnionType)


def _without_none(tp: Any) -> tuple[Any, bool]:
    """(tp without None, whether None is allowed)."""
    if _is_union(tp):
        args = typing.get_args(tp)
        rest = tuple(a for a in args if a is not type(None))
        if len(rest) < len(args):
            return (rest[0] if len(rest) == 1 else typing.Union[rest]), True
    return tp, False


def _json_fields(cls: type) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if _in_json(f)]


def _required(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


def _fits(cls: type, data: Any) -> bool:
    """Whether ``data``'s keys are those of record ``cls`` (its required keys present, no other
    keys unless it has a flat field)."""
    if not isinstance(data, Mapping):
        return False
    fields = _json_fields(cls)
    names = {f.name for f in fields if not f.metadata.get(_FLAT)}
    required = {f.name for f in fields if _required(f) and not f.metadata.get(_FLAT)}
    keys = set(data)
    return required <= keys and (keys <= names or any(f.metadata.get(_FLAT) for f in fields))


def _misfit(alts: list[type], data: Any) -> str:
    """What keeps ``data`` from the nearest of the records ``alts``: its missing and unknown keys."""
    if not isinstance(data, Mapping):
        return f"not an object: {data!r:.80}"
    keys = set(data)

    def names(cls: type) -> set[str]:
        return {f.name for f in _json_fields(cls) if not f.metadata.get(_FLAT)}

    best = max(alts, key=lambda cls: len(names(cls) & keys))
    required = {f.name for f in _json_fields(best) if _required(f) and not f.metadata.get(_FLAT)}
    return f"as {best.__name__}: missing {sorted(required - keys)}, unknown {sorted(keys - names(best))}"


def _contains_array(tp: Any) -> bool:
    tp, _ = _without_none(tp)
    if tp is np.ndarray:
        return True
    return typing.get_origin(tp) in _DICTS and _contains_array(typing.get_args(tp)[1])


class _Reader:
    def __init__(self, arrays: Mapping[str, np.ndarray]):
        self.arrays = arrays
        self.used: set[str] = set()

    # arrays ---------------------------------------------------------------------------------
    def take(self, key: str) -> np.ndarray | None:
        if key in self.arrays:
            self.used.add(key)
            return self.arrays[key]
        return None

    def scan(self, path: tuple[str, ...], template: str) -> list[str]:
        """Keys (the ``{}`` of ``template``) of the unread arrays below ``path`` named by
        ``template``, in archive order; a key holds no ``__``."""
        prefix = _join(path)
        head, _, tail = template.partition("{}")
        pat = re.compile(re.escape((prefix + "__" if prefix else "") + head) + r"((?:(?!__).)+?)"
                         + re.escape(tail) + r"(?:__|$)")
        keys: list[str] = []
        for name in self.arrays:
            m = pat.match(name)
            if m and name not in self.used and m.group(1) not in keys:
                keys.append(m.group(1))
        return keys

    # values ---------------------------------------------------------------------------------
    def value(self, tp: Any, data: Any, path: tuple[str, ...], template: str, where: str) -> Any:
        if tp is Any:
            return data
        inner, nullable = _without_none(tp)
        if data is None and nullable:
            return None
        tp = inner
        if _is_union(tp):
            alts = [a for a in typing.get_args(tp) if dataclasses.is_dataclass(a)]
            for alt in alts:
                if _fits(alt, data):
                    return self.record(alt, data, path, where)
            raise SchemaError(f"{where}: fits none of {[a.__name__ for a in alts]}; {_misfit(alts, data)}")
        if dataclasses.is_dataclass(tp):
            return self.record(tp, data, path, where)
        if isinstance(tp, type) and issubclass(tp, enum.Enum):
            try:
                return tp(data)
            except ValueError:
                raise SchemaError(f"{where}: expected one of {[e.value for e in tp]}, got {data!r:.80}") from None
        origin = typing.get_origin(tp)
        if origin in _DICTS:
            _, vt = typing.get_args(tp)
            if not isinstance(data, Mapping):
                raise SchemaError(f"{where}: expected an object, got {data!r:.80}")
            return {k: self.value(vt, v, path + (template.format(k),), "{}", f"{where}[{k!r}]")
                    for k, v in data.items()}
        if origin is tuple:
            args = typing.get_args(tp)
            if not isinstance(data, (list, tuple)):
                raise SchemaError(f"{where}: expected a list, got {data!r:.80}")
            if len(args) == 2 and args[1] is Ellipsis:
                args = (args[0],) * len(data)
            elif len(args) != len(data):
                raise SchemaError(f"{where}: expected {len(args)} values, got {len(data)}")
            return tuple(self.value(a, v, path + (template.format(i),), "{}", f"{where}[{i}]")
                         for i, (a, v) in enumerate(zip(args, data)))
        if tp is np.ndarray:
            return np.asarray(data, dtype=float)
        if tp is float:
            if data is None:
                return float("nan")
            if not isinstance(data, (int, float, np.integer, np.floating)) or isinstance(data, (bool, np.bool_)):
                raise SchemaError(f"{where}: expected a number, got {data!r:.80}")
            return data  # an int stays an int: the files keep what was written
        if tp is bool and isinstance(data, (bool, np.bool_)):
            return bool(data)
        if tp is int and isinstance(data, (int, np.integer)) and not isinstance(data, (bool, np.bool_)):
            return int(data)
        if tp is str and isinstance(data, str):
            return str(data)
        if tp in (int, str, bool):
            raise SchemaError(f"{where}: expected {tp.__name__}, got {data!r:.80}")
        raise SchemaError(f"{where}: cannot read type {tp!r}")

    def npz_value(self, tp: Any, path: tuple[str, ...], template: str, where: str) -> Any:
        """An npz-only field: an array, or a dict of them (dicts of dicts too)."""
        inner, nullable = _without_none(tp)
        if inner is np.ndarray:
            got = self.take(_join(path))
            if got is None and not nullable:
                raise SchemaError(f"{where}: array {_join(path)} missing")
            return got
        if typing.get_origin(inner) in _DICTS:
            _, vt = typing.get_args(inner)
            out = {}
            for k in self.scan(path, template):
                out[k] = self.npz_value(vt, path + (template.format(k),), "{}", f"{where}[{k!r}]")
            return out
        raise SchemaError(f"{where}: npz-only fields hold arrays, not {tp!r}")

    def record(self, cls: type, data: Any, path: tuple[str, ...], where: str) -> Any:
        if not isinstance(data, Mapping):
            raise SchemaError(f"{where}: expected an object for {cls.__name__}, got {data!r:.80}")
        if hasattr(cls, "to_dict"):  # a documented exception (see the module docstring)
            if not hasattr(cls, "from_dict"):
                raise SchemaError(f"{where}: {cls.__name__} is written as a summary and cannot be read back")
            try:
                return cls.from_dict(data)
            except (KeyError, TypeError, ValueError) as exc:
                raise SchemaError(f"{where}: not a {cls.__name__} ({type(exc).__name__}: {exc})") from None
        hints = _hints(cls)
        kwargs: dict[str, Any] = {}
        known: set[str] = set()
        flat_field = None
        later: list[dataclasses.Field] = []  # npz-only dicts scan what the named arrays leave
        for f in dataclasses.fields(cls):
            if f.metadata.get(_INTERNAL):
                continue
            tp = hints[f.name]
            sub = f"{where}.{f.name}"
            if f.metadata.get(_FLAT):
                flat_field = f
                continue
            container = typing.get_origin(_without_none(tp)[0]) in (*_DICTS, tuple)
            seg_path = path if container else path + (f.metadata.get(_NPZ, f.name),)
            template = _template(f) if container else "{}"
            if not _in_json(f):
                if container:
                    later.append(f)
                else:
                    kwargs[f.name] = self.npz_value(tp, seg_path, template, sub)
                continue
            known.add(f.name)
            if f.name not in data:
                if _required(f):
                    raise SchemaError(f"{where}: key {f.name!r} missing")
                continue
            if _contains_array(tp) and f.metadata.get(_JSON) is not None:  # array in both files
                got = self.take(_join(seg_path))
                kwargs[f.name] = got if got is not None else self.value(tp, data[f.name], seg_path, template, sub)
                continue
            kwargs[f.name] = self.value(tp, data[f.name], seg_path, template, sub)
            if _CONVERT in f.metadata:
                kwargs[f.name] = f.metadata[_CONVERT].from_file(kwargs[f.name])
        if flat_field is not None:
            vt = typing.get_args(_without_none(hints[flat_field.name])[0])[1]
            kwargs[flat_field.name] = {k: self.value(vt, v, path + (_template(flat_field).format(k),), "{}",
                                                     f"{where}[{k!r}]")
                                       for k, v in data.items() if k not in known}
        else:
            unknown = sorted(set(data) - known)
            if unknown:
                raise SchemaError(f"{where}: unknown key(s) {unknown} for {cls.__name__}")
        for f in later:
            kwargs[f.name] = self.npz_value(hints[f.name], path, _template(f), f"{where}.{f.name}")
        return cls(**kwargs)


# --------------------------------------------------------------------------------------------
# Equality
# --------------------------------------------------------------------------------------------
def canonical(obj: Any, /) -> tuple[Any, dict[str, Any]]:
    """What ``obj`` writes: its JSON (NaN as None) and its arrays (dtype, shape, values with NaN
    as None), for comparisons."""
    arrays = {k: (v.dtype.str, v.shape, nan_to_none(v.tolist())) for k, v in encode_arrays(obj).items()}
    return nan_to_none(to_json(obj)), arrays
