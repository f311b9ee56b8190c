"""A study's joint moments: the session keys that ask for them and one long table of them.

A session with ``body_mass_kg`` (kg; or every session, with ``exubio study --body-mass``) and
optionally ``hand_load_kg`` has its trials reconstructed with the joint moments
(``<trial>.<method>.moments.csv`` and ``.sto``, exubio.dynamics). ``moments.parquet`` and
``moments.csv.gz`` hold them all: one row per trial, method, frame and quantity (every column of
the moments CSV: the joint moments N m, the same per kg N m/kg, the generalized forces and girdle
torques N m, the scapulothoracic contact forces N): subject, session, trial, task, method, time_s,
quantity, value (SI), unit, body_mass_kg, hand_load_kg, verdict. The numbers are those of the
per-trial files (read back from them). Written atomically, like angles.parquet
(exubio.run.study_table); ``exubio.load_study(folder, table="moments")`` reads it.
"""
from __future__ import annotations

import io
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Mapping

import numpy as np

from exubio.errors import InputError
from exubio.io.result_names import beside, method_stem, set_paths
from exubio.io.results import atomic_write
from exubio.run.csv_gz import gzip_writer
from exubio.run.study_table import VERDICTS, categorical_runs

if TYPE_CHECKING:
    import pandas

__all__ = ["SESSION_KEYS", "PARQUET", "CSV_GZ", "MOMENT_COLUMNS", "session_moments", "moments_study_table",
           "write_moments_table", "read_moments_table", "unit_of", "moments_as_asked"]

SESSION_KEYS = ("body_mass_kg", "hand_load_kg")
PARQUET = "moments.parquet"
CSV_GZ = "moments.csv.gz"
MOMENT_COLUMNS = ("subject", "session", "trial", "task", "method", "time_s", "quantity", "value", "unit",
                  "body_mass_kg", "hand_load_kg", "verdict")
_CATEGORICAL = ("subject", "session", "trial", "task", "method", "quantity", "unit", "verdict")


def session_moments(raw: Mapping[str, Any], where: str, /, *, default_mass_kg: float | None = None
                    ) -> tuple[float | None, float | None]:
    """(body mass kg or None, hand load kg or None: no moments) of a session mapping of the study
    file (its ``body_mass_kg``, else ``default_mass_kg``: ``--body-mass``); InputError naming the key."""
    def number(key: str, minimum_exclusive: bool) -> float | None:
        v = raw.get(key)
        if v is None:
            return None
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and (
            v > 0 if minimum_exclusive else v >= 0)
        if not ok:
            raise InputError(f"{where}.{key}: expected a number {'> 0' if minimum_exclusive else '>= 0'} (kg), got {v!r}")
        return float(v)

    mass = number("body_mass_kg", True)
    load = number("hand_load_kg", False)
    mass = mass if mass is not None else default_mass_kg
    if load is not None and mass is None:
        raise InputError(f"{where}.hand_load_kg: the joint moments need the subject's body mass too: give "
                         "body_mass_kg in the session (or --body-mass)")
    return mass, (None if mass is None else float(load or 0.0))


def unit_of(column: str) -> str:
    """The unit of a moments CSV column, from its suffix."""
    for suffix, unit in (("_Nm_per_kg", "N m/kg"), ("_Nm", "N m"), ("_N", "N")):
        if column.endswith(suffix):
            return unit
    raise InputError(f"moments column '{column}': expected a name ending in _Nm, _Nm_per_kg or _N")


def _trial_part(csv: Path, summary: Mapping[str, Any], keys: Mapping[str, str]) -> dict[str, Any]:
    """One result's moments as numbers and runs of text (exubio.run.study_table.categorical_runs)."""
    from exubio.dynamics.moments_file import read_moments_csv

    t, columns, values = read_moments_csv(csv)
    n, k = values.shape
    m = (summary.get("moments") or {})
    runs = {key: ([v], n * k) for key, v in keys.items()}
    runs.update({"quantity": (list(columns), n), "unit": ([unit_of(c) for c in columns], n)})
    return {"runs": runs, "time_s": np.tile(t, k), "value": values.T.ravel(),
            "body_mass_kg": np.full(n * k, float(m.get("body_mass_kg", np.nan))),
            "hand_load_kg": np.full(n * k, float(m.get("hand_load_kg", np.nan)))}


def moments_study_table(trials: Iterable[tuple[dict, Path]], /) -> "pandas.DataFrame":
    """The long table of ``trials`` ((keys, npz path) each, exubio.run.study_table.table_trials):
    the results with a moments CSV beside their .npz, in the order given."""
    import json

    import pandas as pd

    parts = []
    for keys, npz in trials:
        csv = beside(npz, "moments")
        if not csv.is_file():
            continue
        summary_path = beside(npz, "summary")
        summary = json.loads(summary_path.read_text(encoding="utf-8")) if summary_path.is_file() else {}
        parts.append(_trial_part(csv, summary, keys))
    cols = {}
    for c in MOMENT_COLUMNS:
        if c in _CATEGORICAL:
            cols[c] = categorical_runs((p["runs"][c] for p in parts), VERDICTS if c == "verdict" else None)
        else:
            cols[c] = np.concatenate([p[c] for p in parts]).astype("float64") if parts else np.zeros(0)
    return pd.DataFrame(cols)


def write_moments_table(out_dir: Path, trials: Iterable[tuple[dict, Path]], /) -> tuple[Path, Path] | None:
    """``moments.parquet`` and ``moments.csv.gz`` in out_dir (atomic), when any result has moments."""
    df = moments_study_table(trials)
    if df.empty:
        return None
    pq = atomic_write(out_dir / PARQUET, lambda tmp: df.to_parquet(tmp, engine="pyarrow", index=False))

    def write_gz(tmp) -> None:  # the same bytes for the same rows (no name, mtime 0), as angles.csv.gz
        with open(tmp, "wb") as raw, gzip_writer(raw) as gz_file:
            with io.TextIOWrapper(gz_file, encoding="utf-8", newline="") as text:
                df.to_csv(text, index=False, float_format="%.9g")

    return pq, atomic_write(out_dir / CSV_GZ, write_gz)


def read_moments_table(folder: str | Path, /) -> "pandas.DataFrame":
    """The study's ``moments.parquet`` (InputError naming it when absent or unreadable)."""
    import pandas as pd

    path = Path(folder) / PARQUET
    if not path.is_file():
        raise InputError(f"{path}: not there; `exubio study` writes it when a session has body_mass_kg (or with "
                         "--body-mass): the joint moments")
    try:
        return pd.read_parquet(path, engine="pyarrow")
    except Exception as exc:  # noqa: BLE001 - any reader error is a damaged or foreign file, said
        raise InputError(f"{path}: not a readable Parquet table ({type(exc).__name__}: {exc})") from None


def moments_as_asked(folder: Path, stem: str, methods: Iterable[str], body_mass_kg: float | None,
                     hand_load_kg: float | None, /) -> bool:
    """Whether a complete trial folder of an earlier run holds the moments its session asks for now:
    none asked, or every method's summary.json there with a ``moments`` entry of the same body mass
    and hand load (otherwise the trial is run again: a set without them, or with others, is not kept)."""
    import json

    if body_mass_kg is None:
        return True
    for m in methods:
        path = set_paths(folder, method_stem(stem, m))["summary"]
        if not path.is_file():  # that method failed in the earlier run: nothing of it to keep or redo here
            continue
        try:
            entry = json.loads(path.read_text(encoding="utf-8")).get("moments")
        except (OSError, ValueError):
            return False
        if not entry or entry.get("body_mass_kg") != body_mass_kg or entry.get("hand_load_kg") != hand_load_kg:
            return False
    return True
