"""``exubio study STUDY.yaml --out OUT --bids DIR``: the study's angles as a BIDS motion derivative dataset.

DIR is the derivative dataset's root (in a BIDS dataset: ``<bids>/derivatives/exubio``). It gets a
``dataset_description.json`` (DatasetType "derivative", GeneratedBy exubio), a README, and per trial
and method (BIDS 1.9 motion modality)::

    sub-<subject>/[ses-<session>/]motion/
        sub-<s>_[ses-<s>_]task-<task>_tracksys-<method>_[run-<n>_]motion.tsv     no header, one column a channel
        ..._channels.tsv     name, component, type, tracked_point, units (+ description)
        ..._motion.json      SamplingFrequency, TaskName, TrackingSystemName, channel counts, ...

tracksys is the reconstruction method (``pf``/``ls``: the two are two estimates of the same joint
motion, as two tracking systems are); run numbers the trials of one task within a session. The
channels per anatomical angle: the angle (type JNTANG, deg), its standard uncertainty (MISC, deg)
and its status code (MISC; 0 measured, 1 modelled, 2 not measured). Missing values are ``n/a``.
Labels (subject, session, task) are made BIDS labels by keeping their letters and digits; a label
with none, or two different labels that become the same, is refused naming them.
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

import exubio
from exubio.errors import InputError
from exubio.io.results import atomic_write

__all__ = ["BIDS_VERSION", "bids_label", "write_bids"]

BIDS_VERSION = "1.9.0"
_NOT_ALNUM = re.compile(r"[^A-Za-z0-9]")
_STATUS_CODES = {"measured": 0, "modelled": 1, "not measured": 2}  # exubio.trust.observability.AngleStatus


def bids_label(value: str, /, *, what: str) -> str:
    """``value`` as a BIDS label (letters and digits only); InputError naming ``what`` if none is left."""
    label = _NOT_ALNUM.sub("", str(value))
    if not label:
        raise InputError(f"{what} '{value}': has no letter or digit to make a BIDS label of (BIDS labels are "
                         f"alphanumeric); rename it in the study file")
    return label


def _labels(values, what: str) -> dict[str, str]:
    """{value: label}, refusing two values that become the same label."""
    out: dict[str, str] = {}
    back: dict[str, str] = {}
    for v in values:
        lab = bids_label(v, what=what)
        if lab in back and back[lab] != v:
            raise InputError(f"{what}s '{back[lab]}' and '{v}' both become the BIDS label '{lab}' (BIDS labels are "
                             f"alphanumeric); rename one in the study file")
        out[v], back[lab] = lab, v
    return out


def _channel(angle: str) -> tuple[str, str]:
    """(component, tracked_point) of an anatomical angle column: ``GH_X_elevation`` -> ("x", "GH")."""
    parts = angle.split("_")
    for k, p in enumerate(parts):
        if p in ("X", "Y", "Z"):
            return p.lower(), "_".join(parts[:k])
    return "n/a", parts[0]


def _tsv(values: np.ndarray, codes: np.ndarray) -> str:
    """Rows of values (6 decimals) then status codes (integers), n/a where missing; no header (BIDS motion)."""
    rows = []
    for row, code in zip(values, codes):
        cells = ["n/a" if not np.isfinite(v) else f"{v:.6f}" for v in row]
        cells += ["n/a" if not np.isfinite(c) else str(int(c)) for c in code]
        rows.append("\t".join(cells))
    return "\n".join(rows) + "\n"


def write_bids(table: Any, out_dir: str | Path, /, *, overwrite: bool = False,
               study_name: str = "exubio study") -> list[Path]:
    """Write the study table (a pandas DataFrame as exubio.run.study_table makes it: one row per trial,
    method, frame and angle) as a BIDS motion derivative dataset into ``out_dir`` (module docstring).
    Refuses (InputError) a folder holding a dataset already unless ``overwrite``. Returns the files
    written."""
    out = Path(out_dir)
    desc = out / "dataset_description.json"
    if desc.exists() and not overwrite:
        raise InputError(f"--bids {out}: holds a dataset already ({desc.name}); give --overwrite-bids to replace its files")
    if table.empty:
        raise InputError(f"--bids {out}: the study has no reconstructed trial to write")
    subjects = _labels(dict.fromkeys(table["subject"].astype(str)), "subject")
    sessions = _labels(dict.fromkeys(table["session"].astype(str)), "session")
    tasks = _labels(dict.fromkeys(table["task"].astype(str)), "task")
    written: list[Path] = []
    trials = table[["subject", "session", "task", "trial"]].astype(str).drop_duplicates()
    single_session = {s: len(set(trials.loc[trials["subject"] == s, "session"])) == 1 for s in subjects}
    run_of: dict[tuple[str, str, str], int] = {}
    count: dict[tuple[str, str, str], int] = {}
    for s, ses, task, trial in trials.itertuples(index=False):
        key = (s, ses, task)
        count[key] = count.get(key, 0) + 1
        run_of[(s, ses, trial)] = count[key]
    groups = table.groupby(["subject", "session", "trial", "method"], observed=True, sort=False)
    for (s, ses, trial, method), df in groups:
        s, ses, trial, method = str(s), str(ses), str(trial), str(method)
        task = str(df["task"].iloc[0])
        angles = list(dict.fromkeys(df["angle"].astype(str)))
        times = np.unique(df["time_s"].to_numpy(dtype=float))
        wide = {c: df.pivot_table(index="time_s", columns="angle", values=c, observed=True, dropna=False)
                .reindex(index=times, columns=angles) for c in ("value_deg", "u_deg")}
        status = df.assign(code=df["status"].astype(str).map(_STATUS_CODES).astype(float)).pivot_table(
            index="time_s", columns="angle", values="code", observed=True, dropna=False).reindex(index=times, columns=angles)
        data = np.concatenate([wide["value_deg"].to_numpy(), wide["u_deg"].to_numpy()], axis=1)
        data[np.isinf(data)] = np.nan  # u = inf (not measured at all): n/a
        rate = 1.0 / float(np.median(np.diff(times))) if times.size > 1 else 0.0
        parts = [f"sub-{subjects[s]}"] + ([] if single_session[s] and len(sessions) == 1 else [f"ses-{sessions[ses]}"])
        folder = out.joinpath(*parts, "motion")
        run = [f"run-{run_of[(s, ses, trial)]}"] if count[(s, ses, task)] > 1 else []
        stem = "_".join(parts + [f"task-{tasks[task]}", f"tracksys-{bids_label(method, what='method')}"] + run)
        folder.mkdir(parents=True, exist_ok=True)
        chan = ["name\tcomponent\ttype\ttracked_point\tunits\tdescription"]
        for a in angles:
            comp, point = _channel(a)
            chan.append(f"{a}\t{comp}\tJNTANG\t{point}\tdeg\tanatomical angle {a} (ISB)")
        for a in angles:
            comp, point = _channel(a)
            chan.append(f"{a}_u\t{comp}\tMISC\t{point}\tdeg\tstandard uncertainty of {a} (1 SD)")
        for a in angles:
            comp, point = _channel(a)
            chan.append(f"{a}_status\t{comp}\tMISC\t{point}\tn/a\tstatus of {a}: 0 measured, 1 modelled, 2 not measured")
        sidecar = {"TaskName": task, "SamplingFrequency": round(rate, 6), "TrackingSystemName": f"exubio {method}",
                   "RecordingDuration": round(float(times[-1] - times[0]), 6) if times.size else 0.0,
                   "MotionChannelCount": 3 * len(angles), "JNTANGChannelCount": len(angles),
                   "MISCChannelCount": 2 * len(angles), "TrackedPointsCount": len({_channel(a)[1] for a in angles}),
                   "RecordingType": "continuous", "MissingValues": "n/a", "SoftwareVersions": f"exubio {exubio.__version__}",
                   "Description": f"joint angles of trial '{trial}' (subject '{s}', session '{ses}') reconstructed by "
                                  f"exubio ({method}); first sample at {float(times[0]) if times.size else 0.0:g} s "
                                  f"of the trial"}
        for name, text in ((f"{stem}_motion.tsv", _tsv(data, status.to_numpy())), (f"{stem}_channels.tsv", "\n".join(chan) + "\n"),
                           (f"{stem}_motion.json", json.dumps(sidecar, indent=2) + "\n"),
                           (f"{stem}_channels.json", json.dumps({"Description": f"the channels of {stem}_motion.tsv: per "
                                                                 "anatomical angle its value, standard uncertainty "
                                                                 "and status"}, indent=2) + "\n")):
            written.append(atomic_write(folder / name, lambda tmp, t=text: tmp.write_text(t, encoding="utf-8")))
    description = {"Name": f"{study_name}: joint angles (exubio)", "BIDSVersion": BIDS_VERSION,
                   "DatasetType": "derivative",
                   "GeneratedBy": [{"Name": "exubio", "Version": exubio.__version__,
                                    "Description": "upper-extremity joint angles from motion-capture markers"}]}
    written.append(atomic_write(desc, lambda tmp: tmp.write_text(json.dumps(description, indent=2) + "\n",
                                                                  encoding="utf-8")))
    readme = (f"Joint angles of the study '{study_name}' reconstructed by exubio {exubio.__version__}: per trial and "
              "method (tracksys-pf, tracksys-ls) the ISB anatomical angles in degrees (JNTANG), their standard "
              "uncertainty (MISC, deg) and status (MISC: 0 measured, 1 modelled, 2 not measured).\n")
    written.append(atomic_write(out / "README", lambda tmp: tmp.write_text(readme, encoding="utf-8")))
    return written


def add_bids_arguments(parser) -> None:
    parser.add_argument("--bids", metavar="DIR", help="also write the study's angles as a BIDS motion derivative "
                        "dataset into DIR (e.g. <bids>/derivatives/exubio): per trial and method a _motion.tsv, "
                        "_channels.tsv and _motion.json (docs/bids.md)")
    parser.add_argument("--overwrite-bids", action="store_true", help="replace the files of a dataset already in --bids DIR")


def check_bids(args) -> None:
    """Refuse, before the study runs, a --bids DIR that cannot be written or holds a dataset already."""
    if not getattr(args, "bids", None):
        return
    out = Path(args.bids)
    if out.exists() and not out.is_dir():
        raise InputError(f"--bids {args.bids}: is a file; expected a folder for the derivative dataset")
    if (out / "dataset_description.json").exists() and not args.overwrite_bids:
        raise InputError(f"--bids {args.bids}: holds a dataset already (dataset_description.json); give "
                         f"--overwrite-bids to replace its files")


def bids_after_study(args, study_name: str) -> list[Path]:
    """Write the study's table (``--out``'s angles.parquet) as BIDS into ``--bids`` and say where."""
    from exubio.run.study_table import read_study_table

    files = write_bids(read_study_table(args.out), args.bids, overwrite=args.overwrite_bids, study_name=study_name)
    print(f"BIDS motion derivatives: {sum(f.name.endswith('_motion.tsv') for f in files)} recording(s) in {args.bids}")
    return files
