"""BIDS motion derivatives (exubio study --bids DIR): the study's angles come back from the files exactly
as the study table holds them, labels are made BIDS labels or refused, and the official BIDS validator
(the schema-based one, PyPI bids-validator-deno) accepts the dataset where it is installed."""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from exubio.errors import InputError
from exubio.run.bids import bids_label, write_bids

ANGLES = ("GH_X_elevation", "HT_Y_axial_rotation", "elbow_flexion")
STATUS = ("measured", "modelled", "not measured")
TRIALS = (("P01", "day1", "t1", "drinking"), ("P01", "day1", "t2", "drinking"), ("P01", "day2", "t3", "comb hair"),
          ("P_02", "day1", "t4", "drinking"))


def _table(seed: int = 0) -> pd.DataFrame:
    """A study table (exubio.run.study_table's columns) with known values: random angles, an uncertainty
    that is infinite for one angle, statuses that change frame by frame."""
    rng = np.random.default_rng(seed)
    rows = []
    for subject, session, trial, task in TRIALS:
        for method in ("pf", "ls"):
            for k in range(7):
                for a, angle in enumerate(ANGLES):
                    rows.append({"subject": subject, "session": session, "trial": trial, "task": task, "method": method,
                                 "time_s": 0.2 + k / 100, "angle": angle, "value_deg": float(rng.normal(0, 60)),
                                 "u_deg": np.inf if angle == "elbow_flexion" else float(rng.uniform(1, 9)),
                                 "status": STATUS[(k + a) % 3], "verdict": "ok"})
    df = pd.DataFrame(rows)
    for c in ("subject", "session", "trial", "task", "method", "angle", "status", "verdict"):
        df[c] = pd.Categorical(df[c])
    return df


def _read(tsv: Path) -> np.ndarray:
    return np.array([[np.nan if c == "n/a" else float(c) for c in line.split("\t")]
                     for line in tsv.read_text().splitlines()])


def test_the_files_give_back_the_table(tmp_path):
    table = _table()
    write_bids(table, tmp_path / "bids", study_name="unit")
    root = tmp_path / "bids"
    desc = json.loads((root / "dataset_description.json").read_text())
    assert desc["DatasetType"] == "derivative" and desc["GeneratedBy"][0]["Name"] == "exubio"
    motion = sorted(root.rglob("*_motion.tsv"))
    assert len(motion) == len(TRIALS) * 2
    runs = {p.name for p in motion}
    assert "sub-P01_ses-day1_task-drinking_tracksys-pf_run-2_motion.tsv" in runs  # two trials of one task: runs
    assert "sub-P01_ses-day2_task-combhair_tracksys-ls_motion.tsv" in runs  # one: no run entity, label sanitised
    assert "sub-P02_ses-day1_task-drinking_tracksys-ls_motion.tsv" in runs
    for (subject, session, trial, task), run in zip(TRIALS, (1, 2, None, None)):
        for method in ("pf", "ls"):
            sub = bids_label(subject, what="subject")
            stem = (f"sub-{sub}_ses-{session}_task-{bids_label(task, what='task')}_tracksys-{method}"
                    + (f"_run-{run}" if run else ""))
            folder = root / f"sub-{sub}" / f"ses-{session}" / "motion"
            data = _read(folder / f"{stem}_motion.tsv")
            part = table[(table.trial == trial) & (table.method == method)]
            chans = [line.split("\t") for line in (folder / f"{stem}_channels.tsv").read_text().splitlines()]
            assert chans[0][:5] == ["name", "component", "type", "tracked_point", "units"]
            names = [c[0] for c in chans[1:]]
            assert data.shape == (7, len(names))
            for a in ANGLES:
                rows = part[part.angle == a].sort_values("time_s")
                np.testing.assert_allclose(data[:, names.index(a)], rows.value_deg, atol=5e-7)
                u = rows.u_deg.to_numpy()
                np.testing.assert_allclose(data[:, names.index(f"{a}_u")], np.where(np.isinf(u), np.nan, u), atol=5e-7)
                codes = [STATUS.index(s) for s in rows.status.astype(str)]
                assert data[:, names.index(f"{a}_status")].tolist() == codes
            types = {c[0]: (c[2], c[4]) for c in chans[1:]}
            assert types["GH_X_elevation"] == ("JNTANG", "deg") and types["GH_X_elevation_status"][0] == "MISC"
            side = json.loads((folder / f"{stem}_motion.json").read_text())
            assert side["SamplingFrequency"] == pytest.approx(100.0) and side["TaskName"] == task


def test_labels_are_made_bids_labels_or_refused(tmp_path):
    assert bids_label("P_02-b", what="subject") == "P02b"
    with pytest.raises(InputError, match="subject '__'"):
        bids_label("__", what="subject")
    table = _table()
    table["subject"] = table["subject"].astype(str).replace({"P_02": "P-01"})
    table["subject"] = table["subject"].astype(str).replace({"P01": "P_01"})
    with pytest.raises(InputError, match="'P_01' and 'P-01' both become the BIDS label 'P01'"):
        write_bids(table, tmp_path / "b")


def test_an_existing_dataset_is_not_overwritten(tmp_path):
    write_bids(_table(), tmp_path / "b")
    with pytest.raises(InputError, match="overwrite"):
        write_bids(_table(1), tmp_path / "b")
    write_bids(_table(1), tmp_path / "b", overwrite=True)


def _validator() -> str | None:
    return shutil.which("bids-validator-deno")


@pytest.mark.skipif(_validator() is None, reason="the BIDS validator (pip install bids-validator-deno) is absent")
def test_the_bids_validator_accepts_the_dataset(tmp_path):
    write_bids(_table(), tmp_path / "bids", study_name="unit")
    done = subprocess.run([_validator(), str(tmp_path / "bids"), "--format", "json"], capture_output=True, text=True,
                          timeout=300)
    report = json.loads(done.stdout)
    errors = [i for i in report["issues"]["issues"] if i["severity"] == "error"]
    assert not errors, errors[:3]
    assert done.returncode == 0
    assert "motion" in report["summary"]["modalities"]


@pytest.mark.slow  # a one-trial study (LS) through the CLI
def test_exubio_study_writes_bids_from_its_table(tmp_path):
    import yaml

    from exubio.api import load_study
    from exubio.cli import main

    trial = tmp_path / "abduction_1.c3d"
    shutil.copy(Path(__file__).resolve().parents[2] / "exubio" / "data" / "example_abduction.c3d", trial)
    study = tmp_path / "study.yaml"
    study.write_text(yaml.safe_dump({"schema_version": 1, "report": False, "methods": ["ls"], "sessions": [
        {"subject": "S-01", "session": "pre", "trials": ["abduction_1.c3d"], "tasks": {"abduction_1.c3d": "abduction"}}]}))
    out, bids = tmp_path / "out", tmp_path / "derivatives" / "exubio"
    assert main(["study", str(study), "--out", str(out), "--bids", str(bids), "-q"]) in (0, 1)
    # one session in the whole study: no ses- level (BIDS: optional where a subject has one session)
    tsv = bids / "sub-S01" / "motion" / "sub-S01_task-abduction_tracksys-ls_motion.tsv"
    data = _read(tsv)
    names = [line.split("\t")[0] for line in tsv.with_name(tsv.name.replace("_motion.tsv", "_channels.tsv"))
             .read_text().splitlines()[1:]]
    table = load_study(out)
    gh = table[table.angle == "GH_X_elevation"].sort_values("time_s")
    np.testing.assert_allclose(data[:, names.index("GH_X_elevation")], gh.value_deg, atol=5e-7)
    assert main(["study", str(study), "--out", str(out), "--bids", str(bids), "-q"]) == 2  # not overwritten
