"""Read and write marker trajectories in C3D files (the only module of exubio that uses ezc3d).

Reading gives metres, labels without subject prefixes, NaN for missing samples, and drops
unlabelled markers (``*12``). Missing samples: a C3D marks them with a negative residual; ezc3d
1.7.2 already returns NaN coordinates for those, and we additionally mask every sample whose
residual is negative or whose coordinates contain NaN, so the (0, 0, 0) placeholder that other
writers store is never taken as a position.

ezc3d silently stops at the end of a truncated file (it returns the frames it could read and
rewrites the header to match), so the frame count declared in the raw 512-byte header is checked
against what was read.

Long trials: the header counts frames in 16 bits, and ezc3d reads at most 65535 frames. A file
whose header says 65535 is read whole here (the point block, with numpy) when POINT:LONG_FRAMES,
TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD or a POINT:FRAMES above 65535 give more frames; with
none of these over a data block that holds more frames, it is refused (the count is unknown).
Writing such a trial stores POINT:LONG_FRAMES and the TRIAL fields, where readers look.

A header that contradicts itself is never read silently. Checked on the raw bytes before ezc3d
sees the file (ezc3d crashes or allocates what the header asks): a parameter block or data start
past the end of the file is refused, and so is a rate (header or POINT:RATE) that is not finite, not
> 0 or above exubio.io.limits.MAX_RATE_HZ (the work after reading grows with it). A header whose
last frame is before its first, or whose 65535 (the 16-bit "see POINT:LONG_FRAMES") stands over a
data block of fewer frames and no count elsewhere, is read as the data block holds, with a warning
naming the field (logged, and in ``Trajectories.input_findings``, which the results carry); a
POINT:LONG_FRAMES that is not a whole number >= 1 is refused.

Writing stores 32-bit floats (C3D "float" format): a position of magnitude x metres comes back
within about 6e-8 * x (well under 1e-6 m for any lab volume).
"""
from __future__ import annotations

import logging
import os
import re
import struct
from pathlib import Path
from typing import Any

import numpy as np

from exubio.errors import InputError
from exubio.io.limits import rate_problem
from exubio.io.results import atomic_write
from exubio.types import Trajectories

logger = logging.getLogger(__name__)

METRES_PER_UNIT = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
_UNLABELLED = re.compile(r"^\*\d+$")
_HEADER_CLIPPED = 0xFFFF  # a 16-bit header frame number: long trials store the real count elsewhere
_DEC, _MIPS = 85, 86  # processor type byte of the parameter section (84: Intel)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_c3d(path: str | os.PathLike, /) -> Trajectories:
    """Marker trajectories of a C3D file, in metres (see the module docstring)."""
    path = Path(path)
    _check_raw_header(path)
    c3d = _open(path)
    points = c3d["data"]["points"]  # (4, n_markers, n_frames), file units
    residuals = c3d["data"]["meta_points"]["residuals"]
    n_long = _long_frame_count(path, c3d)
    findings = []
    if n_long is None:
        _check_not_truncated(path, points.shape[2])
        findings += _header_count_findings(path, points.shape[2])
    else:  # more frames than the 16-bit header, and so ezc3d, counts
        points, residuals = _read_point_block(path, c3d, n_long)
    params = c3d["parameters"]["POINT"]
    header_rate = c3d["header"]["points"]["frame_rate"]
    del c3d  # ezc3d's per-sample C++ objects: gone before the arrays below are made
    _release_freed_heap()
    for finding in findings:
        logger.warning("%s", finding)
    unit = _units(path, params)
    rate = _rate(path, params, header_rate)
    raw_labels = _labels(path, params, points.shape[1])
    positions = _positions(points, residuals) * METRES_PER_UNIT[unit.split()[0]]
    keep, labels, ignored = _select_markers(path, raw_labels)
    n_frames = positions.shape[0]
    return Trajectories(
        labels=tuple(labels),
        positions_m=positions[:, keep, :],
        rate_hz=rate,
        time_s=np.arange(n_frames) / rate,
        source=str(path),
        ignored_labels=tuple(ignored),
        units_in_file=unit,
        input_findings=tuple(findings),
    )


def _open(path: Path) -> Any:
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if not path.is_file():
        raise InputError(f"{path}: a C3D file was expected, but this is a folder")
    import ezc3d  # deferred: importing ezc3d costs time and only this module needs it

    try:
        return ezc3d.c3d(str(path))
    except Exception as exc:  # ezc3d raises OSError/RuntimeError/ValueError from C++
        raise InputError(f"{path}: not a readable C3D file ({type(exc).__name__}: {exc})") from exc


def _release_freed_heap() -> None:
    """Give the C heap ezc3d freed back to the system. ezc3d holds every sample as a small C++
    object (~4 kB per frame of 22 markers); freed, they stay in the process's heap (glibc keeps
    fragmented small blocks), which measured 106 MB after reading a 24,000-frame file and 18 MB
    after ``malloc_trim``. Elsewhere than glibc this does nothing."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _check_raw_header(path: Path) -> None:
    """Refuse, before ezc3d reads it, a file whose header points past its end or whose rate is
    unusable (see the module docstring); ezc3d itself gives an error for a header shorter than 512 bytes."""
    if not path.is_file():
        return  # _open says why
    size = path.stat().st_size
    byte_order, processor, header = _raw_header(path)
    if len(header) < 512:
        return
    bad = "not a readable C3D file (the header contradicts the file: "
    param_block = header[0]
    if param_block < 1 or (param_block - 1) * 512 + 4 > size:
        raise InputError(f"{path}: {bad}its first byte puts the parameter block at 512-byte block {param_block}, "
                         f"byte {(max(param_block, 1) - 1) * 512}, but the file has {size} bytes)")
    data_start = struct.unpack(byte_order + "H", header[16:18])[0]
    if data_start < 1 or (data_start - 1) * 512 >= size:
        raise InputError(f"{path}: {bad}its word 9 puts the data at 512-byte block {data_start}, byte "
                         f"{(max(data_start, 1) - 1) * 512}, but the file has {size} bytes)")
    if processor == _DEC:
        return  # VAX floats: ezc3d converts them; the rate is checked after reading (_rate)
    point_rate = _raw_point_rate(path, byte_order, param_block, size)
    if point_rate is not None and rate_problem(point_rate):  # ezc3d crashes on a NaN there
        raise InputError(f"{path}: POINT:RATE is {rate_problem(point_rate)}; expected the marker sampling rate in Hz")


_TYPE_BYTES = {-1: 1, 1: 1, 2: 2, 4: 4}  # C3D parameter types: char, byte, int16, float


def _raw_point_rate(path: Path, byte_order: str, param_block: int, size: int) -> float | None:
    """POINT:RATE read from the raw parameter section (a float, the first value), None when absent:
    ezc3d crashes on a NaN there, so it is looked at before ezc3d. On the way every parameter's
    declared size is checked against the section (``_raw_parameters``)."""
    section, params = _raw_parameters(path, byte_order, param_block, size)
    for group, name, kind, start in params:
        if group == "POINT" and name == "RATE" and kind == 4 and start + 4 <= len(section):
            return float(struct.unpack(byte_order + "f", section[start:start + 4])[0])
    return None


def _raw_parameters(path: Path, byte_order: str, param_block: int, size: int
                    ) -> tuple[bytes, list[tuple[str, str, int, int]]]:
    """The raw parameter section and its parameters (group, name, type, offset of the data). A
    section that contradicts itself is refused: a parameter whose type is unknown or whose
    dimensions declare more data than the section holds, a record whose offset to the next record
    lies inside it or past the section, a group id defined twice, a parameter of a group no record
    defines, a name that is no name. ezc3d reads past its buffers on such sections (segmentation
    faults, measured: a 255 x 255 POINT:LABELS, a parameter turned into a group by one byte)."""
    with open(path, "rb") as fh:
        fh.seek((param_block - 1) * 512)
        section = fh.read(min(size - (param_block - 1) * 512, 512 * 255))
    if len(section) < 4:
        return section, []
    section = section[: max(section[2], 1) * 512]  # byte 3: the section's length in 512-byte blocks
    groups: dict[int, str] = {}
    raw: list[tuple[int, str, int, int, list[int], int]] = []  # group id, name, type, n dims, dims, data start
    bad = "not a readable C3D file (the header contradicts the file: parameter section"

    def refuse(what: str) -> None:
        raise InputError(f"{path}: {bad}: {what})")

    pos = 4
    while pos + 2 <= len(section):
        n_chars, ident = struct.unpack("bb", section[pos:pos + 2])
        if n_chars == 0:
            break
        name = section[pos + 2:pos + 2 + abs(n_chars)].decode("latin-1").upper()
        here = pos + 2 + abs(n_chars)
        if here + 3 > len(section):
            break
        if ident == 0 or not name.isprintable() or " " in name or not name.isascii():
            refuse(f"a record at byte {pos} is named {name!r} in group 0 or with characters that are not a name")
        step = struct.unpack(byte_order + "h", section[here:here + 2])[0]
        if ident < 0:
            if -ident in groups:
                refuse(f"group id {-ident} is defined twice ({groups[-ident]} and {name})")
            groups[-ident] = name
            end = here + 3 + section[here + 2]  # its description
        else:
            kind, n_dims = struct.unpack("bB", section[here + 2:here + 4])
            dims = list(section[here + 4:here + 4 + n_dims])
            name = f"{groups.get(ident, f'group {ident}')}:{name}"
            if kind not in _TYPE_BYTES or n_dims > 7:
                refuse(f"parameter {name} has type {kind} and {n_dims} dimensions; expected a type of -1, 1, 2 or 4 "
                       f"and at most 7")
            start = here + 4 + n_dims
            n_bytes = _TYPE_BYTES[kind] * int(np.prod(dims, dtype=np.int64))
            if start + n_bytes + 1 > len(section):
                refuse(f"parameter {name} declares dimensions {dims}, {n_bytes} bytes, past the end of the "
                       f"{len(section)}-byte section")
            end = start + n_bytes + 1 + section[start + n_bytes]  # its description
            raw.append((ident, name, kind, n_dims, dims, start))
        if end > len(section) or (step > 0 and here + step < end) or here + step > len(section):
            refuse(f"the record {name} at byte {pos} ends at byte {end} but its offset to the next record is {step} "
                   f"(from byte {here}) in a {len(section)}-byte section")
        if step <= 0:
            break
        pos = here + step
    for ident, name, _, _, _, _ in raw:
        if ident not in groups:
            refuse(f"parameter {name} belongs to group {ident}, which no group record defines")
    return section, [(groups[g], name.split(":")[-1], kind, start) for g, name, kind, _, _, start in raw]


def _header_count_findings(path: Path, n_read: int) -> list[str]:
    """Warnings for a header frame count the data block contradicts, read as the data hold: a last
    frame before the first; a last frame of 65535 over fewer frames and no count elsewhere."""
    byte_order, _, header = _raw_header(path)
    if len(header) < 10:
        return []
    first, last = struct.unpack(byte_order + "2H", header[6:10])
    if last < first:
        return [f"{path.name}: the header's last frame (word 5) is {last}, before its first frame (word 4) "
                f"{first}; read the {n_read} frames the data block holds"]
    if last == _HEADER_CLIPPED and n_read < last - first + 1:
        return [f"{path.name}: the header's last frame (word 5) is 65535 (more frames than 16 bits count, "
                f"see POINT:LONG_FRAMES) but there is no POINT:LONG_FRAMES and the data block holds "
                f"{n_read} frames; read those {n_read}"]
    return []


def _check_not_truncated(path: Path, n_read: int) -> None:
    declared = _declared_frame_count(path)
    if declared is not None and n_read < declared:
        raise InputError(
            f"{path}: not a readable C3D file (truncated: the header declares {declared} frames, "
            f"only {n_read} could be read)"
        )


def _raw_header(path: Path) -> tuple[str, int, bytes]:
    """(struct byte order, processor type byte, the raw 512-byte header) of a C3D file."""
    with open(path, "rb") as fh:
        header = fh.read(512)
        fh.seek(max(header[0] - 1, 0) * 512 + 3 if header else 0)
        processor = fh.read(1)
    kind = processor[0] if processor else 0
    return (">" if kind == _MIPS else "<"), kind, header  # MIPS big-endian; Intel, DEC little


def _declared_frame_count(path: Path) -> int | None:
    """Frames declared by the raw header (last - first + 1), None when it cannot say."""
    byte_order, _, header = _raw_header(path)
    if len(header) < 10:
        return None
    first, last = struct.unpack(byte_order + "2H", header[6:10])
    if last == _HEADER_CLIPPED or last < first:
        return None
    return last - first + 1


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


def _units(path: Path, params: dict) -> str:
    values = [str(v).strip() for v in _value(params, "UNITS")]
    unit = values[0] if values and values[0] else ""
    if not unit:
        logger.warning("%s: POINT:UNITS absent, assuming millimetres", path)
        return "mm (assumed)"
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


def _select_markers(path: Path, raw_labels: list[str]) -> tuple[list[int], list[str], list[str]]:
    """Columns to keep, their stripped labels, and the original labels dropped (unlabelled
    ``*N`` markers, empty labels, duplicates after prefix stripping: the first one is kept)."""
    keep: list[int] = []
    labels: list[str] = []
    ignored: list[str] = []
    for i, raw in enumerate(raw_labels):
        label = strip_prefix(raw)
        if not label or _UNLABELLED.match(label):
            ignored.append(raw)
        elif label in labels:
            logger.warning("%s: marker '%s' duplicates '%s' after prefix stripping; keeping the first",
                           path, raw, raw_labels[keep[labels.index(label)]])
            ignored.append(raw)
        else:
            keep.append(i)
            labels.append(label)
    if ignored:
        logger.info("%s: ignoring %d marker(s): %s", path, len(ignored), ignored)
    return keep, labels, ignored


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
