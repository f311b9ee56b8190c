"""Read and write marker trajectories in C3D files (the only module of exubio that uses ezc3d).

Reading gives metres, labels without subject prefixes, NaN for missing samples, and drops
unlabelled markers (``*12``). Missing samples: a C3D marks them with a negative residual; ezc3d
1.7.2 already returns NaN coordinates for those, and we additionally mask every sample whose
residual is negative or whose coordinates contain NaN, so the (0, 0, 0) placeholder that other
writers store is never taken as a position.

ezc3d silently stops at the end of a truncated file (it returns the frames it could read and
rewrites the header to match), so the frame count declared in the raw 512-byte header is checked
against what was read.

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
from exubio.io.results import atomic_write
from exubio.types import Trajectories

logger = logging.getLogger(__name__)

METRES_PER_UNIT = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
_UNLABELLED = re.compile(r"^\*\d+$")
_HEADER_CLIPPED = 0xFFFF  # a 16-bit header frame number: long trials store the real count elsewhere


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_c3d(path: str | os.PathLike, /) -> Trajectories:
    """Marker trajectories of a C3D file, in metres (see the module docstring)."""
    path = Path(path)
    c3d = _open(path)
    points = c3d["data"]["points"]  # (4, n_markers, n_frames), file units
    _check_not_truncated(path, points.shape[2])
    params = c3d["parameters"]["POINT"]
    unit = _units(path, params)
    rate = _rate(path, params, c3d["header"]["points"]["frame_rate"])
    raw_labels = _labels(path, params, points.shape[1])
    positions = _positions(points, c3d["data"]["meta_points"]["residuals"]) * METRES_PER_UNIT[unit.split()[0]]
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


def _check_not_truncated(path: Path, n_read: int) -> None:
    declared = _declared_frame_count(path)
    if declared is not None and n_read < declared:
        raise InputError(
            f"{path}: not a readable C3D file (truncated: the header declares {declared} frames, "
            f"only {n_read} could be read)"
        )


def _declared_frame_count(path: Path) -> int | None:
    """Frames declared by the raw header (last - first + 1), None when it cannot say."""
    with open(path, "rb") as fh:
        header = fh.read(512)
        param_block = header[0]
        fh.seek(max(param_block - 1, 0) * 512 + 3)
        processor = fh.read(1)
    if len(header) < 10:
        return None
    byte_order = ">" if processor == b"\x56" else "<"  # 86 = MIPS (big-endian); Intel, DEC little
    first, last = struct.unpack(byte_order + "2H", header[6:10])
    if last == _HEADER_CLIPPED or last < first:
        return None
    return last - first + 1


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
    values = np.asarray(_value(params, "RATE"), dtype=float).ravel()
    rate = float(values[0]) if values.size else float(header_rate)
    if not rate > 0:
        rate = float(header_rate)
    if not rate > 0:
        raise InputError(f"{path}: POINT:RATE is {values.tolist()} and the header rate {header_rate}; expected > 0")
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
    return c3d
