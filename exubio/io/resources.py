"""Where the shipped model, protocol and example files are: installed as the packages
exubio.models / exubio.protocols / exubio.data, or at the top of a source checkout."""
from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

_CHECKOUT = Path(__file__).resolve().parents[2]  # exubio/io/resources.py -> the checkout


def shipped_file(package: str, name: str, checkout_dir: str) -> Path:
    """Path of a shipped file: from the installed package if there, else from the checkout."""
    try:
        candidate = resources.files(package).joinpath(name)
        if candidate.is_file():
            return Path(str(candidate))
    except ModuleNotFoundError:
        pass
    return _CHECKOUT / checkout_dir / name


def shipped_dir(package: str, checkout_dir: str, probe: str) -> Path:
    """The folder of a shipped package's files (``probe``: one file known to be there)."""
    return shipped_file(package, probe, checkout_dir).parent


def resolve(value: str | Path, package: str, checkout_dir: str, probe: str, /) -> Path:
    """A file the user named: the path if it exists, else, for a bare name (no folder), the
    shipped file of that name, with or without ``.yaml`` (``--protocol upper_limb_21`` works from
    any folder, installed or not). Otherwise the path as given (its reader reports it missing)."""
    path = Path(value)
    if path.is_file() or path.parent != Path("."):
        return path
    folder = shipped_dir(package, checkout_dir, probe)
    for name in (path.name, f"{path.name}.yaml"):
        if (folder / name).is_file():
            return folder / name
    return path


def shipped_beside(value: Any, base: Path, package: str, checkout_dir: str, probe: str, /) -> Any:
    """A file named in a file in folder ``base`` (a study file's protocol or model): the shipped one
    when ``value`` is a bare name that is not a file in ``base``, else ``value`` as given."""
    if isinstance(value, str) and value and not (Path(base) / value).exists() and Path(value).parent == Path("."):
        shipped = resolve(value, package, checkout_dir, probe)
        if shipped.is_file():
            return str(shipped)
    return value


def shipped_names(package: str, checkout_dir: str, probe: str, /) -> list[str]:
    """The names of the shipped YAML files of a package (without .yaml)."""
    return sorted(p.stem for p in shipped_dir(package, checkout_dir, probe).glob("*.yaml"))
