"""The file names of a result set, in one place: ``<trial>.<method>`` is a set's stem, and each kind
of file in it has its suffix. The writer (exubio.run.trial_files), the resumption of a run
(exubio.run.resume), the pipeline and the readers of a result (the report, the study table, the
viewer) name the files through here; the writing itself (atomic, all or nothing, locks, journal) is
exubio.io.result_set's, the formats exubio.io.results'."""
from __future__ import annotations

from pathlib import Path

__all__ = ["CORE", "SUFFIXES", "beside", "method_stem", "set_names", "set_paths", "stem_of"]

SUFFIXES = {
    "thorax": ".thorax.csv",  # the thorax's motion in the lab (with the joint moments, when measured)
    "moments": ".moments.csv",  # the joint moments (exubio.dynamics)
    "moments_sto": ".moments.sto",  # ... as OpenSim's inverse dynamics tool writes them
    "csv": ".csv",  # the anatomical angles (degrees) with their status and uncertainty
    "mot": ".mot",  # the same for OpenSim
    "npz": ".npz",  # everything
    "summary": ".summary.json",  # the figures and the verdict: written last, the set is complete once it is there
}
"""Every kind of file a result set may hold, in the order they are written (summary.json last)."""

CORE = ("csv", "mot", "npz", "summary")
"""The files every result set holds."""


def stem_of(trial_path: str | Path, method: str, /) -> str:
    """A result set's stem: ``<trial file's stem>.<method>``."""
    return method_stem(Path(trial_path).stem, method)


def method_stem(trial_stem: str, method: str, /) -> str:
    """A result set's stem from the trial's stem (a name that may hold dots): ``<trial_stem>.<method>``."""
    return f"{trial_stem}.{method}"


def set_names(stem: str, /, *, moments: bool = False, thorax: bool = False) -> dict[str, str]:
    """The file name of each kind of file of the set ``stem``, in the order they are written: the
    CORE files, and with ``moments`` the moments' CSV and .sto, with ``thorax`` the thorax's motion."""
    kinds = [k for k in SUFFIXES if k in CORE or (moments and k.startswith("moments")) or (thorax and k == "thorax")]
    return {kind: f"{stem}{SUFFIXES[kind]}" for kind in kinds}


def set_paths(out_dir: str | Path, stem: str, /) -> dict[str, Path]:
    """The paths of the CORE files of the set ``stem`` in ``out_dir``."""
    return {kind: Path(out_dir) / name for kind, name in set_names(stem).items()}


def beside(npz_path: str | Path, kind: str, /) -> Path:
    """The file of ``kind`` (a key of SUFFIXES) of the set whose .npz is ``npz_path``."""
    p = str(npz_path)
    return Path((p[: -len(SUFFIXES["npz"])] if p.endswith(SUFFIXES["npz"]) else p) + SUFFIXES[kind])
