"""Read and write marker trajectories in C3D files (the only module of exubio that uses ezc3d).

Reading gives metres, labels without subject prefixes, NaN for missing samples, and drops
unlabelled markers (``*12``). Missing samples: a C3D marks them with a negative residual; ezc3d
1.7.2 already returns NaN coordinates for those, and we additionally mask every sample whose
residual is negative or whose coordinates contain NaN, so the (0, 0, 0) placeholder that other
writers store is never taken as a position.

Every file ezc3d reads is read; what exubio reads around is an input finding naming the field
(logged, and in ``Trajectories.input_findings``, which the results carry): a point with an empty
label (not read: no protocol can name it), a label two points carry after prefix stripping (the
first with samples is kept, named), a POINT:UNITS that spells metres another way ("mete",
"meters"), and what exubio.io.c3d_raw reads around in the raw bytes (a vendor's parameter names,
a parameter section longer than it declares, a POINT:RATE of 0 under a header rate). What is
refused names the file, the field and why: a file with no 3-D point (analog channels only, or no
parameters to describe its points), no point with a label, and what ezc3d refuses, said in the
file's terms where it is known (POINT:LABELS missing for POINT:USED points).

What ezc3d cannot read but exubio.io.c3d_raw can put in terms it reads is read through a copy
(``ezc3d_copy``, in a temporary folder, with a finding): an SGI/MIPS (big-endian) file turned to
Intel byte order, a description longer than 127 characters cut, analog channels ezc3d crashes on
(ANALOG:SCALE or OFFSET absent) or refuses (ANALOG:OFFSET stored as floats) left out.

ezc3d silently stops at the end of a truncated file (it returns the frames it could read and
rewrites the header to match), so the frame count declared in the raw 512-byte header is checked
against what was read.

Long trials: the header counts frames in 16 bits, and ezc3d reads at most 65535 frames. A file
whose header says 65535 is read whole here (the point block, with numpy) when POINT:LONG_FRAMES,
TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD or a POINT:FRAMES above 65535 give more frames; with
none of these over a data block that holds more frames, it is refused (the count is unknown).
Writing such a trial stores POINT:LONG_FRAMES and the TRIAL fields, where readers look.

A header that contradicts itself is never read silently: it is checked on the raw bytes before
ezc3d sees the file (exubio.io.c3d_raw; ezc3d crashes or allocates what the header asks). A header
whose last frame is before its first, or whose 65535 (the 16-bit "see POINT:LONG_FRAMES") stands
over a data block of fewer frames and no count elsewhere, is read as the data block holds, with a
warning naming the field; a POINT:LONG_FRAMES that is not a whole number >= 1 is refused.

Writing stores 32-bit floats (C3D "float" format): a position of magnitude x metres comes back
within about 6e-8 * x (well under 1e-6 m for any lab volume).
"""
from __future__ import annotations

import logging
import os
import re
import struct
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from exubio.errors import InputError
from exubio.io.c3d_raw import DEC as _DEC
from exubio.io.c3d_raw import HEADER_CLIPPED as _HEADER_CLIPPED
from exubio.io.c3d_raw import RawCheck, check_raw_header, declared_frame_count, declared_point_count, header_count_findings
from exubio.io.c3d_raw import ezc3d_copy, parameter_records
from exubio.io.heap import release_freed_heap
from exubio.io.c3d_raw import raw_header as _raw_header
from exubio.io.c3d_raw import raw_parameters as _raw_parameters  # noqa: F401 (the tests patch files through it)
from exubio.io.labels import keep_one_per_label
from exubio.io.limits import rate_problem
from exubio.io.results import atomic_write
from exubio.types import Trajectories

logger = logging.getLogger(__name__)

METRES_PER_UNIT = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
_UNLABELLED = re.compile(r"^\*\d+$")
_UNIT_SPELLINGS = {"mete": "m", "meter": "m", "meters": "m", "metre": "m", "metres": "m", "millimeters": "mm",
                   "millimetres": "mm", "centimeters": "cm", "centimetres": "cm"}  # Peak Performance: "mete"


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_c3d(path: str | os.PathLike, /) -> Trajectories:
    """Marker trajectories of a C3D file, in metres (see the module docstring)."""
    path = Path(path)
    raw = check_raw_header(path)
    c3d = _open(path, raw)
    points = c3d["data"]["points"]  # (4, n_markers, n_frames), file units
    residuals = c3d["data"]["meta_points"]["residuals"]
    if points.shape[1] == 0:
        raise InputError(_no_point_reason(path, c3d))
    n_long = _long_frame_count(path, c3d)
    findings = list(raw.notes)
    if n_long is None:
        _check_not_truncated(path, points.shape[2])
        findings += header_count_findings(path, points.shape[2])
    else:  # more frames than the 16-bit header, and so ezc3d, counts
        points, residuals = _read_point_block(path, c3d, n_long)
    params = c3d["parameters"]["POINT"]
    header_rate = c3d["header"]["points"]["frame_rate"]
    del c3d  # ezc3d's per-sample C++ objects: gone before the arrays below are made
    release_freed_heap()  # ezc3d's ~4 kB per frame of 22 markers: 106 MB kept after a 24,000-frame file, 18 MB trimmed
    unit = _units(path, params, findings)
    rate = raw.rate_hz if raw.rate_hz is not None else _rate(path, params, header_rate)
    raw_labels = _labels(path, params, points.shape[1])
    positions = _positions(points, residuals)
    del points, residuals  # the file's arrays: gone before the positions are scaled and selected
    positions *= METRES_PER_UNIT[unit.split()[0]]  # in place: no second whole-trial array
    keep, labels, ignored = _select_markers(path, raw_labels, positions, findings)
    for finding in findings:
        logger.warning("%s", finding)
    n_frames = positions.shape[0]
    return Trajectories(
        labels=tuple(labels),
        positions_m=positions if list(keep) == list(range(positions.shape[1])) else positions[:, keep, :],
        rate_hz=rate,
        time_s=np.arange(n_frames) / rate,
        source=str(path),
        ignored_labels=tuple(ignored),
        units_in_file=unit,
        input_findings=tuple(findings),
    )


def read_c3d_analogs(path: str | os.PathLike, /) -> tuple[tuple[str, ...], tuple[str, ...], float, np.ndarray]:
    """The analog channels of a C3D file: (labels, units (ANALOG:UNITS, "" where absent), rate Hz,
    values (n_samples, n_channels) as ezc3d scales them), the first sample at the first point
    frame's time. A file with no analog channel raises InputError."""
    path = Path(path)
    raw = check_raw_header(path)
    if raw.analogs_unreadable:
        raise InputError(f"{path}: its analog channels cannot be read: {raw.analogs_unreadable}")
    c3d = _open(path, raw)
    analogs = np.asarray(c3d["data"]["analogs"], dtype=float)  # (1, n_channels, n_samples)
    params = c3d["parameters"].get("ANALOG", {})
    if analogs.ndim != 3 or analogs.shape[1] == 0 or analogs.shape[2] == 0:
        raise InputError(f"{path}: no analog channel (ANALOG:USED is 0); the protocol's analog_loads need them")
    labels = tuple(str(x).strip() for x in _value(params, "LABELS"))
    units = tuple(str(x).strip() for x in _value(params, "UNITS")) if "UNITS" in params else ()
    rate = float(c3d["header"]["analogs"]["frame_rate"])
    n = analogs.shape[1]
    labels = labels[:n] + tuple(f"channel{k + 1}" for k in range(len(labels), n))
    units = units[:n] + ("",) * max(0, n - len(units))
    return labels, units, rate, analogs[0].T.copy()


def _open(path: Path, raw: RawCheck | None = None) -> Any:
    """ezc3d's reading of the file; where the raw check says it ``needs_copy`` (SGI/MIPS byte
    order, a description ezc3d misreads, analog channels ezc3d crashes on) of the copy
    exubio.io.c3d_raw.ezc3d_copy makes, written to a temporary file ezc3d reads and removed."""
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if not path.is_file():
        raise InputError(f"{path}: a C3D file was expected, but this is a folder")
    import ezc3d  # deferred: importing ezc3d costs time and only this module needs it

    try:
        if raw is None or not raw.needs_copy:
            return ezc3d.c3d(str(path))
        with tempfile.TemporaryDirectory(prefix="exubio-c3d-") as folder:
            copy = Path(folder) / "copy.c3d"
            copy.write_bytes(ezc3d_copy(path, drop_analogs=bool(raw.analogs_unreadable)))
            return ezc3d.c3d(str(copy))
    except Exception as exc:  # ezc3d raises OSError/RuntimeError/ValueError from C++
        raise InputError(f"{path}: not a readable C3D file ({_ezc3d_refusal(path, exc)})") from exc


def _ezc3d_refusal(path: Path, exc: Exception) -> str:
    """Why ezc3d refused the file, in the file's terms where the cause is known."""
    message = str(exc)
    if path.stat().st_size == 0:
        return "the file is empty (0 bytes)"
    if "OFFSET parameter is not an INT" in message:
        return ("ANALOG:OFFSET is stored as floating-point numbers, where the C3D standard and ezc3d, the C3D "
                "reader exubio uses, want integers; export the trial again, or with its analog channels left out")
    if "format is not standard" in message:
        byte_order, _, header = _raw_header(path)
        section, params = parameter_records(path, byte_order, header[0], path.stat().st_size)
        found = {(p.group, p.name): p for p in params}
        used, labels = found.get(("POINT", "USED")), found.get(("POINT", "LABELS"))
        if used is not None and used.kind == 2:
            n_used = struct.unpack(byte_order + "h", section[used.start:used.start + 2])[0]
            n_labels = (labels.dims[1] if len(labels.dims) > 1 else int(bool(labels.dims))) if labels else 0
            if n_labels < n_used:
                return (f"POINT:USED says {n_used} points but POINT:LABELS holds {n_labels} label(s); ezc3d, the C3D "
                        f"reader exubio uses, refuses points without labels, and no protocol could name them")
        return (f"ezc3d, the C3D reader exubio uses, finds its parameter section not standard ({message.split('.')[0]}"
                f"); exubio's own check of that section found nothing to name")
    return f"{type(exc).__name__}: {message}"


def _no_point_reason(path: Path, c3d: Any) -> str:
    """Why a file ezc3d read holds no 3-D point, and why nothing can be done."""
    declared = declared_point_count(path) or 0
    if declared:
        return (f"{path}: no 3-D point can be read: the header (word 2) declares {declared} points, but the file has "
                f"no POINT parameters to describe them (POINT:USED, POINT:LABELS, POINT:SCALE: the parameter section "
                f"is empty or has no POINT group); without labels no marker can be named, so nothing can be read; "
                f"export the trial again with its parameters")
    n_analog = c3d["data"]["analogs"].shape[1]
    return (f"{path}: no 3-D point: POINT:USED is 0 (analog channels only: {n_analog}); exubio reads marker "
            f"trajectories, so there is nothing to read")


def _check_not_truncated(path: Path, n_read: int) -> None:
    declared = declared_frame_count(path)
    if declared is not None and n_read < declared:
        raise InputError(
            f"{path}: not a readable C3D file (truncated: the header declares {declared} frames, "
            f"only {n_read} could be read)"
        )


def _long_frame_count(path: Path, c3d: Any) -> int | None:
    """The frame count of a file whose header's last frame is clipped at 65535, when its
    parameters give more frames than ezc3d read; None for every other file. A clipped file with
    no such count whose data block holds more frames is refused."""
    byte_order, _, header = _raw_header(path)
    if len(header) < 10 or struct.unpack(byte_order + "H", header[8:10])[0] != _HEADER_CLIPPED:
        return None
    point, trial = c3d["parameters"]["POINT"], c3d["parameters"].get("TRIAL", {})
    long_frames, frames = _value(point, "LONG_FRAMES"), _value(point, "FRAMES")
    start, end = _value(trial, "ACTUAL_START_FIELD"), _value(trial, "ACTUAL_END_FIELD")
    if long_frames:
        value = float(long_frames[0])
        if not (value >= 1 and value == round(value)):
            raise InputError(f"{path}: not a readable C3D file (POINT:LONG_FRAMES is {value:g}; expected the "
                             f"number of frames, a whole number >= 1)")
        count = round(value)
    elif len(start) == 2 and len(end) == 2:  # 32-bit frame numbers as two 16-bit words, low first
        first, last = ((int(v[1]) & 0xFFFF) << 16 | (int(v[0]) & 0xFFFF) for v in (start, end))
        count = last - first + 1
    elif frames and float(frames[0]) > _HEADER_CLIPPED:  # a floating-point POINT:FRAMES (the C3D manual's advice)
        count = round(float(frames[0]))
    else:
        count = None
    n_read = c3d["data"]["points"].shape[2]
    if count is None:
        offset, dtype, words, _ = _point_block_layout(path, c3d)
        spare = path.stat().st_size - offset - n_read * words * dtype.itemsize
        if spare >= 512 + words * dtype.itemsize:  # more than the padding of the last 512-byte block
            raise InputError(
                f"{path}: not a readable C3D file (its header counts frames in 16 bits and says 65535, its data "
                f"block holds more, and no POINT:LONG_FRAMES or TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD says how "
                f"many frames there are)")
    return count if count is not None and count > n_read else None


def _point_block_layout(path: Path, c3d: Any) -> tuple[int, np.dtype, int, float]:
    """(byte offset of the data block, word dtype, words per frame, point scale) as ezc3d reads
    them: data start from the header, float words when POINT:SCALE < 0, else int16 scaled."""
    byte_order, processor, header = _raw_header(path)
    if processor == _DEC:
        raise InputError(f"{path}: a C3D file in DEC (VAX) format with more than 65535 frames is not supported; "
                         f"save it in Intel format")
    data_start = struct.unpack(byte_order + "H", header[16:18])[0]
    scale = ([float(v) for v in _value(c3d["parameters"]["POINT"], "SCALE")]
             or [struct.unpack(byte_order + "f", header[12:16])[0]])[0]
    points, analogs = c3d["data"]["points"], c3d["data"]["analogs"]
    analog_words = analogs.shape[1] * (analogs.shape[2] // points.shape[2]) if points.shape[2] else 0
    dtype = np.dtype(byte_order + ("f4" if scale < 0 else "i2"))
    return (data_start - 1) * 512, dtype, 4 * points.shape[1] + analog_words, abs(scale)


def _read_point_block(path: Path, c3d: Any, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (4, n_markers, n_frames) and their residual words (1, n_markers, n_frames; negative:
    missing) of all ``n_frames`` frames, read from the data block (analog samples skipped)."""
    offset, dtype, words, scale = _point_block_layout(path, c3d)
    available = (path.stat().st_size - offset) // (words * dtype.itemsize)
    if available < n_frames:
        raise InputError(f"{path}: not a readable C3D file (truncated: its parameters declare {n_frames} frames, "
                         f"the data block holds only {available})")
    n_markers = c3d["data"]["points"].shape[1]
    block = np.fromfile(path, dtype=dtype, count=n_frames * words, offset=offset).reshape(n_frames, words)
    xyzr = block[:, : 4 * n_markers].reshape(n_frames, n_markers, 4).astype(float)
    if dtype.kind == "i":  # integer format: coordinates in units of POINT:SCALE
        xyzr[..., :3] *= scale
    return xyzr.transpose(2, 1, 0), xyzr[..., 3].T[None]


def _units(path: Path, params: dict, findings: list[str]) -> str:
    """POINT:UNITS as mm, cm or m; absent: millimetres, and a spelling of one of them ("mete",
    "meters"): that unit, each with a finding; anything else is refused."""
    values = [str(v).strip() for v in _value(params, "UNITS")]
    unit = values[0] if values and values[0] else ""
    if not unit:
        findings.append(f"{path.name}: POINT:UNITS is absent; read as millimetres (the C3D default)")
        return "mm (assumed)"
    if unit.lower() in _UNIT_SPELLINGS:
        findings.append(f"{path.name}: POINT:UNITS is '{unit}'; read as '{_UNIT_SPELLINGS[unit.lower()]}'")
        return _UNIT_SPELLINGS[unit.lower()]
    if unit.lower() not in METRES_PER_UNIT:
        raise InputError(
            f"{path}: POINT:UNITS is '{unit}', expected one of {sorted(METRES_PER_UNIT)}"
        )
    return unit.lower()


def _rate(path: Path, params: dict, header_rate: float) -> float:
    """POINT:RATE, else (absent) the header's rate; one that is not a usable rate is refused."""
    values = np.asarray(_value(params, "RATE"), dtype=float).ravel()
    what = "POINT:RATE" if values.size else "the header's frame rate"
    rate = float(values[0]) if values.size else float(header_rate)
    if rate_problem(rate):
        raise InputError(f"{path}: {what} is {rate_problem(rate)}; expected the marker sampling rate in Hz")
    return rate


def _labels(path: Path, params: dict, n_markers: int) -> list[str]:
    """POINT:LABELS followed by LABELS2, LABELS3, ... (files with more than 255 markers)."""
    labels = [str(v) for v in _value(params, "LABELS")]
    k = 2
    while f"LABELS{k}" in params:
        labels += [str(v) for v in _value(params, f"LABELS{k}")]
        k += 1
    if len(labels) < n_markers:
        raise InputError(f"{path}: POINT:LABELS has {len(labels)} labels for {n_markers} markers")
    return labels[:n_markers]


def _value(params: dict, key: str) -> list:
    entry = params.get(key)
    if not entry or "value" not in entry:
        return []
    value = entry["value"]
    return list(np.atleast_1d(value)) if isinstance(value, np.ndarray) else list(value)


def _positions(points: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """(n_frames, n_markers, 3) float64 with NaN where the residual is negative or a NaN came."""
    xyz = np.asarray(points[:3], dtype=float).transpose(2, 1, 0).copy()
    res = np.asarray(residuals, dtype=float)[0].T  # (n_frames, n_markers)
    missing = (res < 0) | np.isnan(xyz).any(axis=2)
    xyz[missing] = np.nan
    return xyz


def _select_markers(path: Path, raw_labels: list[str], positions: np.ndarray, findings: list[str]
                    ) -> tuple[list[int], list[str], list[str]]:
    """Columns to keep, their stripped labels, and the original labels dropped: unlabelled ``*N``
    markers; empty labels (a finding each: no protocol can name them); points whose label another
    carries after prefix stripping (exubio.io.labels: the first with samples is kept, a finding
    names it). No point left is refused."""
    labels: list[str | None] = []
    for i, raw in enumerate(raw_labels):
        label = strip_prefix(raw)
        if not label:
            n = int(np.isfinite(positions[:, i]).all(axis=1).sum())
            findings.append(f"{path.name}: POINT:LABELS: point {i + 1} has an empty label ({raw!r}, {n} samples); "
                            f"not read, as no protocol can name it")
        labels.append(label if label and not _UNLABELLED.match(label) else None)
    keep = keep_one_per_label(labels, positions, raw=raw_labels, field="POINT:LABELS", name=path.name,
                              findings=findings, column="point")
    ignored = [raw for i, raw in enumerate(raw_labels) if i not in set(keep)]  # in the file's order
    if not keep:
        raise InputError(f"{path}: none of its {len(raw_labels)} points has a label a protocol can name (POINT:LABELS: "
                         f"{', '.join(repr(r) for r in raw_labels[:8])}{', ...' if len(raw_labels) > 8 else ''}); "
                         f"label the markers in the capture software and export again")
    if ignored:
        logger.info("%s: ignoring %d marker(s): %s", path, len(ignored), ignored)
    return keep, [labels[c] for c in keep], ignored


def strip_prefix(label: str) -> str:
    """``"Martin:ARM "`` -> ``"ARM"``: everything up to the last ':' and surrounding spaces go."""
    return label.rsplit(":", 1)[-1].strip()


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------
def write_c3d(path: str | os.PathLike, trajectories: Trajectories, /, *, units: str = "mm") -> Path:
    """Write a C3D file (float format) atomically; NaN samples are stored with residual -1 and
    (0, 0, 0) coordinates, so they read back as NaN here and as gaps in other software."""
    path = Path(path)
    if units not in METRES_PER_UNIT:
        raise InputError(f"{path}: cannot write C3D in units '{units}', expected one of {sorted(METRES_PER_UNIT)}")
    if trajectories.n_frames == 0:
        raise InputError(f"{path}: cannot write a C3D file without frames (trajectories have 0 frames)")
    c3d = _build_c3d(trajectories, units)
    # ezc3d appends ".c3d" to any name not ending in (lower-case) ".c3d": give it one that does
    return atomic_write(path, lambda tmp: c3d.write(str(tmp)), temp_suffix=".c3d")


def _build_c3d(traj: Trajectories, units: str) -> Any:
    import ezc3d

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = np.array([float(traj.rate_hz)])
    point["LABELS"]["value"] = tuple(traj.labels)
    point["UNITS"]["value"] = [units]
    missing = np.isnan(traj.positions_m).any(axis=2)  # (n_frames, n_markers)
    xyz = np.where(missing[..., None], 0.0, traj.positions_m / METRES_PER_UNIT[units])
    points = np.ones((4, traj.n_markers, traj.n_frames))
    points[:3] = xyz.transpose(2, 1, 0)
    residuals = np.where(missing, -1.0, 0.0).T[None, :, :]
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"]["residuals"] = residuals
    if traj.n_frames > _HEADER_CLIPPED:  # the header and POINT:FRAMES stop at 65535: the count where readers look
        from ezc3d import ezc3d as swig

        n = traj.n_frames
        c3d.add_parameter("POINT", "LONG_FRAMES", np.array([float(n)]))
        words = {"ACTUAL_START_FIELD": [1, 0], "ACTUAL_END_FIELD": [n & 0xFFFF, n >> 16]}  # low word first
        c3d["parameters"]["TRIAL"] = {"__METADATA__": {"DESCRIPTION": "", "IS_LOCKED": False}, **{
            name: {"type": swig.INT, "value": np.array(v), "description": "", "is_locked": False}
            for name, v in words.items()}}
    return c3d


def write_c3d_samples(source: str | os.PathLike, path: str | os.PathLike, samples: dict[str, tuple[np.ndarray, np.ndarray]],
                      /, *, group: str = "EXUBIO_FILL") -> Path:
    """A copy of the C3D ``source`` (every point, label, analog channel, parameter and the frame
    numbering kept) with the samples of ``samples`` set: label (as read_c3d names it) -> (frames (n,)
    bool, positions (n, 3) m, used where frames is True; a NaN sample is written missing: residual -1,
    coordinates 0), stored in the file's POINT:UNITS with residual
    0 (the C3D's mark of a point "processed, not the original measured value") and listed in the
    parameter group ``group`` (LABELS, FIRST, LAST: each run of set samples, file frame numbers), since
    files that store residual 0 on measured samples too (Vicon Nexus exports) cannot tell them apart
    by the residual. Written atomically."""
    source, path = Path(source), Path(path)
    raw = check_raw_header(source)
    if raw.analogs_unreadable:
        raise InputError(f"{source}: {raw.analogs_unreadable}: its analog channels cannot be read, so a copy of the "
                         f"file with its samples set cannot be written (it would lose them); fill the gaps in the "
                         f"capture software")
    c3d = _open(source, raw)
    points = c3d["data"]["points"]
    n_frames = points.shape[2]
    if _long_frame_count(source, c3d) is not None:
        raise InputError(f"{source}: more than {_HEADER_CLIPPED} frames; writing its samples back is not supported")
    params = c3d["parameters"]["POINT"]
    unit = _units(source, params, [])
    scale = METRES_PER_UNIT[unit.split()[0]]
    raw_labels = _labels(source, params, points.shape[1])
    first = int(c3d["header"]["points"]["first_frame"]) + 1  # the header counts from 0, C3D frames from 1
    residuals = c3d["data"]["meta_points"]["residuals"]
    runs: list[tuple[str, int, int]] = []
    for label, (frames, pos_m) in samples.items():
        cols = [i for i, raw in enumerate(raw_labels) if strip_prefix(raw) == label]
        if len(cols) != 1:
            raise InputError(f"{source}: POINT:LABELS has {len(cols)} points named '{label}'; expected one to write "
                             f"its samples to")
        frames = np.asarray(frames, dtype=bool)
        if frames.shape != (n_frames,):
            raise InputError(f"{source}: '{label}': {frames.shape[0]} frames to write, the file has {n_frames}")
        xyz = np.asarray(pos_m, dtype=float) / scale
        gone = frames & ~np.isfinite(xyz).all(axis=1)  # a NaN sample is written missing (a gap cut)
        frames = frames & ~gone
        points[:3, cols[0], frames] = xyz[frames].T
        residuals[0, cols[0], frames] = 0.0
        points[:3, cols[0], gone] = 0.0
        residuals[0, cols[0], gone] = -1.0
        edges = np.flatnonzero(np.diff(np.r_[0, frames.astype(int), 0]))
        runs += [(label, int(a) + first, int(b) - 1 + first) for a, b in zip(edges[::2], edges[1::2])]
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"]["residuals"] = residuals
    if runs:
        c3d.add_parameter(group, "LABELS", [r[0] for r in runs])
        c3d.add_parameter(group, "FIRST", np.array([float(r[1]) for r in runs]))
        c3d.add_parameter(group, "LAST", np.array([float(r[2]) for r in runs]))
    return atomic_write(path, lambda tmp: c3d.write(str(tmp)), temp_suffix=".c3d")
