"""YAML configuration files: the one place exubio parses YAML, and the unknown-key check every
loader (protocols, models) applies."""
from __future__ import annotations

import difflib
import math
import os
import re
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from exubio.errors import ExubioError, ProtocolError

class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading a number written with an exponent and no point (``2e3``,
    ``1E-4``) as a float, as YAML 1.2 and every other YAML reader do; PyYAML (YAML 1.1) reads it as
    the text '2e3', which a protocol or model then refused as "not a number"."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))

MAX_NESTING = 64
"""The deepest nesting of mappings and lists a configuration file may have. exubio's own files nest
at most 6 levels; a file nested thousands of levels deep (hostile or generated) would exhaust
Python's recursion in the YAML composer and in every walk over it."""


def read_yaml(path: str | os.PathLike[str], /, *, error: type[ExubioError] = ProtocolError) -> dict[str, Any]:
    """Parse a YAML file whose top level must be a mapping.

    Raises ``error`` naming the file when it is missing, unreadable, not valid YAML, has a
    repeated key in a mapping (with its line), nests deeper than MAX_NESTING, or is not a mapping
    at the top.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{p}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{p}: cannot read the file ({exc})") from None
    return _parse(text, str(p), error)


def _parse(text: str, path: str, error: type[ExubioError]) -> dict[str, Any]:
    """The parsed mapping of a file's text. Not cached: a run parses each file once and passes the
    loaded objects on (exubio.run.inputs.Session travels to the study's workers whole)."""
    p = Path(path)
    try:
        _check_nesting(text, p, error)
        _check_duplicate_keys(yaml.compose(text, Loader=yaml.SafeLoader), p, error)
        data = yaml.load(text, Loader=_Loader)  # _Loader is a SafeLoader
    except yaml.YAMLError as exc:
        raise error(f"{p}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise error(f"{p}: expected a mapping of keys at the top level, got {_kind(data)}")
    return data


def _check_nesting(text: str, path: Path, error: type[ExubioError]) -> None:
    """Refuse a file nested deeper than MAX_NESTING, found on YAML's event stream (its parser is
    iterative: no recursion however deep the file) before anything recursive reads it."""
    depth = 0
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_NESTING:
                raise error(f"{path}: line {event.start_mark.line + 1}: nested more than {MAX_NESTING} levels deep "
                            f"(mappings and lists within each other); expected at most {MAX_NESTING}")
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1


def _check_duplicate_keys(node: yaml.Node | None, path: Path, error: type[ExubioError]) -> None:
    """Repeated keys are silently merged by YAML loaders; a copy-pasted marker would vanish."""
    if isinstance(node, yaml.MappingNode):
        seen: dict[Any, int] = {}
        for key_node, value_node in node.value:
            if isinstance(key_node, yaml.ScalarNode):
                line = key_node.start_mark.line + 1
                if key_node.value in seen:
                    raise error(
                        f"{path}: key '{key_node.value}' appears twice in the same mapping "
                        f"(lines {seen[key_node.value]} and {line}); each key must be unique"
                    )
                seen[key_node.value] = line
            _check_duplicate_keys(value_node, path, error)
    elif isinstance(node, yaml.SequenceNode):
        for child in node.value:
            _check_duplicate_keys(child, path, error)


def check_keys(
    mapping: Mapping[str, Any],
    valid: Iterable[str],
    /,
    *,
    where: str,
    source: str,
    error: type[ExubioError] = ProtocolError,
) -> None:
    """Raise ``error`` for the first key of ``mapping`` not in ``valid``: names the file, the key
    with its dotted path (``where``), a close match if any and the valid keys."""
    valid = tuple(valid)
    for key in mapping:
        if key not in valid:
            path = f"{where}.{key}" if where else str(key)
            hint = difflib.get_close_matches(str(key), valid, n=1)
            did = f" (did you mean '{hint[0]}'?)" if hint else ""
            raise error(
                f"{source}: unknown key '{path}'{did}; valid keys"
                f"{' of ' + where if where else ''} are {list(valid)}"
            )


def finite_float(value: Any, /) -> float | None:
    """``value`` as a float when it is a finite real number (YAML int or float; not a bool, a
    string, ``.nan``, ``.inf`` or an integer too large for a float), else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def _kind(value: Any) -> str:
    if value is None:
        return "nothing (empty)"
    return f"{type(value).__name__} {value!r}" if not isinstance(value, (dict, list)) else type(value).__name__


