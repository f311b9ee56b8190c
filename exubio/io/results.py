"""Write (and read back) reconstruction results: angle CSV, OpenSim .mot, .npz archive, JSON.

Every file is written atomically, and the files of one result are one result set, complete or
absent, written by one run at a time: exubio.io.result_set (its names are re-exported here, where
the writers use them).

Angles are radians in memory and degrees in the CSV and .mot files (labelled: the .mot header says
``inDegrees=yes``; the CSV holds degrees in every coordinate column, time in seconds).

Each writer sits beside its reader so that every round trip is seen (and tested,
tests/io/test_io_results.py) together.
"""
from __future__ import annotations

import io
import json
import logging
import math
import os
import zipfile
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.io.result_set import (EMPTY_LOCK_GRACE_S, ResultSet, atomic_write, claim, done_with,  # noqa: F401 - re-exported
                                  in_progress, prepare_output_dir, remove_after_interrupt, remove_in_progress,
                                  remove_leftovers, writable_folder)
from exubio.io.result_set import _write_text
from exubio.types import Gap, Reconstruction

logger = logging.getLogger(__name__)

_ANGLE_FORMAT = "%.6f"  # degrees: 1e-6 deg printed resolution
_TIME_FORMAT = "%.6f"  # seconds


# --------------------------------------------------------------------------------------------
# Angles: CSV and OpenSim .mot
# --------------------------------------------------------------------------------------------
def _check_angles(path: Path, time_s: np.ndarray, names: Sequence[str], q_rad: np.ndarray, *, n_more: int = 0) -> tuple:
    """(time, names, q) checked: q holds the columns of all ``names`` but the last ``n_more``."""
    time = np.asarray(time_s, dtype=float)
    q = np.asarray(q_rad, dtype=float)
    names = tuple(str(n) for n in names)
    if time.ndim != 1:
        raise InputError(f"{path}: time must be 1-D, got shape {time.shape}")
    if q.shape != (time.shape[0], len(names) - n_more):
        raise InputError(
            f"{path}: angles have shape {q.shape}, expected (n_frames, n_coordinates) = "
            f"({time.shape[0]}, {len(names) - n_more})"
        )
    if len(set(names)) != len(names):
        raise InputError(f"{path}: duplicate coordinate names in {list(names)}")
    for name in names:
        if not name or name != name.strip() or any(c in name for c in ",\t\r\n\""):
            raise InputError(
                f"{path}: coordinate name {name!r} cannot be a column header "
                f"(expected a non-empty name without commas, tabs, quotes or surrounding spaces)"
            )
    return time, names, q


TABLE_BLOCK_ROWS = 5000  # text tables are formatted and written this many rows at a time (~3 MB of text a block)


def _table_text(time: np.ndarray, q_deg: np.ndarray, sep: str) -> str:
    if time.shape[0] == 0:
        return ""
    buf = io.StringIO()
    fmt = [_TIME_FORMAT] + [_ANGLE_FORMAT] * q_deg.shape[1]
    np.savetxt(buf, np.column_stack([time, q_deg]), fmt=fmt, delimiter=sep)
    return buf.getvalue()


def _write_table(path: Path, head: str, time: np.ndarray, q_rad: np.ndarray, sep: str,
                 as_is: np.ndarray | None = None, *, paired: np.ndarray | None = None,
                 after: np.ndarray | None = None) -> Path:
    """``head`` then the rows (time, degrees; the columns ``as_is`` (bool mask) unconverted),
    formatted a block of rows at a time (a long trial's table is never one string in memory).
    ``paired`` (same shape as ``q_rad``): each of its columns right after q_rad's; ``after``: more
    columns after q_rad's; both joined a block at a time (no whole-trial copy of the joined table)."""
    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(head)
            for a in range(0, time.shape[0], TABLE_BLOCK_ROWS):
                b = min(a + TABLE_BLOCK_ROWS, time.shape[0])
                rows = q_rad[a:b] if paired is None else np.stack([q_rad[a:b], paired[a:b]], axis=2).reshape(b - a, -1)
                rows = rows if after is None else np.column_stack([rows, after[a:b]])
                block = np.degrees(rows)
                if as_is is not None:
                    block[:, as_is] = rows[:, as_is]
                fh.write(_table_text(time[a:b], block, sep))

    return atomic_write(path, writer)


UNCERTAINTY_SUFFIX = "_u_deg"
"""The column of an angle's standard uncertainty, beside ``<angle>_deg`` in the angles CSV."""


def write_angles_csv(
    path: str | os.PathLike, time_s: np.ndarray, coordinate_names: Sequence[str], q_rad: np.ndarray, /, *,
    comments: Sequence[str] = (), uncertainty_rad: np.ndarray | None = None,
) -> Path:
    """Plain CSV: optional ``# comment`` lines (e.g. the Euler sequences of ISB angles), the header
    ``time_s,<coordinate names as in the model>``, then one row per frame, time in seconds and
    angles in DEGREES, ``%.6f``. NaN is written ``nan``. ``uncertainty_rad`` (n, a): each angle's
    standard uncertainty, written in degrees in a column ``<angle>_u_deg`` right after the angle's
    (``<name>_deg``; ``inf`` where the angle is not measured at all)."""
    path = Path(path)
    time, names, q = _check_angles(path, time_s, coordinate_names, q_rad)
    head = "".join(f"# {c}\n" for c in comments)
    u = None
    if uncertainty_rad is not None:
        u = np.asarray(uncertainty_rad, dtype=float)
        if u.shape != q.shape:
            raise InputError(f"{path}: uncertainty has shape {u.shape}, the angles {q.shape}")
        names = tuple(c for n in names for c in (n, n.removesuffix("_deg") + UNCERTAINTY_SUFFIX))
    return _write_table(path, head + ",".join(("time_s",) + names) + "\n", time, q, ",", paired=u)


def read_angles_csv(path: str | os.PathLike, /, *, uncertainty: bool = False):
    """Read a file of ``write_angles_csv``: (time_s, coordinate names, q in radians), the uncertainty
    columns left out; with ``uncertainty``, also their values (n, a) rad, NaN where the file has none."""
    path = Path(path)
    lines = _read_lines(path)
    skip = next((i for i, line in enumerate(lines) if not line.startswith("#")), len(lines))
    lines = lines[skip:]
    if not lines or lines[0].split(",")[0].strip() != "time_s":
        raise InputError(f"{path}: line {skip + 1}: expected a header starting with 'time_s', got {lines[:1]}")
    header = lines[0].split(",")
    names = tuple(h.strip() for h in header[1:])
    table = _parse_table(path, lines[1:], len(header), first_line=skip + 2)
    is_u = np.array([n.endswith(UNCERTAINTY_SUFFIX) for n in names], dtype=bool)
    angles = tuple(n for n, u in zip(names, is_u) if not u)
    values = np.radians(table[:, 1:][:, ~is_u])
    if not uncertainty:
        return table[:, 0].copy(), angles, values
    u_of = {n.removesuffix(UNCERTAINTY_SUFFIX): j for j, n in enumerate(names) if is_u[j]}
    u = np.full(values.shape, np.nan)
    for k, n in enumerate(angles):
        j = u_of.get(n.removesuffix("_deg"))
        if j is not None:
            u[:, k] = np.radians(table[:, 1 + j])
    return table[:, 0].copy(), angles, values, u


def as_in_table(values: np.ndarray, /) -> np.ndarray:
    """``values`` as a table of ``write_angles_csv`` gives them back: each printed ``%.6f`` and read
    (what a reader of the file draws; the report of a result in memory draws the same)."""
    v = np.asarray(values, dtype=float)
    return np.array([float(_ANGLE_FORMAT % x) for x in v.ravel()], dtype=float).reshape(v.shape)


def as_in_json(data: Mapping[str, Any], /, *, strict: bool = True) -> Any:
    """``data`` as its JSON file gives it back: ``write_json``'s (strict: NaN/inf -> None) or the
    .npz's metadata (not strict)."""
    return json.loads(_dumps(data, strict=strict))


def read_angles_comments(path: str | os.PathLike, /) -> list[str]:
    """The ``# comment`` lines at the head of a file of ``write_angles_csv`` (without the '# ')."""
    path = Path(path)
    out = []
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                out.append(line[1:].strip())
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from exc
    return out


def write_mot(
    path: str | os.PathLike,
    time_s: np.ndarray,
    coordinate_names: Sequence[str],
    q_rad: np.ndarray,
    /,
    *,
    name: str = "exubio",
    notes: Sequence[str] = (),
    metres: Sequence[str] = (),
    more: np.ndarray | None = None,
) -> Path:
    """OpenSim motion file (.mot, storage version 1): angles in degrees (``inDegrees=yes``),
    tab-separated, ``time`` then the coordinates. ``notes``: single-line ``key=value`` remarks
    written in the header before ``endheader`` (e.g. coordinates that are not measurements).
    ``metres``: coordinates that are translations (m; e.g. the thorax's free joint,
    exubio.export.thorax): written as they are (OpenSim converts only rotational coordinates).
    ``more`` (n, j): the last j coordinates' values, after q_rad's (n, len(names) - j) columns
    (joined a block of rows at a time: no whole-trial copy of the joined table)."""
    path = Path(path)
    extra = None if more is None else np.asarray(more, dtype=float)
    j = 0 if extra is None else extra.shape[-1]
    time, names, q = _check_angles(path, time_s, coordinate_names, q_rad, n_more=j)
    if extra is not None and extra.shape != (time.shape[0], j):
        raise InputError(f"{path}: the further columns have shape {extra.shape}, expected ({time.shape[0]}, {j})")
    if "\n" in name or "\r" in name:
        raise InputError(f"{path}: .mot name must be a single line, got {name!r}")
    if any("\n" in n or "\r" in n or "=" not in n for n in notes):
        raise InputError(f"{path}: .mot header notes must be single 'key=value' lines, got {list(notes)!r}")
    header = (
        f"{name}\nversion=1\nnRows={time.shape[0]}\nnColumns={len(names) + 1}\n"
        f"inDegrees=yes\n" + "".join(f"{n}\n" for n in notes) + "endheader\n" + "\t".join(("time",) + names) + "\n"
    )
    unknown = sorted(set(metres) - set(names))
    if unknown:
        raise InputError(f"{path}: metres names {unknown}, which are not columns of the .mot")
    as_is = np.array([n in set(metres) for n in names], dtype=bool) if metres else None
    return _write_table(path, header, time, q, "\t", as_is, after=extra)


def read_mot(path: str | os.PathLike, /) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """Read an OpenSim .mot/.sto of angles: (time_s, coordinate names, q in radians).
    Honours ``inDegrees`` (yes: degrees converted to radians; no: radians kept)."""
    path = Path(path)
    lines = _read_lines(path)
    header, body_start = _mot_header(path, lines)
    if body_start >= len(lines):
        raise InputError(f"{path}: no column line after 'endheader'")
    columns = [c.strip() for c in lines[body_start].split("\t")]
    if columns[0].lower() != "time":
        raise InputError(f"{path}: line {body_start + 1}: expected first column 'time', got '{columns[0]}'")
    rows = [
        _parse_row(path, body_start + 2 + i, line.split("\t"), len(columns))
        for i, line in enumerate(lines[body_start + 1 :])
        if line.strip()
    ]
    table = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    _check_mot_counts(path, header, table.shape)
    in_degrees = header.get("indegrees", "no").lower() == "yes"
    q = np.radians(table[:, 1:]) if in_degrees else table[:, 1:]
    return table[:, 0].copy(), tuple(columns[1:]), q


def _mot_header(path: Path, lines: list[str]) -> tuple[dict[str, str], int]:
    header: dict[str, str] = {}
    for i, line in enumerate(lines):
        text = line.strip()
        if text.lower() == "endheader":
            return header, i + 1
        if "=" in text:
            key, value = text.split("=", 1)
            header[key.strip().lower()] = value.strip()
    raise InputError(f"{path}: not a .mot file: no 'endheader' line in {len(lines)} lines")


def _check_mot_counts(path: Path, header: Mapping[str, str], shape: tuple[int, int]) -> None:
    for key, actual in (("nrows", shape[0]), ("ncolumns", shape[1])):
        if key in header and header[key] != str(actual):
            raise InputError(f"{path}: header says {key}={header[key]} but the table has {actual}")


def _read_lines(path: Path) -> list[str]:
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return fh.read().splitlines()
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from exc


def _parse_table(path: Path, lines: list[str], n_columns: int, /, *, first_line: int) -> np.ndarray:
    """The numbers of the table's lines (blank ones skipped), (rows, n_columns): numpy's compiled
    reader (the same doubles as float() of each cell), else, for a line it refuses, the line named."""
    body = [line for line in lines if line.strip()]
    try:
        table = np.loadtxt(body, delimiter=",", dtype=float, ndmin=2, comments=None)
        if table.shape[1] == n_columns or not body:
            return table.reshape(len(body), n_columns)
    except ValueError:
        pass
    rows = [_parse_row(path, first_line + i, line.split(","), n_columns) for i, line in enumerate(lines) if line.strip()]
    return np.array(rows, dtype=float).reshape(len(rows), n_columns)


def _parse_row(path: Path, line_no: int, cells: list[str], n_columns: int) -> list[float]:
    if len(cells) != n_columns:
        raise InputError(f"{path}: line {line_no}: {len(cells)} columns, expected {n_columns}")
    try:
        return [float(c) for c in cells]
    except ValueError:
        raise InputError(f"{path}: line {line_no}: non-numeric value in {cells}") from None


# --------------------------------------------------------------------------------------------
# Full results: .npz
# --------------------------------------------------------------------------------------------
_NPZ_ARRAYS = (
    "time_s",
    "q_rad",
    "qd_rad_s",
    "qdd_rad_s2",
    "model_points_m",
    "measured_m",
    "residuals_m",
    "constraint",
    "constraint_velocity",
    "status",
)


def write_npz(path: str | os.PathLike, reconstruction: Reconstruction, /, *, metadata: Mapping[str, Any],
              extra_arrays: Mapping[str, np.ndarray] | None = None, streamed: Mapping[str, Any] | None = None) -> Path:
    """Every array of ``reconstruction`` (names as string arrays, gaps as three parallel arrays,
    timings/info as JSON) plus ``metadata`` JSON-encoded in the string entry ``metadata_json``,
    and ``extra_arrays`` (e.g. ``undetermined``: (n, m) bool, coordinates the markers do not
    determine in that frame). Uncompressed, loadable with ``np.load(path)`` (no pickle), the same
    layout as ``np.savez``. ``streamed``: arrays the reconstruction does not hold in memory (e.g.
    ``model_points_m`` of exubio.io.streamed), as objects with ``shape``, ``dtype``, ``complete``
    and ``blocks()`` (their rows in order), copied into the archive a block at a time."""
    rec = reconstruction
    streamed = dict(streamed or {})
    for key, source in streamed.items():
        if key not in _NPZ_ARRAYS or getattr(rec, key) is not None:
            raise ValueError(f"write_npz: streamed '{key}' must be a reconstruction entry it does not hold")
        if not source.complete:
            raise ValueError(f"write_npz: streamed '{key}' is incomplete")
    arrays: dict[str, Any] = {key: streamed.get(key, None) if key in streamed else np.asarray(getattr(rec, key))
                              for key in _NPZ_ARRAYS}
    for key, value in (extra_arrays or {}).items():
        if key in arrays or key in _NPZ_RESERVED:
            raise ValueError(f"write_npz: extra array '{key}' would replace a reconstruction entry")
        arrays[key] = np.asarray(value)
    arrays.update(
        method=np.array(rec.method),
        coordinate_names=np.array(rec.coordinate_names, dtype=str),
        marker_names=np.array(rec.marker_names, dtype=str),
        gap_markers=np.array([g.marker for g in rec.gaps], dtype=str),
        gap_start=np.array([g.start for g in rec.gaps], dtype=np.int64),
        gap_stop=np.array([g.stop for g in rec.gaps], dtype=np.int64),
        timings_json=np.array(_dumps(dict(rec.timings_s), strict=False)),
        info_json=np.array(_dumps(dict(rec.info), strict=False)),
        metadata_json=np.array(_dumps(dict(metadata), strict=False)),
    )

    def writer(tmp: Path) -> None:
        with zipfile.ZipFile(tmp, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for key, value in arrays.items():
                with zf.open(key + ".npy", "w", force_zip64=True) as fh:
                    if isinstance(value, np.ndarray):
                        np.lib.format.write_array(fh, value, allow_pickle=False)
                    else:  # rows from a file, a block at a time
                        header = {"descr": np.lib.format.dtype_to_descr(np.dtype(value.dtype)),
                                  "fortran_order": False, "shape": tuple(value.shape)}
                        np.lib.format.write_array_header_1_0(fh, header)
                        for block in value.blocks():
                            fh.write(np.ascontiguousarray(block, dtype=value.dtype).tobytes())

    return atomic_write(path, writer)


_NPZ_RESERVED = {"method", "coordinate_names", "marker_names", "gap_markers", "gap_start", "gap_stop",
                 "timings_json", "info_json", "metadata_json"}


POINT_ARRAYS = ("model_points_m", "measured_m")
"""The per-marker 3-D arrays of a result (~1 kB per frame with 22 markers): what a reader that only
needs the angles and residuals leaves on disk (``read_npz(..., points=False)``)."""


def read_npz(path: str | os.PathLike, /, *, points: bool = True) -> Reconstruction:
    """The Reconstruction stored by ``write_npz`` (metadata: see ``read_npz_metadata``). ``points``
    False: the model points and measured markers (POINT_ARRAYS) are not read (None), e.g. for a
    report of a long trial."""
    with _NpzReader(Path(path)) as data:
        gaps = tuple(
            Gap(str(m), int(a), int(b)) for m, a, b in zip(data["gap_markers"], data["gap_start"], data["gap_stop"])
        )
        return Reconstruction(
            method=str(data["method"]),
            coordinate_names=tuple(str(n) for n in data["coordinate_names"]),
            marker_names=tuple(str(n) for n in data["marker_names"]),
            timings_s=json.loads(str(data["timings_json"])),
            info=json.loads(str(data["info_json"])),
            gaps=gaps,
            **{key: (None if not points and key in POINT_ARRAYS else data[key]) for key in _NPZ_ARRAYS},
        )


def read_npz_metadata(path: str | os.PathLike, /) -> dict[str, Any]:
    """The ``metadata`` dict given to ``write_npz``."""
    with _NpzReader(Path(path)) as data:
        return json.loads(str(data["metadata_json"]))


def read_npz_arrays(path: str | os.PathLike, keys: Sequence[str], /) -> dict[str, np.ndarray]:
    """Extra arrays that ``write_npz`` stored (e.g. ``angle_status``, ``angle_names``,
    ``undetermined``); an InputError names the file and a key it lacks."""
    with _NpzReader(Path(path)) as data:
        return {k: np.asarray(data[k]) for k in keys}


class _NpzReader:
    """np.load with InputErrors naming the file and a missing key."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> "_NpzReader":
        try:
            self.data = np.load(self.path, allow_pickle=False)
        except FileNotFoundError:
            raise InputError(f"{self.path}: file not found") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # BadZipFile: truncated, damaged
            raise InputError(f"{self.path}: not a readable .npz file ({type(exc).__name__}: {exc}); expected an "
                             f"exubio result <trial>.<method>.npz, whole") from None
        if not isinstance(self.data, np.lib.npyio.NpzFile):  # a .npy array under an .npz name
            raise InputError(f"{self.path}: not an .npz archive (a single array: a .npy file?); expected an exubio "
                             f"result <trial>.<method>.npz")
        return self

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self.data[key]
        except KeyError:
            raise InputError(
                f"{self.path}: no entry '{key}' (not an exubio result?); entries are {sorted(self.data.files)}"
            ) from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # a damaged member (CRC, short)
            raise InputError(f"{self.path}: entry '{key}' is not readable ({type(exc).__name__}: {exc}); the file "
                             f"is damaged") from None

    def __exit__(self, *exc: object) -> None:
        self.data.close()


# --------------------------------------------------------------------------------------------
# JSON
# --------------------------------------------------------------------------------------------
def write_json(path: str | os.PathLike, data: Mapping[str, Any], /) -> Path:
    """Strict JSON, indent 2: numpy scalars/arrays become numbers/lists, tuples lists, paths
    strings, and NaN/inf become null."""
    return _write_text(path, _dumps(data, strict=True, indent=2) + "\n")


def _dumps(data: Any, *, strict: bool, indent: int | None = None) -> str:
    """JSON text. strict: NaN/inf → null (valid JSON); otherwise kept (Python's NaN extension),
    for exact round trips inside the .npz."""
    return json.dumps(_jsonable(data, strict), indent=indent, allow_nan=not strict)


def _jsonable(obj: Any, strict: bool) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v, strict) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist(), strict)
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [_jsonable(v, strict) for v in obj]
    if isinstance(obj, np.generic):
        return _jsonable(obj.item(), strict)
    if isinstance(obj, float):
        return None if strict and not math.isfinite(obj) else obj
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    raise TypeError(f"cannot write {type(obj).__name__} to JSON: {obj!r}")
