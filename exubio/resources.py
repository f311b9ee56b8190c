"""Where the shipped model, protocol and example files are: installed as the packages
exubio.models / exubio.protocols / exubio.data, or at the top of a source checkout."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

_CHECKOUT = Path(__file__).resolve().parent.parent


def shipped_file(package: str, name: str, checkout_dir: str) -> Path:
    """Path of a shipped file: from the installed package if there, else from the checkout."""
    try:
        candidate = resources.files(package).joinpath(name)
        if candidate.is_file():
            return Path(str(candidate))
    except ModuleNotFoundError:
        pass
    return _CHECKOUT / checkout_dir / name
