"""External loads from a CSV file (``--loads FILE.csv``), low-pass filtered with the markers' filter
and resampled onto the trial's frames: exubio.dynamics.loads.ExternalLoad.

The file: optional ``#`` comment lines, a header line, then one row per sample, comma-separated:

=========================  =====================================================================
column                     meaning
=========================  =====================================================================
``time_s``                 sample time, s (strictly increasing, uniformly sampled, covering every
                           frame of the trial: its first to its last sample time)
``fx_N, fy_N, fz_N``       the force the environment applies to the body, N
``mx_Nm, my_Nm, mz_Nm``    a free moment (couple) it applies, N m
``px_m, py_m, pz_m``       the point of application, m, in the model frame of ``segment``
                           (origin: the segment's proximal joint centre; axes: the thorax's in
                           the model's reference posture, carried by the segment)
``segment``                the model segment the point is fixed in (humerus, ulna, radius, hand,
                           clavicle, scapula); the same in every row
``frame``                  the frame of the force and moment: lab | thorax | segment; the same in
                           every row
=========================  =====================================================================

Filter: the protocol's low-pass (order and cut-off; with cut-off "auto", the median of the cut-offs
the markers got) at the file's own rate, zero-lag (exubio.prep.filtering.lowpass), then a cubic
spline through the filtered samples evaluated at the trial's frame times. A bad file gets one
InputError naming the file, the column (and row) and what was expected.
"""
from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from exubio.dynamics.loads import LOAD_FRAMES, ExternalLoad
from exubio.errors import InputError
from exubio.prep.filtering import lowpass

__all__ = ["LOAD_COLUMNS", "NUMERIC_COLUMNS", "read_loads_csv", "resample_load"]

NUMERIC_COLUMNS = ("time_s", "fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm", "px_m", "py_m", "pz_m")
LOAD_COLUMNS = (*NUMERIC_COLUMNS, "segment", "frame")
UNIFORM_TOLERANCE = 0.01  # sample intervals within 1 % of their median
COVER_TOLERANCE_S = 1e-6


def _rows(path: Path) -> tuple[list[str], list[list[str]], int]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"{path}: cannot read the loads file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: the loads file is not UTF-8 text (expected a CSV file)") from None
    lines = text.splitlines()
    skip = 0
    while skip < len(lines) and (lines[skip].startswith("#") or not lines[skip].strip()):
        skip += 1
    table = list(csv.reader(lines[skip:]))
    table = [r for r in table if any(c.strip() for c in r)]
    if not table:
        raise InputError(f"{path}: the loads file has no header line; expected the columns {list(LOAD_COLUMNS)}")
    return [c.strip() for c in table[0]], table[1:], skip + 1


def read_loads_csv(path: str | os.PathLike, /, *, segments) -> dict:
    """The raw samples of a loads file (module docstring): {"time_s": (k,), "force_N", "moment_Nm",
    "point_m": (k, 3), "segment": str, "frame": str, "source": str}; ``segments``: the model's
    segment names (a segment not among them is refused)."""
    path = Path(path)
    header, rows, first = _rows(path)
    missing = [c for c in LOAD_COLUMNS if c not in header]
    if missing:
        raise InputError(f"{path}: missing column(s) {missing}; a loads file has the columns {list(LOAD_COLUMNS)} "
                         f"(it has {header})")
    if len(rows) < 2:
        raise InputError(f"{path}: column 'time_s' has {len(rows)} sample(s); a load needs at least 2")
    idx = {c: header.index(c) for c in LOAD_COLUMNS}
    values = np.empty((len(rows), len(NUMERIC_COLUMNS)))
    for i, row in enumerate(rows):
        for j, c in enumerate(NUMERIC_COLUMNS):
            cell = row[idx[c]].strip() if idx[c] < len(row) else ""
            try:
                values[i, j] = float(cell)
            except ValueError:
                values[i, j] = np.nan
            if not np.isfinite(values[i, j]):
                raise InputError(f"{path}: column '{c}', line {first + i + 1}: '{cell}' is not a finite number "
                                 f"(expected {c.rsplit('_', 1)[-1].replace('Nm', 'N m')})")
    texts = {}
    for c, allowed in (("segment", tuple(segments)), ("frame", LOAD_FRAMES)):
        seen = sorted({(row[idx[c]].strip() if idx[c] < len(row) else "") for row in rows})
        if len(seen) != 1:
            raise InputError(f"{path}: column '{c}' must hold one value in every row, got {seen}")
        if seen[0] not in allowed:
            raise InputError(f"{path}: column '{c}': unknown {c} '{seen[0]}'; expected one of {list(allowed)}")
        texts[c] = seen[0]
    t = values[:, 0]
    dt = np.diff(t)
    if not np.all(dt > 0):
        k = int(np.flatnonzero(dt <= 0)[0])
        raise InputError(f"{path}: column 'time_s' must increase strictly; line {first + k + 2} is at {t[k + 1]:g} s "
                         f"after {t[k]:g} s")
    med = float(np.median(dt))
    if np.any(np.abs(dt - med) > UNIFORM_TOLERANCE * med):
        raise InputError(f"{path}: column 'time_s' is not uniformly sampled (intervals {dt.min():g}-{dt.max():g} s, "
                         f"median {med:g} s); resample the loads to a constant rate")
    return {"time_s": t, "force_N": values[:, 1:4], "moment_Nm": values[:, 4:7], "point_m": values[:, 7:10],
            "segment": texts["segment"], "frame": texts["frame"], "source": str(path)}


def resample_load(raw: dict, time_s: np.ndarray, /, *, cutoff_hz: float | None, order: int = 2) -> ExternalLoad:
    """The load ``raw`` (read_loads_csv) on the trial's frame times ``time_s``: low-pass filtered at
    ``cutoff_hz`` (None: not filtered) at the file's rate, then a cubic spline (module docstring)."""
    t = raw["time_s"]
    time_s = np.asarray(time_s, dtype=float)
    if t[0] > time_s[0] + COVER_TOLERANCE_S or t[-1] < time_s[-1] - COVER_TOLERANCE_S:
        raise InputError(f"{raw['source']}: column 'time_s' covers {t[0]:g}-{t[-1]:g} s, the trial "
                         f"{time_s[0]:g}-{time_s[-1]:g} s; the loads must cover every frame of the trial")
    series = np.stack([raw["force_N"], raw["moment_Nm"], raw["point_m"]], axis=1)  # (k, 3, 3)
    rate = 1.0 / float(np.median(np.diff(t)))
    if cutoff_hz is not None:
        if not cutoff_hz < rate / 2:
            raise InputError(f"{raw['source']}: its rate {rate:g} Hz cannot carry the markers' low-pass cut-off "
                             f"{cutoff_hz:g} Hz (the rate must exceed twice it)")
        series = lowpass(series, rate_hz=rate, cutoff_hz=cutoff_hz, order=order)
    at = np.clip(time_s, t[0], t[-1])
    out = CubicSpline(t, series, axis=0)(at)
    how = f"low-pass {cutoff_hz:g} Hz" if cutoff_hz is not None else "not filtered"
    return ExternalLoad(segment=raw["segment"], frame=raw["frame"], force_N=out[:, 0], moment_Nm=out[:, 1],
                        point_m=out[:, 2], source=f"{raw['source']} ({how}, {rate:g} Hz resampled to the trial)")


FORCE_UNITS = {"N": 1.0, "": 1.0}
MOMENT_UNITS = {"Nm": 1.0, "N.m": 1.0, "N m": 1.0, "": 1.0, "Nmm": 1e-3, "N.mm": 1e-3, "N mm": 1e-3}


def analog_load(spec, path: str | os.PathLike, /, *, protocol_source: str = "") -> dict:
    """The raw samples (as read_loads_csv gives them) of a protocol's ``analog_loads`` entry
    (exubio.types.AnalogLoadSpec) in the C3D file ``path``: the named analog channels, scaled to N
    and N m by their ANALOG:UNITS, the point fixed. A channel the file lacks, or a unit that is not
    a force's or a moment's, raises InputError naming the channel and the protocol key."""
    from exubio.io.c3d import read_c3d_analogs

    path = Path(path)
    labels, units, rate, values = read_c3d_analogs(path)
    where = f"{protocol_source or 'protocol'}: analog_loads"

    def take(channels, known: dict, what: str) -> np.ndarray:
        cols = []
        for ch in channels:
            if ch not in labels:
                raise InputError(f"{path}: analog channel '{ch}' ({where}, {what}) is not in the file; its analog "
                                 f"channels are {list(labels)}")
            j = labels.index(ch)
            if units[j] not in known:
                raise InputError(f"{path}: analog channel '{ch}' ({where}, {what}) is in '{units[j]}'; expected one "
                                 f"of {[u for u in known if u]}")
            cols.append(values[:, j] * known[units[j]])
        return np.column_stack(cols)

    force = take(spec.force, FORCE_UNITS, "force")
    moment = take(spec.moment, MOMENT_UNITS, "moment") if spec.moment else np.zeros_like(force)
    if not np.isfinite(force).all() or not np.isfinite(moment).all():
        raise InputError(f"{path}: an analog channel of {where} holds samples that are not numbers")
    t = np.arange(force.shape[0]) / rate
    return {"time_s": t, "force_N": force, "moment_Nm": moment, "point_m": np.tile(spec.point_m, (t.size, 1)),
            "segment": spec.segment, "frame": spec.frame,
            "source": f"{path} analog channels {list(spec.force) + list(spec.moment or ())}"}
