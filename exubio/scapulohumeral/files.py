"""The rhythm read from result files: a trial's ``<trial>.<method>.csv`` (angles, uncertainty) and
``.npz`` (each angle's status per frame, the model file), a study's ``study.json`` and its trial
folders. Reads files only: the reports draw from here without a solver."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from exubio.errors import InputError
from exubio.io.result_names import beside, method_stem, set_paths
from exubio.io.results import read_angles_csv, read_npz_arrays, read_npz_metadata
from exubio.model.signs import convert, factors, signs_of_file
from exubio.scapulohumeral.reference import Reference, reference, trial_plane
from exubio.scapulohumeral.table import (HT_GRID_DEG, PHASES, RHYTHM_ANGLES, Average, Resampled, TrialRhythm, average, resample,
                                 trial_rhythm)
from exubio.types import Model

__all__ = ["read_trial_rhythm", "rhythm_of", "trial_model", "model_of", "trial_reference", "rhythm_reference", "StudyTrial", "StudyRhythm", "study_trials",
           "study_rhythm", "trial_columns", "study_columns", "shown_band"]


def read_trial_rhythm(npz_path: str | Path, /) -> TrialRhythm:
    """A trial's rhythm from its ``.npz`` and the ``.csv`` beside it (InputError naming the file
    when the result has no angle status or no shoulder angles)."""
    npz_path = Path(npz_path)
    csv = beside(npz_path, "csv")
    status = read_npz_arrays(npz_path, ("angle_status",))["angle_status"]
    t, names, values, u = read_angles_csv(csv, uncertainty=True)
    names = tuple(n.removesuffix("_deg") for n in names)
    if status.shape != values.shape:
        raise InputError(f"{npz_path}: angle_status has shape {status.shape}, the angles of {csv.name} {values.shape}")
    signs = signs_of_file(csv)  # the rhythm holds ISB values; the table and the page show the file's convention
    return rhythm_of(t, names, convert(names, values, signs, "isb"), u, status, signs, where=csv)


def rhythm_of(time_s: np.ndarray, names: tuple[str, ...], isb_rad: np.ndarray, u_rad: np.ndarray | None,
              status: np.ndarray, signs: str, /, *, where: str | Path) -> TrialRhythm:
    """A trial's rhythm from its anatomical angles (ISB, rad; their uncertainty, None or NaN where
    none; their status codes) as its files hold them, in memory (InputError naming ``where`` without
    the shoulder angles)."""
    u = np.full(isb_rad.shape, np.nan) if u_rad is None else u_rad
    try:
        return trial_rhythm(time_s, names, np.degrees(isb_rad), np.degrees(u), status == 0, signs=signs)
    except KeyError as exc:
        raise InputError(f"{where}: {exc.args[0]}") from None


def trial_model(npz_path: str | Path, /) -> tuple[Model, str]:
    """(model, which) the trial was reconstructed with (its metadata's model file), else the
    generic model (said in ``which``)."""
    return model_of(read_npz_metadata(npz_path))


def model_of(metadata: Mapping[str, Any], /, *, model: Model | None = None) -> tuple[Model, str]:
    """(model, which) of a result's metadata: ``model`` when the caller holds the one the trial was
    reconstructed with, else read from the metadata's model file, else the generic model (said)."""
    from exubio.model.load import load_model

    path = metadata.get("model")
    if model is not None:
        return model, f"the trial's model {Path(str(path)).name}" if path else "the trial's model"
    if path and Path(str(path)).is_file():
        try:
            return load_model(path), f"the trial's model {Path(str(path)).name}"
        except Exception as exc:  # noqa: BLE001 - the corridor falls back to the generic bones, said
            return load_model(), f"the generic model ({Path(str(path)).name} unreadable: {exc})"
    return load_model(), "the generic model (the trial's model file is not there)"


def trial_reference(npz_path: str | Path, r: TrialRhythm, /) -> tuple[Reference, str]:
    return rhythm_reference(r, *trial_model(npz_path))


def rhythm_reference(r: TrialRhythm, model: Model, which: str, /) -> tuple[Reference, str]:
    """(corridor of the trial's plane on ``model``'s bones, ``which`` model it is)."""
    plane, deg, why = trial_plane(r)
    return reference(model, plane, plane_deg=deg, why=why), which


@dataclass(frozen=True)
class StudyTrial:
    subject: str
    session: str
    trial: str
    method: str
    npz: Path
    verdict: str


def study_trials(study_dir: str | Path, /, *, method: str | None = None) -> list[StudyTrial]:
    """The study's trials with a result of ``method`` (None: each trial's every method), in study
    order, from its ``study.json`` (InputError naming it when absent or unreadable)."""
    study_dir = Path(study_dir)
    path = study_dir / "study.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: expected the study.json of `exubio study` ({exc})") from None
    out = []
    for row in data.get("trials", []):
        folder = Path(row.get("folder", ""))
        if not folder.is_absolute():
            folder = study_dir / folder
        stem = Path(row["trial"]).stem
        for m in (method,) if method else ("pf", "ls"):
            npz = set_paths(folder, method_stem(stem, m))["npz"]
            if npz.is_file():
                out.append(StudyTrial(row["subject"], row["session"], stem, m, npz, row.get(f"{m}_verdict") or ""))
    return out


@dataclass
class StudyRhythm:
    """The rhythm of a study's trials of one method and one plane: each trial resampled, each
    subject's mean and SD over its trials, the group's over the subjects' means, the corridor on
    the generic model, and the trials left out with the reason."""

    method: str
    plane: str
    trials: list[tuple[StudyTrial, Resampled]] = field(default_factory=list)
    subjects: dict[str, Average] = field(default_factory=dict)
    group: Average | None = None
    reference: Reference | None = None
    left_out: list[tuple[StudyTrial, str]] = field(default_factory=list)
    signs: str = "isb"  # the convention the pages and the table show (the trials' files'); the averages are ISB


def study_rhythm(study_dir: str | Path, /, *, method: str | None = None) -> list[StudyRhythm]:
    """One StudyRhythm per method and plane that has trials (trials raising in no studied plane,
    or without a raising, are in ``left_out`` of the first). Every trial is read as ISB (whatever
    its file's convention) and averaged so; ``signs``: the convention the trials' files share (isb
    when they differ)."""
    from exubio.model.load import load_model

    trials = study_trials(study_dir, method=method)
    groups: dict[tuple[str, str], StudyRhythm] = {}
    left: list[tuple[StudyTrial, str]] = []
    planes: dict[str, float] = {}
    seen_signs: set[str] = set()
    for st in trials:
        try:
            r = read_trial_rhythm(st.npz)
        except InputError as exc:
            left.append((st, str(exc)))
            continue
        plane, deg, why = trial_plane(r)
        if plane is None:
            left.append((st, why))
            continue
        g = groups.setdefault((st.method, plane), StudyRhythm(st.method, plane))
        planes.setdefault(plane, deg)
        g.trials.append((st, resample(r)))
        seen_signs.add(r.signs)
    model = load_model() if groups else None
    for (_m, plane), g in groups.items():
        subjects: dict[str, list[np.ndarray]] = {}
        for st, rs in g.trials:
            subjects.setdefault(st.subject, []).append(rs.values_deg)
        g.subjects = {s: average(c) for s, c in subjects.items()}
        g.group = average([a.mean_deg for a in g.subjects.values()])
        g.reference = reference(model, plane, plane_deg=planes[plane],
                                why=f"{plane} plane (the trials' raising); corridor on the generic model's bones")
        g.signs = next(iter(seen_signs)) if len(seen_signs) == 1 else "isb"
    out = list(groups.values())
    if out:
        out[0].left_out = left
    elif left:
        raise InputError(f"{study_dir}: no trial of the study has a rhythm: " + "; ".join(
            f"{t.subject}/{t.session}/{t.trial} ({t.method}): {why}" for t, why in left[:5]))
    return out


def shown_band(lo: np.ndarray, hi: np.ndarray, factor: float, /) -> tuple[np.ndarray, np.ndarray]:
    """A band (lo, hi) of ISB values in the convention whose factor is ``factor`` (+-1): flipped
    and swapped when it is -1, so lo stays the lower bound."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return (lo, hi) if factor > 0 else (-hi, -lo)


def trial_columns(r: TrialRhythm, ref: Reference, /) -> dict[str, np.ndarray]:
    """The table behind a trial's rhythm page, long: one row per frame of a cycle and rhythm angle
    (time_s, phase, cycle, ht_elevation_deg, angle, value_deg, u_deg, measured, corridor_lo_deg,
    corridor_hi_deg: the corridor at the frame's HT elevation, NaN where there is none)."""
    rows = np.flatnonzero(r.phase > 0)
    cols: dict[str, list] = {c: [] for c in ("time_s", "phase", "cycle", "ht_elevation_deg", "angle", "value_deg",
                                             "u_deg", "measured", "corridor_lo_deg", "corridor_hi_deg")}
    for i, name in enumerate(r.names):
        f = factors([name], r.signs)[0]  # ISB inside; the table in the trial's convention
        lo, hi = shown_band(*ref.at(name, r.ht_deg[rows]), f)
        cols["time_s"].append(r.time_s[rows])
        cols["phase"].append(np.where(r.phase[rows] == 1, "raising", "lowering"))
        cols["cycle"].append(r.cycle[rows])
        cols["ht_elevation_deg"].append(r.ht_deg[rows])
        cols["angle"].append(np.full(rows.size, name, dtype=object))
        cols["value_deg"].append(r.values_deg[rows, i] * f)
        cols["u_deg"].append(r.u_deg[rows, i])
        cols["measured"].append(r.measured[rows, i])
        cols["corridor_lo_deg"].append(lo)
        cols["corridor_hi_deg"].append(hi)
    return {c: np.concatenate(v) if v else np.zeros(0) for c, v in cols.items()}


def study_columns(groups: list[StudyRhythm], /) -> dict[str, np.ndarray]:
    """The table behind a study's rhythm pages, long: one row per method, plane, level ("group" or
    "subject"), subject ("" for the group), phase, HT elevation grid point and angle with a value
    (mean_deg, sd_deg, n: subjects for the group, trials for a subject; corridor_lo_deg, corridor_hi_deg)."""
    cols: dict[str, list] = {c: [] for c in ("method", "plane", "level", "subject", "phase", "ht_elevation_deg", "angle",
                                             "mean_deg", "sd_deg", "n", "corridor_lo_deg", "corridor_hi_deg")}
    names = [a for a, _ in RHYTHM_ANGLES]
    for g in groups:
        levels = [("group", "", g.group)] + [("subject", s, a) for s, a in g.subjects.items()]
        for level, subject, a in levels:
            for p, phase in enumerate(PHASES):
                for i, name in enumerate(names):
                    ok = a.n[p, :, i] > 0
                    m = int(ok.sum())
                    f = factors([name], g.signs)[0]
                    lo, hi = shown_band(*g.reference.at(name, HT_GRID_DEG[ok]), f)
                    for c, v in (("method", g.method), ("plane", g.plane), ("level", level), ("subject", subject),
                                 ("phase", phase), ("angle", name)):
                        cols[c].append(np.full(m, v, dtype=object))
                    cols["ht_elevation_deg"].append(HT_GRID_DEG[ok])
                    cols["mean_deg"].append(a.mean_deg[p, ok, i] * f)
                    cols["sd_deg"].append(a.sd_deg[p, ok, i])
                    cols["n"].append(a.n[p, ok, i])
                    cols["corridor_lo_deg"].append(lo)
                    cols["corridor_hi_deg"].append(hi)
    return {c: np.concatenate(v) if v else np.zeros(0) for c, v in cols.items()}
