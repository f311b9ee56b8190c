"""The generalized forces of a reconstruction as an OpenSim storage file (``.sto``, version 1), the
file OpenSim's inverse dynamics tool writes (``inverse_dynamics.sto``): ``<stem>.<method>.moments.sto``.

Format (what OpenSim's Storage and TimeSeriesTable read): a name line, ``version=1``,
``nRows=<frames>``, ``nColumns=<1 + coordinates>``, ``inDegrees=no``, exubio's own ``key=value``
lines (body mass, hand load, inertia source, where q'' came from, PF's inertia scale), ``endheader``,
then the tab-separated column line ``time`` and one column per coordinate named as OpenSim's ID
tool names its output: ``<coordinate>_moment`` (N m) for a rotational coordinate, ``<coordinate>_force``
(N) for a translational one. The coordinates are the model's (those of the .osim exported with
``coordinates="model"``, whose ID on the same q, q', q'' gives these numbers: tests/dynamics/test_moments_outputs.py).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np

from exubio.errors import InputError
from exubio.io.results import atomic_write

__all__ = ["GENERALIZED_FORCE_SUFFIXES", "sto_columns", "write_generalized_forces_sto"]

GENERALIZED_FORCE_SUFFIXES = {"_generalized_force_Nm": "_moment", "_generalized_force_N": "_force"}
"""Moment-table column suffix (exubio.dynamics.moments) -> OpenSim ID output suffix."""


def sto_columns(columns: tuple[str, ...] | list[str], /) -> list[tuple[int, str]]:
    """(index in ``columns``, OpenSim name) of every generalized-force column of a moment table."""
    out = []
    for j, c in enumerate(columns):
        for suffix, osim in GENERALIZED_FORCE_SUFFIXES.items():
            if c.endswith(suffix):
                out.append((j, c[: -len(suffix)] + osim))
    return out


def _clean(value: object) -> str:
    return " ".join(str(value).replace("=", ":").split())


def write_generalized_forces_sto(path: str | os.PathLike, moments, /, *, name: str = "Inverse Dynamics Generalized Forces",
                                 notes: Mapping[str, object] | None = None) -> Path:
    """Write the generalized forces of ``moments`` (exubio.dynamics.moments.Moments) at ``path``
    (atomically) as the module docstring says; ``notes``: further ``key=value`` header lines (a
    value's ``=`` and line breaks are written as ``:`` and spaces)."""
    path = Path(path)
    picked = sto_columns(moments.columns)
    if not picked:
        raise InputError(f"{path}: the moment table has no generalized-force column (<coordinate>_generalized_force_Nm)")
    time = np.asarray(moments.time_s, dtype=float)
    values = np.asarray(moments.values, dtype=float)[:, [j for j, _ in picked]]
    head = {"body_mass_kg": f"{moments.body_mass_kg:g}", "hand_load_kg": f"{moments.hand_load_kg:g}",
            "inertia_source": moments.inertia_source, "units": "N m (_moment), N (_force), s",
            **{k: v for k, v in (moments.info or {}).items()}, **dict(notes or {})}
    lines = [_clean(name), "version=1", f"nRows={time.shape[0]}", f"nColumns={len(picked) + 1}", "inDegrees=no"]
    lines += [f"{_clean(k)}={_clean(v)}" for k, v in head.items()]
    text = "\n".join(lines) + "\nendheader\n" + "\t".join(["time"] + [n for _, n in picked]) + "\n"

    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
            if time.shape[0]:
                np.savetxt(fh, np.column_stack([time, values]), fmt="%.12g", delimiter="\t")

    return atomic_write(path, writer)
