"""One table of a study's angles for the statistics: ``angles.parquet`` and ``angles.csv.gz``.

One row per trial, method, frame and anatomical angle (exubio.model.angles.ANATOMICAL_ANGLES):
subject, session, trial (the file's stem), task (the session's ``tasks`` key, else the trial's
stem), method, time_s, angle, value_deg, u_deg (standard uncertainty; NaN where the result has
none, inf where the angle is not measured at all), status (measured, modelled, not measured) and
verdict (the trial's verdict of that method) and signs (the sign convention of the trial's files,
exubio.model.signs: isb or clinical; value_deg is in it, as in the per-trial CSV). Text columns are categoricals, numbers float64
(time, value, uncertainty). Read from each trial's ``<trial>.<method>.csv`` and the status in its
``.npz``: the numbers are those of the per-trial files. Written atomically (the Parquet by
pyarrow; the CSV gzip-compressed, the same rows, readable by any statistics tool)."""
from __future__ import annotations

import gzip
import io

from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np

from exubio.errors import InputError
from exubio.io.result_names import beside, method_stem, set_paths
from exubio.method_registry import method_names
from exubio.io.results import atomic_write, read_angles_csv, read_npz_arrays
from exubio.model.signs import SIGNS, signs_of_file
from exubio.trust.observability import AngleStatus

if TYPE_CHECKING:
    import pandas

__all__ = ["TABLE_COLUMNS", "PARQUET", "CSV_GZ", "trial_rows", "study_table", "write_study_table", "read_study_table",
           "table_trials"]

PARQUET = "angles.parquet"
CSV_GZ = "angles.csv.gz"
TABLE_COLUMNS = ("subject", "session", "trial", "task", "method", "time_s", "angle", "value_deg", "u_deg", "status",
                 "verdict", "signs")
_CATEGORICAL = ("subject", "session", "trial", "task", "method", "angle", "status", "verdict", "signs")
_STATUS = tuple(s.label for s in AngleStatus)
_VERDICTS = ("ok", "check", "fail", "")


def trial_rows(npz: Path, /, **keys: str) -> dict[str, np.ndarray]:
    """The long rows of one result (``<trial>.<method>.npz`` and the CSV beside it), with ``keys``
    (subject, session, trial, task, method, verdict) repeated on every row."""
    csv = beside(npz, "csv")
    t, names, values, u = read_angles_csv(csv, uncertainty=True)
    status = read_npz_arrays(npz, ("angle_status",))["angle_status"]
    if status.shape != values.shape:
        raise InputError(f"{npz}: angle_status has shape {status.shape}, the angles of {csv.name} {values.shape}")
    n, a = values.shape
    codes = status.astype(int).T.ravel()
    if codes.size and (codes.min() < 0 or codes.max() >= len(_STATUS)):
        raise InputError(f"{npz}: angle_status holds codes outside 0-{len(_STATUS) - 1}")
    out = {k: np.full(n * a, v, dtype=object) for k, v in keys.items()}
    out.update({"time_s": np.tile(t, a), "angle": np.repeat([s.removesuffix("_deg") for s in names], n).astype(object),
                "value_deg": np.degrees(values.T.ravel()), "u_deg": np.degrees(u.T.ravel()),
                "status": np.asarray(_STATUS, dtype=object)[codes],
                "signs": np.full(n * a, signs_of_file(csv), dtype=object)})
    return out


def study_table(trials: Iterable[tuple[dict, Path]], /) -> "pandas.DataFrame":
    """The table of ``trials``: (keys, npz path) each (trial_rows), in the order given."""
    import pandas as pd

    parts = [trial_rows(npz, **keys) for keys, npz in trials]
    cols = {c: (np.concatenate([p[c] for p in parts]) if parts else np.zeros(0, dtype=object)) for c in TABLE_COLUMNS}
    df = pd.DataFrame({c: cols[c] for c in TABLE_COLUMNS})
    for c in ("time_s", "value_deg", "u_deg"):
        df[c] = df[c].astype("float64")
    for c in _CATEGORICAL:
        cats = {"status": _STATUS, "verdict": _VERDICTS, "signs": SIGNS}.get(c)
        df[c] = pd.Categorical(df[c], categories=cats if cats else list(dict.fromkeys(df[c])))
    return df


def write_study_table(out_dir: Path, trials: Iterable[tuple[dict, Path]], /) -> tuple[Path, Path]:
    """``angles.parquet`` and ``angles.csv.gz`` in out_dir (atomic), the same rows."""
    df = study_table(trials)
    df.attrs = {}
    pq = atomic_write(out_dir / PARQUET, lambda tmp: df.to_parquet(tmp, engine="pyarrow", index=False))
    # no file name and mtime 0 in the gzip header, so the same rows give the same bytes (a study run
    # twice, or resumed; the temporary file's name would otherwise be in it); streamed, not one string

    def write_gz(tmp) -> None:
        with open(tmp, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz_file:
            with io.TextIOWrapper(gz_file, encoding="utf-8", newline="") as text:
                df.to_csv(text, index=False, float_format="%.6f")

    gz = atomic_write(out_dir / CSV_GZ, write_gz)
    return pq, gz


def read_study_table(folder: str | Path, /) -> "pandas.DataFrame":
    """The study's ``angles.parquet`` (InputError naming it when absent or unreadable)."""
    import pandas as pd

    path = Path(folder) / PARQUET
    if not path.is_file():
        raise InputError(f"{path}: not there; expected the output folder of `exubio study` (it writes {PARQUET})")
    try:
        return pd.read_parquet(path, engine="pyarrow")
    except Exception as exc:  # noqa: BLE001 - any reader error is a damaged or foreign file, said
        raise InputError(f"{path}: not a readable Parquet table ({type(exc).__name__}: {exc})") from None


def table_trials(spec, outcomes: Iterable) -> list[tuple[dict, Path]]:
    """(keys, npz) of every method's result of every trial with one, in study order: ``spec`` an
    exubio.run.study.StudySpec, ``outcomes`` its TrialOutcomes."""
    by_key = {(o.subject, o.session, o.trial): o for o in outcomes}
    out = []
    for s in spec.sessions:
        for t in s.trials:
            o = by_key.get((s.subject, s.session, str(t)))
            if o is None or o.status == "failed" and not o.verdicts:
                continue
            for m in method_names():
                npz = set_paths(o.folder, method_stem(t.stem, m))["npz"]
                if npz.is_file():
                    out.append(({"subject": s.subject, "session": s.session, "trial": t.stem, "task": s.tasks.get(t.name, t.stem),
                                 "method": m, "verdict": o.verdicts.get(m) or ""}, npz))
    return out


def tasks_key(value, names: Iterable[str], where: str) -> dict[str, str]:
    """A session's ``tasks`` key checked: {trial file name of the session: task name}."""
    names = sorted(names)
    value = value or {}
    if not isinstance(value, dict) or not all(isinstance(v, str) and v and str(k) in names for k, v in value.items()):
        raise InputError(f"{where}: expected a mapping of this session's trial file names {names} -> a task name, "
                         f"got {value!r}")
    return {str(k): v for k, v in value.items()}
