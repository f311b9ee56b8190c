"""Scapula calibrations judged against a scapula locator (bone truth for AA, TS and AI).

The data: per participant, static posture and system (``locator``: the scapula locator, the
truth; ``skin``: skin markers over the landmarks; ``cluster``: a scapula-cluster
reconstruction), the trial-mean lab positions of the acromion angle (AA), trigonum spinae (TS)
and inferior angle (AI), as in aceglia/scapula_cluster ``data_analysis/data_df.csv`` (Ceglia,
Begon et al., Montréal; left arm). That writer transposed the columns: AA = (AA_x, AI_x, TS_x),
AI = (AA_y, AI_y, TS_y), TS = (AA_z, AI_z, TS_z); ``<L>_mean`` is the mean of those three, which
the reader checks. Millimetres in the file, metres inside.

The calibrations (pure functions; ``calibrate`` then ``apply_calibration``):
- none: the skin markers (or the cluster's landmarks) as they are;
- single: in one calibration posture, the locator-minus-tracked offset of each landmark in a
  scapula frame built from the three tracked landmarks, carried by that frame into every posture;
- double / multiple: the same in two or more postures, the offsets interpolated linearly (held
  constant outside the calibrated range) in the **upward rotation of the tracked frame**: its
  rotation about the scapular-plane normal (ISB X) of the lowest calibration posture. No humerus
  is measured, so the humerothoracic elevation a double calibration of an acromion cluster uses
  (Brochard et al. 2011; Prinold et al. 2011) is not available; the tracked frame's own upward
  rotation is, in a static and in a movement alike, and grows with elevation.
The tracked frame is either the ISB frame of the three tracked landmarks (``Frame.ISB``: origin
AA, Z along TS-AA) or the rigid least-squares registration of the calibration posture's tracked
triad (``Frame.REGISTRATION``: exubio.calibration.cluster.cluster_poses, the registration that
exubio's scapula calibration carries through a movement).

ISB scapula frame (Wu et al. 2005), mirrored for a left arm so that X points forward and Y up in
both: origin AA, Z from AA towards TS on the left (from TS to AA on the right), X normal to the
AA-TS-AI plane, Y = Z x X.
"""
from __future__ import annotations

import csv
import enum
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Literal, Mapping, Sequence

import numpy as np

from exubio.calibration.cluster import cluster_poses
from exubio.errors import InputError

__all__ = ["GROSS_OFFSET_M", "LANDMARKS", "RECOMMENDED_ELEVATIONS", "RECOMMENDED_PLANE", "Calibration", "Frame",
           "LocatorData", "LocatorTrial", "Posture", "System", "apply_calibration", "calibrate", "calibration_trials",
           "locator_displaced", "orientation_error", "parse_posture", "read_locator_csv", "recommended_calibration",
           "scapula_frame", "upward_rotation"]

LANDMARKS = ("AA", "TS", "AI")
# the file's columns holding each landmark's (x, y, z), as its writer transposed them
_COLUMNS = {"AA": ("AA_x", "AI_x", "TS_x"), "AI": ("AA_y", "AI_y", "TS_y"), "TS": ("AA_z", "AI_z", "TS_z")}
_MEAN_TOLERANCE_MM = 1e-6  # <L>_mean against the mean of the landmark's three columns (round-off only)
_FILE_NAME = re.compile(r"^(abd|flex)_(\d+|max)(?:_(avant|arriere))?_(\d+)$")
# A locator triad whose centroid lies farther than this from the skin's and the cluster's is not a
# measurement of that scapula in that posture (a trial mean over the wrong window, a mislabelled
# trial): skin markers over AA, TS and AI cannot slide 10 cm together. On P9-P12 the largest
# offset of the closer of the two is 33 mm, except one trial at 278 mm.
GROSS_OFFSET_M = 0.10
_DUPLICATE_NODE_RAD = 1e-9  # calibration postures at the same upward rotation are averaged
Side = Literal["left", "right"]


class System(enum.Enum):
    """Who measured a landmark."""
    LOCATOR = "locator"
    SKIN = "skin"
    CLUSTER = "cluster"


class Frame(enum.Enum):
    """The tracked frame a calibration's offsets live in."""
    ISB = "isb"
    REGISTRATION = "registration"


@dataclass(frozen=True)
class Posture:
    """One static trial's posture, parsed from the file's ``file`` column (e.g. ``flex_90_avant_2``).

    plane: "abd" or "flex"; elevation: the nominal arm elevation as written ("45", "90", "120",
    "150", "max"); variant: "" or "avant"/"arriere" (flexion 90 with the shoulder forward/back);
    repeat: the repeat number."""

    file: str
    plane: str
    elevation: str
    variant: str
    repeat: int

    @property
    def name(self) -> str:
        """The posture without its repeat (``flex_90_avant``)."""
        return "_".join(p for p in (self.plane, self.elevation, self.variant) if p)

    @property
    def elevation_order(self) -> float:
        """The nominal elevation as a number for ordering (deg; ``max`` after every number)."""
        return math.inf if self.elevation == "max" else float(self.elevation)


@dataclass(frozen=True, eq=False)
class LocatorTrial:
    """One participant's static trial: the landmarks of each system, (3, 3) rows AA, TS, AI in
    the lab (m); a landmark the file does not give is NaN."""

    participant: str
    posture: Posture
    positions_m: Mapping[System, np.ndarray]


@dataclass(frozen=True, eq=False)
class LocatorData:
    """A locator file: its trials in file order and where it came from."""

    source: str
    trials: tuple[LocatorTrial, ...]

    @property
    def participants(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(t.participant for t in self.trials))

    def of(self, participant: str) -> tuple[LocatorTrial, ...]:
        return tuple(t for t in self.trials if t.participant == participant)


def parse_posture(file: str, /) -> Posture:
    """The posture of a ``file`` value; ValueError if it is not ``<abd|flex>_<deg|max>[_avant|_arriere]_<n>``."""
    m = _FILE_NAME.match(file)
    if not m:
        raise ValueError(f"'{file}' is not <abd|flex>_<degrees|max>[_avant|_arriere]_<repeat>")
    return Posture(file, m.group(1), m.group(2), m.group(3) or "", int(m.group(4)))


def read_locator_csv(path: str | Path, /) -> LocatorData:
    """Read a scapula-locator CSV (columns participant, file, system, AA_x ... TS_z, AA_mean,
    AI_mean, TS_mean; other columns ignored). InputError naming the file, line and column for a
    missing column, a non-number, an unknown system or posture, a row given twice, or a
    ``<L>_mean`` that is not the mean of the landmark's three (transposed) columns. A landmark
    whose coordinates are empty is NaN (kept, and reported wherever it is used)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the locator file ({exc})") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise InputError(f"{path}: empty file; expected a header with participant, file, system, AA_x ... TS_mean")
    header = [h.strip() for h in rows[0]]
    needed = ["participant", "file", "system", *(c for cols in _COLUMNS.values() for c in cols),
              *(f"{lm}_mean" for lm in LANDMARKS)]
    for col in needed:
        if col not in header:
            raise InputError(f"{path}: no column '{col}' (a locator file has {', '.join(needed)})")
    at = {c: header.index(c) for c in needed}
    collected: dict[tuple[str, str], dict[System, np.ndarray]] = {}
    postures: dict[tuple[str, str], Posture] = {}
    for line, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) < len(header):
            raise InputError(f"{path}: line {line} has {len(row)} fields, the header {len(header)}")
        participant, file = row[at["participant"]].strip(), row[at["file"]].strip()
        try:
            system = System(row[at["system"]].strip())
        except ValueError:
            raise InputError(f"{path}: line {line}, column 'system': '{row[at['system']]}' is not one of "
                             f"{', '.join(s.value for s in System)}") from None
        try:
            posture = parse_posture(file)
        except ValueError as exc:
            raise InputError(f"{path}: line {line}, column 'file': {exc}") from None
        xyz = np.empty((3, 3))
        for i, lm in enumerate(LANDMARKS):
            values = [_number(path, line, c, row[at[c]]) for c in _COLUMNS[lm]]
            mean = _number(path, line, f"{lm}_mean", row[at[f"{lm}_mean"]])
            if all(math.isfinite(v) for v in values):
                if not abs(sum(values) / 3.0 - mean) <= _MEAN_TOLERANCE_MM:
                    raise InputError(f"{path}: line {line}, column '{lm}_mean': {mean} is not the mean of "
                                     f"{', '.join(_COLUMNS[lm])} ({sum(values) / 3.0}); the columns are not "
                                     "transposed as this reader expects (AA = AA_x, AI_x, TS_x)")
                xyz[i] = np.array(values) / 1000.0
            else:
                xyz[i] = np.nan  # a landmark with a missing coordinate is missing
        key = (participant, file)
        if system in collected.setdefault(key, {}):
            raise InputError(f"{path}: line {line}: participant {participant}, file {file}, system {system.value} "
                             "is given twice")
        collected[key][system] = xyz
        postures[key] = posture
    if not collected:
        raise InputError(f"{path}: no data rows")
    trials = []
    for (participant, file), systems in collected.items():
        full = {s: systems.get(s, np.full((3, 3), np.nan)) for s in System}
        for arr in full.values():
            arr.setflags(write=False)
        trials.append(LocatorTrial(participant, postures[(participant, file)], full))
    return LocatorData(str(path), tuple(trials))


def _number(path: Path, line: int, column: str, cell: str) -> float:
    cell = cell.strip()
    if cell == "" or cell.lower() == "nan":
        return math.nan
    try:
        value = float(cell)
    except ValueError:
        raise InputError(f"{path}: line {line}, column '{column}': '{cell}' is not a number (mm)") from None
    if not math.isfinite(value):
        raise InputError(f"{path}: line {line}, column '{column}': '{cell}' is not a finite number (mm)")
    return value


def locator_displaced(trial: LocatorTrial, /) -> str:
    """Why the trial's locator landmarks cannot be truth ("" if they can): their centroid lies more
    than GROSS_OFFSET_M from the centroids of both the skin's and the cluster's landmarks."""
    c = trial.positions_m[System.LOCATOR].mean(axis=0)
    offsets = {s: float(np.linalg.norm(trial.positions_m[s].mean(axis=0) - c)) for s in (System.SKIN, System.CLUSTER)
               if np.isfinite(trial.positions_m[s]).all()}
    if offsets and np.isfinite(c).all() and min(offsets.values()) > GROSS_OFFSET_M:
        return (f"the locator's landmarks lie {', '.join(f'{v * 1000:.0f} mm' for v in offsets.values())} from the "
                f"{' and '.join(s.value for s in offsets)} landmarks (centroids; more than {GROSS_OFFSET_M * 1000:.0f} "
                "mm: not a measurement of this posture)")
    return ""


# ----------------------------------------------------------------------------------------------
# Frames
# ----------------------------------------------------------------------------------------------
def scapula_frame(landmarks_m: np.ndarray, /, *, side: Side = "left") -> tuple[np.ndarray, np.ndarray]:
    """The ISB scapula frame of landmarks (..., 3, 3) (rows AA, TS, AI, m): rotation (..., 3, 3),
    columns X, Y, Z in the lab, and origin AA (..., 3). X forward, Y up, Z lateral on the right and
    medial on the left (the mirrored frame). NaN where a landmark is missing."""
    p = np.asarray(landmarks_m, dtype=float)
    aa, ts, ai = p[..., 0, :], p[..., 1, :], p[..., 2, :]
    z = (ts - aa) if side == "left" else (aa - ts)
    x = np.cross(ts - aa, ai - aa) if side == "left" else np.cross(ai - aa, ts - aa)
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1), aa.copy()


def orientation_error(a_m: np.ndarray, b_m: np.ndarray, /, *, side: Side = "left") -> np.ndarray:
    """The angle (rad) between the ISB scapula frames of two landmark sets (..., 3, 3)."""
    Ra, _ = scapula_frame(a_m, side=side)
    Rb, _ = scapula_frame(b_m, side=side)
    c = (np.einsum("...ij,...ij->...", Ra, Rb) - 1.0) / 2.0  # (trace(Ra^T Rb) - 1) / 2
    return np.arccos(np.clip(c, -1.0, 1.0))


def upward_rotation(landmarks_m: np.ndarray, reference_m: np.ndarray, /, *, side: Side = "left") -> np.ndarray:
    """The rotation (rad) of the ISB frame of ``landmarks_m`` (..., 3, 3) about the X axis (the
    scapular-plane normal) of the frame of ``reference_m`` (3, 3): the angle its Z axis turned in the
    reference's Y-Z plane (positive: Z turning towards Y). With AA, TS and AI tracked, the
    scapula's upward rotation from the reference posture (its sign depends on the side)."""
    R0, _ = scapula_frame(reference_m, side=side)
    R, _ = scapula_frame(landmarks_m, side=side)
    z = np.einsum("ji,...j->...i", R0, R[..., :, 2])  # Z axis in the reference frame
    return np.arctan2(z[..., 1], z[..., 2])


def _tracked_frames(tracked_m: np.ndarray, frame: Frame, reference_m: np.ndarray, side: Side):
    """(R (n, 3, 3), origin (n, 3)) of tracked triads (n, 3, 3)."""
    if frame is Frame.ISB:
        return scapula_frame(tracked_m, side=side)
    R, t, _ = cluster_poses(reference_m - reference_m.mean(axis=0), tracked_m)
    return R, t


# ----------------------------------------------------------------------------------------------
# Calibrations
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Calibration:
    """Locator-minus-tracked offsets in the tracked frame, per calibration posture.

    tracked: the system whose landmarks are corrected; frame: the tracked frame; side.
    postures: the calibration trials' ``file`` names, in the order of ``nodes_rad``.
    nodes_rad (k,): the tracked frame's upward rotation at each calibration posture (from the
    first one's frame), increasing; offsets_m (k, 3, 3): the offsets (rows AA, TS, AI) there.
    reference_m (3, 3): the tracked landmarks of the lowest calibration posture (the reference of
    the upward rotation and of the registration)."""

    tracked: System
    frame: Frame
    side: Side
    postures: tuple[str, ...]
    nodes_rad: np.ndarray
    offsets_m: np.ndarray
    reference_m: np.ndarray

    @property
    def kind(self) -> str:
        return {1: "single", 2: "double"}.get(len(self.postures), "multiple")


def calibrate(trials: Sequence[LocatorTrial], /, *, tracked: System = System.SKIN, frame: Frame = Frame.ISB,
              side: Side = "left") -> Calibration:
    """A single (one trial), double (two) or multiple calibration of ``tracked`` against the
    locator. The trials are ordered by nominal elevation; the lowest is the reference. InputError
    if a trial lacks a landmark of the locator or of ``tracked``, or if there is no trial."""
    if not trials:
        raise InputError("calibrate: no calibration posture given")
    trials = sorted(trials, key=lambda t: (t.posture.elevation_order, t.posture.file))
    for t in trials:
        for system in (System.LOCATOR, tracked):
            missing = [lm for lm, row in zip(LANDMARKS, t.positions_m[system]) if not np.isfinite(row).all()]
            if missing:
                raise InputError(f"calibrate: participant {t.participant}, file {t.posture.file}: no {system.value} "
                                 f"{', '.join(missing)}; a calibration posture needs all three landmarks")
    tracked_m = np.stack([t.positions_m[tracked] for t in trials])
    locator_m = np.stack([t.positions_m[System.LOCATOR] for t in trials])
    reference = tracked_m[0].copy()
    R, o = _tracked_frames(tracked_m, frame, reference, side)
    offsets = np.einsum("nji,nlj->nli", R, locator_m - o[:, None, :])  # R^T (locator - origin)
    nodes = upward_rotation(tracked_m, reference, side=side)
    order = np.argsort(nodes, kind="stable")
    nodes, offsets, names = nodes[order], offsets[order], [trials[i].posture.file for i in order]
    merged_nodes, merged_offsets, merged_names = [], [], []
    for k in range(len(nodes)):  # postures at the same upward rotation: their mean offset
        if merged_nodes and nodes[k] - merged_nodes[-1][-1] <= _DUPLICATE_NODE_RAD:
            merged_nodes[-1].append(nodes[k])
            merged_offsets[-1].append(offsets[k])
            merged_names[-1] += "+" + names[k]
        else:
            merged_nodes.append([nodes[k]])
            merged_offsets.append([offsets[k]])
            merged_names.append(names[k])
    arrays = (np.array([np.mean(n) for n in merged_nodes]), np.array([np.mean(o, axis=0) for o in merged_offsets]),
              reference)
    for arr in arrays:
        arr.setflags(write=False)
    return Calibration(tracked, frame, side, tuple(merged_names), *arrays)


def apply_calibration(calibration: Calibration, tracked_m: np.ndarray, /) -> np.ndarray:
    """The corrected landmarks (n, 3, 3) of tracked landmarks (n, 3, 3) (rows AA, TS, AI, m): the
    offsets interpolated at each posture's upward rotation (constant outside the calibrated range),
    carried by the tracked frame. NaN where a tracked landmark is missing (the frame needs all
    three)."""
    p = np.asarray(tracked_m, dtype=float)
    single = p.ndim == 2
    p = p[None] if single else p
    out = np.full(p.shape, np.nan)
    ok = np.isfinite(p).all(axis=(1, 2))
    if ok.any():
        c = calibration
        R, o = _tracked_frames(p[ok], c.frame, c.reference_m, c.side)
        theta = upward_rotation(p[ok], c.reference_m, side=c.side)
        if len(c.nodes_rad) == 1:
            d = np.broadcast_to(c.offsets_m[0], (int(ok.sum()), 3, 3))
        else:
            flat = c.offsets_m.reshape(len(c.nodes_rad), 9)
            d = np.stack([np.interp(theta, c.nodes_rad, flat[:, j]) for j in range(9)], axis=-1).reshape(-1, 3, 3)
        out[ok] = o[:, None, :] + np.einsum("nij,nlj->nli", R, d)
    return out[0] if single else out


def calibration_trials(trials: Iterable[LocatorTrial], /, *, plane: str, elevations: Sequence[str],
                       tracked: System = System.SKIN) -> tuple[tuple[LocatorTrial, ...], tuple[str, ...]]:
    """The calibration trials of one participant for nominal ``elevations`` in ``plane``: the plain
    posture (no forward/back variant), its lowest repeat with all three landmarks of the locator and
    of ``tracked`` and a locator that is not displaced (``locator_displaced``); and the postures that have no such trial. ``elevations == ("all",)``: every plain
    elevation of the plane."""
    plain = [t for t in trials if t.posture.plane == plane and not t.posture.variant
             and all(np.isfinite(t.positions_m[s]).all() for s in (System.LOCATOR, tracked))
             and not locator_displaced(t)]
    if tuple(elevations) == ("all",):
        elevations = sorted({t.posture.elevation for t in plain}, key=lambda e: math.inf if e == "max" else float(e))
    chosen, absent = [], []
    for e in elevations:
        there = sorted((t for t in plain if t.posture.elevation == e), key=lambda t: t.posture.repeat)
        if there:
            chosen.append(there[0])
        else:
            absent.append(f"{plane}_{e}")
    return tuple(chosen), tuple(absent)


# ----------------------------------------------------------------------------------------------
# The recommended calibration (studies/README.md, "Scapula calibration against the locator")
# ----------------------------------------------------------------------------------------------
RECOMMENDED_PLANE = "flex"
RECOMMENDED_ELEVATIONS = ("45", "120")


def recommended_calibration(trials: Iterable[LocatorTrial], /, *, side: Side = "left") -> Calibration:
    """The calibration that put AA, TS and AI closest to the locator in the postures it was not
    calibrated on: a double calibration of the skin markers over AA, TS and AI, from the statics
    at 45 and 120 deg of flexion, interpolated in the skin frame's upward rotation. ``trials``: one
    participant's statics (``LocatorData.of``). Apply it with ``apply_calibration`` to that
    participant's skin landmarks (n, 3, 3), static or moving. InputError naming the missing posture
    if a static is absent."""
    trials = tuple(trials)
    if len({t.participant for t in trials}) > 1:
        raise InputError("recommended_calibration: the trials of one participant are needed, got "
                         f"{sorted({t.participant for t in trials})}")
    chosen, absent = calibration_trials(trials, plane=RECOMMENDED_PLANE, elevations=RECOMMENDED_ELEVATIONS)
    if absent:
        who = trials[0].participant if trials else "?"
        raise InputError(f"recommended_calibration: participant {who} has no static {', '.join(absent)} with all "
                         "three landmarks of the locator and the skin; the double calibration needs "
                         f"{' and '.join(f'{RECOMMENDED_PLANE}_{e}' for e in RECOMMENDED_ELEVATIONS)}")
    return calibrate(chosen, tracked=System.SKIN, frame=Frame.ISB, side=side)
