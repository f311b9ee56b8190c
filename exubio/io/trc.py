"""Read and write marker trajectories in OpenSim TRC files (tab-separated text).

Layout (1-based line numbers)::

    1  PathFileType  4  (X/Y/Z)  <name>
    2  DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    3  <the values of line 2>
    4  Frame#  Time  m1  <tab> <tab>  m2 ...
    5  <tab> <tab>  X1  Y1  Z1  X2 ...
       data rows (blank lines skipped): frame, time (s), x y z per marker in the Units of line 3;
       an empty cell or NaN is a missing sample.

Reading converts to metres and takes the sample times from the Time column, which must be finite,
increasing and on the DataRate of line 3 (row i at the first time + i / DataRate, within half a
sample); anything else is refused naming the line. A NumFrames that disagrees with the data rows is
read from the rows, as OpenSim does (published files are off by a row or more), with a warning
naming the header value that also goes into the result (``Trajectories.input_findings``). So is a
NumMarkers that disagrees with line 4's labels when the rows hold as many markers as there are labels
(a Motion Analysis Cortex file lists 34 labels under NumMarkers=28); labels and rows that disagree are
refused. A label on two or more markers keeps the first with samples, and a label left empty in its
place is not read, each with a finding (exubio.io.labels). A DataRate
above exubio.io.limits.MAX_RATE_HZ is refused (the work after reading grows with it). Writing prints
positions with a resolution of 1e-9 m whatever the unit (mm: 6 decimals) and times with 10
significant digits; missing samples become empty cells.
"""
from __future__ import annotations

import logging
import math
import os
from pathlib import Path

import numpy as np

from exubio.errors import InputError
from exubio.io.labels import keep_one_per_label
from exubio.io.limits import rate_problem
from exubio.io.results import atomic_write
from exubio.types import Trajectories

logger = logging.getLogger(__name__)

METRES_PER_UNIT = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
_DECIMALS = {"mm": 6, "cm": 7, "m": 9}  # 1e-9 m printed resolution in every unit
_HEADER_KEYS = ("DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units",
                "OrigDataRate", "OrigDataStartFrame", "OrigNumFrames")
_FIRST_DATA_LINE = 6


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_trc(path: str | os.PathLike, /) -> Trajectories:
    """Marker trajectories of a TRC file, in metres."""
    path = Path(path)
    lines = _read_lines(path)
    header = _header(path, lines)
    unit, rate, n_frames, n_declared = _header_values(path, header)
    findings: list[str] = []
    raw_labels = _marker_labels(path, lines, n_declared, findings)
    n_markers = len(raw_labels)
    time, coords, line_nos = _data(path, lines, n_markers)
    if time.shape[0] != n_frames:
        findings.append(f"{path.name}: line 3: NumFrames is {n_frames} but the file has {time.shape[0]} data rows; "
                        f"read the {time.shape[0]} rows (as OpenSim does)")
        logger.warning("%s", findings[-1])
    if time.shape[0] == 0:
        raise InputError(f"{path}: no data rows after line {_FIRST_DATA_LINE - 1}; expected at least one frame")
    _check_rate(path, time, line_nos, rate)
    positions = coords.reshape(-1, n_markers, 3) * METRES_PER_UNIT[unit]
    before = len(findings)
    for i in (i for i, label in enumerate(raw_labels) if not label):
        findings.append(f"{path.name}: line 4: marker {i + 1} (columns {3 + 3 * i}-{5 + 3 * i}) has an empty label "
                        f"({int(np.isfinite(positions[:, i]).all(axis=1).sum())} samples); not read, as no protocol "
                        f"can name it")
    keep = keep_one_per_label([label or None for label in raw_labels], positions, raw=list(raw_labels),
                              field="line 4", name=path.name, findings=findings, column="marker")
    for finding in findings[before:]:
        logger.warning("%s", finding)
    if not keep:
        raise InputError(f"{path}: line 4: none of its {n_markers} markers has a label; expected one per marker")
    return Trajectories(
        labels=tuple(raw_labels[i] for i in keep),
        positions_m=positions[:, keep],
        ignored_labels=tuple(raw_labels[i] for i in range(n_markers) if i not in set(keep)),
        rate_hz=rate,
        time_s=time,
        source=str(path),
        units_in_file=unit,
        input_findings=tuple(findings),
    )


def _read_lines(path: Path) -> list[str]:
    if not path.exists():
        raise InputError(f"{path}: file not found")
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read as a TRC text file ({exc})") from exc
    lines = text.splitlines()
    if len(lines) < 5:
        raise InputError(f"{path}: not a TRC file: {len(lines)} lines, expected at least 5 header lines")
    return lines


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.split("\t")]


def _header(path: Path, lines: list[str]) -> dict[str, str]:
    """The key/value pairs of lines 2-3, after checking line 1."""
    if _cells(lines[0])[0] != "PathFileType":
        raise InputError(f"{path}: line 1: expected 'PathFileType ...', got {lines[0][:60]!r}")
    keys = [k for k in _cells(lines[1]) if k]
    values = _cells(lines[2])
    if len(values) < len(keys) or any(not v for v in values[: len(keys)]):
        raise InputError(f"{path}: line 3: expected {len(keys)} values for {keys}, got {values}")
    return dict(zip(keys, values))


def _header_values(path: Path, header: dict[str, str]) -> tuple[str, float, int, int]:
    for key in ("DataRate", "NumFrames", "NumMarkers", "Units"):
        if key not in header:
            raise InputError(f"{path}: line 2: no '{key}' column; found {list(header)}")
    unit = header["Units"]
    if unit.lower() not in METRES_PER_UNIT:
        raise InputError(f"{path}: line 3: Units is '{unit}', expected one of {sorted(METRES_PER_UNIT)}")
    try:
        rate = float(header["DataRate"])
        n_frames = int(header["NumFrames"])
        n_markers = int(header["NumMarkers"])
    except ValueError:
        raise InputError(
            f"{path}: line 3: DataRate/NumFrames/NumMarkers must be numbers, got "
            f"{header['DataRate']!r}/{header['NumFrames']!r}/{header['NumMarkers']!r}"
        ) from None
    if not (rate > 0 and math.isfinite(rate)) or n_frames < 0 or n_markers < 0:
        raise InputError(f"{path}: line 3: expected DataRate > 0, NumFrames >= 0, NumMarkers >= 0; got {header}")
    if rate_problem(rate):
        raise InputError(f"{path}: line 3: DataRate is {rate_problem(rate)}")
    return unit.lower(), rate, n_frames, n_markers


def _marker_labels(path: Path, lines: list[str], n_declared: int, findings: list[str]) -> list[str]:
    """The labels of line 4 ("" for one left empty in its place). A NumMarkers (line 3) that
    disagrees with them is read from the labels when the data rows hold as many markers (a finding
    names both); otherwise refused."""
    cells = _cells(lines[3])
    if cells[:2] != ["Frame#", "Time"]:
        raise InputError(f"{path}: line 4: expected 'Frame#<tab>Time<tab>labels...', got {lines[3][:60]!r}")
    labels = [c for c in cells[2:] if c]
    if len(labels) == n_declared:
        return labels
    row = next((line for line in lines[_FIRST_DATA_LINE - 1:] if line.strip()), "")
    width = len(row.rstrip("\r\n").split("\t"))
    at = [cells[2 + 3 * k] if 2 + 3 * k < len(cells) else "" for k in range(n_declared)]
    if row and width == 2 + 3 * n_declared and sum(map(bool, at)) == len(labels):
        return at  # a label left empty in its place: said and left out by read_trc
    if row and width == 2 + 3 * len(labels):
        findings.append(f"{path.name}: line 3: NumMarkers is {n_declared} but line 4 has {len(labels)} marker labels "
                        f"and the data rows {width} columns (2 + 3 x {len(labels)}); read the {len(labels)} markers "
                        f"of line 4 and the rows")
        logger.warning("%s", findings[-1])
        return labels
    raise InputError(f"{path}: line 4: {len(labels)} marker labels, but line 3 says NumMarkers={n_declared}"
                     + (f" and the first data row has {width} columns ({(width - 2) / 3:g} markers)" if row else ""))


def _data(path: Path, lines: list[str], n_markers: int) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Time column (n_frames,), coordinates (n_frames, 3 n_markers) in file units and the line
    number of each row. Times must be finite and increasing; coordinates finite or missing."""
    n_columns = 2 + 3 * n_markers
    times: list[float] = []
    rows: list[list[float]] = []
    line_nos: list[int] = []
    for line_no, line in enumerate(lines[_FIRST_DATA_LINE - 1 :], start=_FIRST_DATA_LINE):
        if not line.strip():
            continue
        cells = _cells(line)
        if len(cells) < n_columns or any(cells[n_columns:]):
            n_found = len(cells) if len(cells) < n_columns else max(i + 1 for i, c in enumerate(cells) if c)
            raise InputError(f"{path}: line {line_no}: {n_found} columns, expected {n_columns} (2 + 3 x {n_markers} markers)")
        values = _floats(path, line_no, cells[1:n_columns])
        if not cells[1]:
            raise InputError(f"{path}: line {line_no}: the Time cell is empty")
        if not math.isfinite(values[0]):
            raise InputError(f"{path}: line {line_no}: Time is '{cells[1]}'; expected a finite number of seconds")
        if times and not values[0] > times[-1]:
            raise InputError(f"{path}: line {line_no}: Time {cells[1]} s is not after {times[-1]:g} s on line "
                             f"{line_nos[-1]}; the Time column must increase")
        bad = next((c for c, v in zip(cells[2:n_columns], values[1:]) if math.isinf(v)), None)
        if bad is not None:
            raise InputError(f"{path}: line {line_no}: coordinate '{bad}' is not finite; a missing sample is an "
                             f"empty cell or NaN")
        times.append(values[0])
        rows.append(values[1:])
        line_nos.append(line_no)
    return np.array(times, dtype=float), np.array(rows, dtype=float).reshape(len(rows), 3 * n_markers), line_nos


def _check_rate(path: Path, time: np.ndarray, line_nos: list[int], rate: float) -> None:
    """Row i must be at time[0] + i / DataRate within half a sample: a DataRate the Time column
    contradicts (or rows missing or repeated) is refused, naming the first line off the grid."""
    expected = time[0] + np.arange(time.shape[0]) / rate if time.size else time
    off = np.flatnonzero(np.abs(time - expected) > 0.5 / rate)
    if off.size:
        i = int(off[0])
        raise InputError(
            f"{path}: line {line_nos[i]}: Time is {time[i]:g} s, but line 3's DataRate {rate:g} Hz puts data row "
            f"{i + 1} at {expected[i]:g} s (a step of {1 / rate:g} s); the DataRate and the Time column disagree "
            f"(a wrong DataRate, or rows missing)"
        )


def _floats(path: Path, line_no: int, cells: list[str]) -> list[float]:
    try:
        return [float(c) if c else math.nan for c in cells]
    except ValueError:
        bad = next(c for c in cells if c and not _is_float(c))
        raise InputError(f"{path}: line {line_no}: '{bad}' is not a number") from None


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------
def write_trc(path: str | os.PathLike, trajectories: Trajectories, /, *, units: str = "mm") -> Path:
    """Write an OpenSim TRC file atomically, positions in ``units`` (mm, cm or m)."""
    path = Path(path)
    if units not in METRES_PER_UNIT:
        raise InputError(f"{path}: cannot write TRC in units '{units}', expected one of {sorted(METRES_PER_UNIT)}")
    for label in trajectories.labels:
        if not label or label != label.strip() or any(c in label for c in "\t\r\n"):
            raise InputError(f"{path}: marker label {label!r} cannot be written to a TRC header")
    text = _header_text(path.name, trajectories, units) + _rows_text(trajectories, units)

    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)

    return atomic_write(path, writer)


def _header_text(name: str, traj: Trajectories, units: str) -> str:
    n, m, rate = traj.n_frames, traj.n_markers, f"{traj.rate_hz:g}"
    values = (rate, rate, str(n), str(m), units, rate, "1", str(n))
    labels = "".join(f"\t{label}\t\t" for label in traj.labels)
    axes = "".join(f"\tX{i}\tY{i}\tZ{i}" for i in range(1, m + 1))
    return (
        f"PathFileType\t4\t(X/Y/Z)\t{name}\n"
        + "\t".join(_HEADER_KEYS) + "\n"
        + "\t".join(values) + "\n"
        + f"Frame#\tTime{labels}\n"
        + f"\t{axes}\n"
        + "\n"
    )


def _rows_text(traj: Trajectories, units: str) -> str:
    coords = traj.positions_m.reshape(traj.n_frames, -1) / METRES_PER_UNIT[units]
    fmt = f"{{:.{_DECIMALS[units]}f}}"
    lines = []
    for i, (t, row) in enumerate(zip(traj.time_s, coords)):
        cells = ["" if math.isnan(v) else fmt.format(v) for v in row.tolist()]
        lines.append(f"{i + 1}\t{t:.10g}\t" + "\t".join(cells) + "\n")
    return "".join(lines)


def write_trc_samples(source: str | os.PathLike, path: str | os.PathLike,
                      samples: dict[str, tuple[np.ndarray, np.ndarray]], /) -> Path:
    """A copy of the TRC ``source`` with the samples of ``samples`` set: label -> (frames (n,) bool over
    its data rows, positions (n, 3) m, used where frames is True; NaN: written as empty cells), printed in the file's Units at
    1e-9 m resolution; every other line and cell is copied byte for byte (header, frame numbers,
    times, the other markers). Which samples were set is not marked in a TRC (its format has no
    place for it): the caller writes that beside it. Written atomically."""
    source, path = Path(source), Path(path)
    lines = _read_lines(source)
    unit, _, _, n_declared = _header_values(source, _header(source, lines))
    raw_labels = _marker_labels(source, lines, n_declared, [])
    text = source.read_text(encoding="utf-8")
    raw_lines = text.splitlines(keepends=True)
    rows = [i for i in range(_FIRST_DATA_LINE - 1, len(raw_lines)) if raw_lines[i].strip()]
    fmt = f"{{:.{_DECIMALS[unit]}f}}"
    for label, (frames, pos_m) in samples.items():
        cols = [k for k, lab in enumerate(raw_labels) if lab == label]
        if len(cols) != 1:
            raise InputError(f"{source}: line 4 names '{label}' {len(cols)} times; expected once to write its samples")
        frames = np.asarray(frames, dtype=bool)
        if frames.shape != (len(rows),):
            raise InputError(f"{source}: '{label}': {frames.shape[0]} frames to write, the file has {len(rows)} rows")
        xyz = np.asarray(pos_m, dtype=float) / METRES_PER_UNIT[unit]
        for r in np.flatnonzero(frames):
            line = raw_lines[rows[r]]
            body = line.rstrip("\r\n")
            cells = body.split("\t")
            c = 2 + 3 * cols[0]
            finite = np.isfinite(xyz[r]).all()  # a NaN sample is written missing (empty cells: a gap cut)
            cells[c:c + 3] = [fmt.format(v) if finite else "" for v in xyz[r]]
            raw_lines[rows[r]] = "\t".join(cells) + line[len(body):]
    out = "".join(raw_lines)

    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(out)

    return atomic_write(path, writer)
