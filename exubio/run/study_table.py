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

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.io.result_names import beside, method_stem, set_paths
from exubio.method_registry import method_names
from exubio.io.results import atomic_write, read_angles_csv, read_npz_arrays
from exubio.run.csv_gz import write_csv_gz
from exubio.model.signs import SIGNS, signs_of_file
from exubio.trust.observability import AngleStatus

if TYPE_CHECKING:
    import pandas

__all__ = ["TABLE_COLUMNS", "PARQUET", "CSV_GZ", "trial_rows", "study_table", "categorical_runs", "write_study_table", "read_study_table",
           "table_trials"]

PARQUET = "angles.parquet"
CSV_GZ = "angles.csv.gz"
TABLE_COLUMNS = ("subject", "session", "trial", "task", "method", "time_s", "angle", "value_deg", "u_deg", "status",
                 "verdict", "signs")
_STATUS = tuple(s.label for s in AngleStatus)
VERDICTS = ("ok", "check", "fail", "")  # the verdict column's categories (a result without one: "")
_FIXED = {"verdict": VERDICTS, "signs": SIGNS}
FLOAT_DECIMALS = 6  # the numbers of angles.csv.gz, printed as "%.6f" (as the per-trial CSV)


def trial_rows(npz: Path, /, **keys: str) -> dict[str, np.ndarray]:
    """The long rows of one result (``<trial>.<method>.npz`` and the CSV beside it), with ``keys``
    (subject, session, trial, task, method, verdict) repeated on every row."""
    part = _read_part(npz, keys)
    n, names = part.time_s.size, part.angles
    out = {k: np.full(part.rows, v, dtype=object) for k, v in keys.items()}
    out.update({"time_s": np.tile(part.time_s, len(names)), "angle": np.repeat(names, n).astype(object),
                "value_deg": part.value_deg, "u_deg": part.u_deg, "status": np.asarray(_STATUS, dtype=object)[part.status],
                "signs": np.full(part.rows, part.signs, dtype=object)})
    return out


@dataclass(frozen=True)
class _Part:
    """One result's rows, held as numbers: its keys are the same on every row, its angles run one
    after the other (each ``time_s.size`` rows), ``status`` the codes of _STATUS."""

    keys: Mapping[str, str]
    time_s: np.ndarray
    angles: tuple[str, ...]
    value_deg: np.ndarray
    u_deg: np.ndarray
    status: np.ndarray
    signs: str

    @property
    def rows(self) -> int:
        return self.time_s.size * len(self.angles)


def _read_part(npz: Path, keys: Mapping[str, str]) -> _Part:
    csv = beside(npz, "csv")
    t, names, values, u = read_angles_csv(csv, uncertainty=True)
    status = read_npz_arrays(npz, ("angle_status",))["angle_status"]
    if status.shape != values.shape:
        raise InputError(f"{npz}: angle_status has shape {status.shape}, the angles of {csv.name} {values.shape}")
    codes = status.astype(int).T.ravel()
    if codes.size and (codes.min() < 0 or codes.max() >= len(_STATUS)):
        raise InputError(f"{npz}: angle_status holds codes outside 0-{len(_STATUS) - 1}")
    return _Part(dict(keys), t, tuple(s.removesuffix("_deg") for s in names), np.degrees(values.T.ravel()),
                 np.degrees(u.T.ravel()), codes, signs_of_file(csv))


def categorical_runs(runs: Iterable[tuple[Sequence[str], int]], /, fixed: Sequence[str] | None = None
                     ) -> "pandas.Categorical":
    """A text column made of runs (values, count): each value on ``count`` rows, one after the
    other, as a categorical: the categories ``fixed``, else the values in order of first appearance
    on a row (a value outside ``fixed`` is missing, as pandas makes it). The same as pandas'
    categorical of the rows' strings, without making them."""
    import pandas as pd

    runs = [(list(values), int(count)) for values, count in runs]
    cats = list(fixed) if fixed is not None else list(dict.fromkeys(v for values, n in runs if n for v in values))
    index = {v: i for i, v in enumerate(cats)}
    codes = [np.repeat(np.array([index.get(v, -1) for v in values], dtype=np.int64), n) for values, n in runs]
    return pd.Categorical.from_codes(_joined(codes, np.int64), categories=cats)


def study_table(trials: Iterable[tuple[dict, Path]], /) -> "pandas.DataFrame":
    """The table of ``trials``: (keys, npz path) each (trial_rows), in the order given. Built from
    each part's numbers and one code per part for its text columns (as fast as the numbers; the
    same frame as categoricals of the rows' strings would give)."""
    import pandas as pd

    parts = [_read_part(npz, keys) for keys, npz in trials]
    sizes = [p.rows for p in parts]
    text = {c: categorical_runs((([p.keys[c]], n) for p, n in zip(parts, sizes)), _FIXED.get(c))
            for c in ("subject", "session", "trial", "task", "method", "verdict")}
    text["signs"] = categorical_runs((([p.signs], n) for p, n in zip(parts, sizes)), _FIXED["signs"])
    text["angle"] = categorical_runs((p.angles, p.time_s.size) for p in parts)
    text["status"] = pd.Categorical.from_codes(_joined([p.status for p in parts], np.int64), categories=list(_STATUS))
    numbers = {"time_s": _joined([np.tile(p.time_s, len(p.angles)) for p in parts], np.float64),
               "value_deg": _joined([p.value_deg for p in parts], np.float64),
               "u_deg": _joined([p.u_deg for p in parts], np.float64)}
    return pd.DataFrame({c: text[c] if c in text else numbers[c] for c in TABLE_COLUMNS})


def _joined(arrays: list[np.ndarray], dtype) -> np.ndarray:
    return np.concatenate(arrays).astype(dtype, copy=False) if arrays else np.zeros(0, dtype=dtype)


def write_study_table(out_dir: Path, trials: Iterable[tuple[dict, Path]], /) -> tuple[Path, Path]:
    """``angles.parquet`` and ``angles.csv.gz`` in out_dir (atomic), the same rows; the Parquet on
    a thread while the CSV is written (pyarrow, polars and the compression run outside Python's lock)."""
    from concurrent.futures import ThreadPoolExecutor

    df = study_table(trials)
    df.attrs = {}
    with ThreadPoolExecutor(1, thread_name_prefix="exubio-parquet") as pool:
        pq = pool.submit(atomic_write, out_dir / PARQUET, lambda tmp: df.to_parquet(tmp, engine="pyarrow", index=False))
        try:
            gz = atomic_write(out_dir / CSV_GZ, lambda tmp: write_csv_gz(tmp, df, FLOAT_DECIMALS))
        finally:
            pq_path = pq.result()  # its error, if any, is the table's
    return pq_path, gz


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
