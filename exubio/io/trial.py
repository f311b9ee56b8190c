"""Read a trial's marker trajectories from whichever supported file it is (by suffix)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

from exubio.errors import InputError
from exubio.types import Trajectories


def _read_c3d(path: Path) -> Trajectories:
    from exubio.io.c3d import read_c3d  # deferred: keeps ezc3d out of TRC-only runs

    return read_c3d(path)


def _read_trc(path: Path) -> Trajectories:
    from exubio.io.trc import read_trc

    return read_trc(path)


_READERS: dict[str, Callable[[Path], Trajectories]] = {".c3d": _read_c3d, ".trc": _read_trc}


def read_trial(path: str | os.PathLike, /) -> Trajectories:
    """Marker trajectories (metres) of a .c3d or .trc file (suffix case-insensitive)."""
    path = Path(path)
    reader = _READERS.get(path.suffix.lower())
    if reader is None:
        raise InputError(
            f"{path}: unsupported trial file type '{path.suffix}'; expected one of {sorted(_READERS)}"
        )
    if not path.is_file():
        raise InputError(f"{path}: file not found" if not path.exists() else f"{path}: not a file")
    return reader(path)
