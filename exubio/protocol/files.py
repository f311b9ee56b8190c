"""Where protocol files are: a shipped protocol by name or a file, the other arm's protocol, and a
protocol's mapping read with the protocols it ``extends`` merged in (exubio.protocol.load checks it)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any


from exubio.errors import ProtocolError
from exubio.io.resources import resolve, shipped_file, shipped_names
from exubio.io.yaml import _kind, check_keys, read_yaml
from exubio.protocol.keys import SCHEMA_VERSION, _TOP_KEYS



def resolve_protocol(value: str | os.PathLike[str], /) -> Path:
    """A protocol file the user named: a path, or the name of a shipped protocol ("upper_limb_21")."""
    return resolve(value, "exubio.protocols", "protocols", "upper_limb_21.yaml")


def shipped_protocols() -> list[str]:
    """The names of the shipped protocols."""
    return shipped_names("exubio.protocols", "protocols", "upper_limb_21.yaml")


def find_other_arm(path: str | os.PathLike[str], /) -> Path:
    """The protocol file a protocol's ``other_arm`` names: next to it, else a shipped one of that name;
    ProtocolError naming the file when it has no other_arm, or the one named is not found."""
    src = resolve_protocol(path)
    ref = read_protocol_mapping(src).get("other_arm")
    if not isinstance(ref, str) or not ref.strip():
        raise ProtocolError(f"{src}: no other_arm key; --both-arms needs it (other_arm: <the other arm's protocol "
                            f"file>), or give --protocol twice, one per arm")
    return _find_base(ref, Path(src), "other_arm")


def read_protocol_mapping(path: str | os.PathLike[str], /) -> dict[str, Any]:
    """The top-level mapping of a protocol file with its ``extends`` chain merged in (what
    load_protocol validates): for code that needs the file's own words, such as the ``point:``
    each marker names. Raises ProtocolError like load_protocol for unreadable files, unknown keys,
    a wrong schema_version or a broken ``extends``."""
    return _read_extended(resolve_protocol(path), ())[0]


def _read_extended(path: Path, seen: tuple[Path, ...]) -> tuple[dict[str, Any], dict[str, str]]:
    """The top-level mapping of a protocol file, merged over the file it ``extends`` (whose keys it
    replaces), and for each key the file it comes from. Every file in the chain is checked for
    unknown keys and its schema_version."""
    src = str(path)
    data = read_yaml(path, error=ProtocolError)
    check_keys(data, _TOP_KEYS, where="", source=src)
    if "schema_version" not in data:
        raise ProtocolError(f"{src}: missing key 'schema_version'; expected 'schema_version: {SCHEMA_VERSION}'")
    version = data["schema_version"]
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        raise ProtocolError(
            f"{src}: schema_version is {version!r}; this exubio reads schema_version {SCHEMA_VERSION}"
        )
    own = {key: src for key in data if key != "extends"}
    if "extends" not in data:
        return data, own
    base = _find_base(data["extends"], path)
    chain = (*seen, path.resolve())
    if base.resolve() in chain:
        names = " -> ".join(str(p) for p in (*chain, base.resolve()))
        raise ProtocolError(f"{src}: extends: '{data['extends']}' leads back to a file already in the chain ({names})")
    merged, origin = _read_extended(base, chain)
    merged = {**merged, **{k: v for k, v in data.items() if k != "extends"}}
    return merged, {**origin, **own}


def _find_base(ref: Any, path: Path, key: str = "extends") -> Path:
    """The file an ``extends:`` names: relative to the extending file's folder, else a shipped
    protocol of that name (with or without .yaml)."""
    src = str(path)
    if not isinstance(ref, str) or not ref.strip():
        raise ProtocolError(f"{src}: {key} must be the name of a protocol file, got {_kind(ref)}")
    ref = ref.strip()
    local = path.parent / ref
    if local.is_file():
        return local
    shipped_dir = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols").parent
    for name in (ref, f"{ref}.yaml"):
        candidate = shipped_dir / name
        if Path(name).name == name and candidate.is_file():
            return candidate
    shipped = sorted(p.name for p in shipped_dir.glob("*.yaml"))
    raise ProtocolError(
        f"{src}: {key}: '{ref}' not found; looked for {local} and among the shipped protocols {shipped}"
    )
