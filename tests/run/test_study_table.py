"""The study's one table (exubio.run.study_table): ``angles.parquet`` read back by pandas and by
pyarrow, and ``angles.csv.gz``, hold the rows of the per-trial CSVs (value, uncertainty), the status
of each trial's .npz and its verdict, typed (categoricals, float64); ``exubio.load_study`` returns
it; the session's ``tasks`` key names the task."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import yaml

import exubio
from exubio.cli import main
from exubio.io.results import read_angles_csv, read_npz_arrays
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial, write_simulated_trial

pytestmark = [pytest.mark.exudyn, pytest.mark.slow]


def _trial(path: Path, motion: str, seed: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_simulated_trial(simulate_trial(load_model(), motion, duration_s=2.0, rate_hz=25.0, noise_mm=0.5, seed=seed),
                          path)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("table")
    _trial(tmp / "a" / "abd.c3d", "abduction", 1)
    _trial(tmp / "a" / "flx.c3d", "flexion", 2)
    _trial(tmp / "b" / "abd.c3d", "abduction", 3)
    spec = {"schema_version": 1, "name": "t", "report": False, "methods": ["ls"], "sessions": [
        {"subject": "S01", "trials": ["a/*.c3d"], "tasks": {"flx.c3d": "flexion"}},
        {"subject": "S02", "trials": ["b/*.c3d"], "static_frames": "10:40"}]}  # a moving window: a check
    (tmp / "study.yaml").write_text(yaml.safe_dump(spec), encoding="utf-8")
    out = tmp / "out"
    assert main(["-q", "study", str(tmp / "study.yaml"), "--out", str(out)]) in (0, 1)
    return out


def _expected(out: Path) -> pd.DataFrame:
    """The rows the per-trial files hold, read with the file readers (not the table's code)."""
    parts = []
    for row in json.loads((out / "study.json").read_text(encoding="utf-8"))["trials"]:
        stem = Path(row["trial"]).stem
        csv = Path(row["folder"]) / f"{stem}.ls.csv"
        t, names, q, u = read_angles_csv(csv, uncertainty=True)
        status = read_npz_arrays(csv.with_suffix(".npz"), ("angle_status",))["angle_status"]
        for j, n in enumerate(names):
            parts.append(pd.DataFrame({"subject": row["subject"], "session": row["session"], "trial": stem,
                                       "method": "ls", "time_s": t, "angle": n.removesuffix("_deg"),
                                       "value_deg": np.degrees(q[:, j]), "u_deg": np.degrees(u[:, j]),
                                       "code": status[:, j], "verdict": row["ls_verdict"]}))
    return pd.concat(parts, ignore_index=True)


def _same(df: pd.DataFrame, ref: pd.DataFrame, atol: float) -> None:
    assert len(df) == len(ref) and len(df) > 0
    for c in ("subject", "session", "trial", "method", "angle", "verdict"):
        assert list(df[c].astype(str)) == list(ref[c].astype(str)), c
    np.testing.assert_allclose(df["time_s"], ref["time_s"], atol=atol)
    np.testing.assert_allclose(df["value_deg"], ref["value_deg"], atol=atol)
    np.testing.assert_allclose(df["u_deg"], ref["u_deg"], atol=atol, equal_nan=True)
    labels = {0: "measured", 1: "modelled", 2: "not measured"}
    assert list(df["status"].astype(str)) == [labels[int(c)] for c in ref["code"]]


def test_parquet_read_by_pandas_and_pyarrow_holds_the_trial_files_rows(study):
    ref = _expected(study)
    by_pandas = pd.read_parquet(study / "angles.parquet")
    _same(by_pandas, ref, 1e-9)
    by_arrow = pq.read_table(study / "angles.parquet").to_pandas()
    _same(by_arrow, ref, 1e-9)
    assert pq.read_table(study / "angles.parquet").num_rows == len(ref)
    for c in ("subject", "session", "trial", "task", "method", "angle", "status", "verdict"):
        assert isinstance(by_pandas[c].dtype, pd.CategoricalDtype), c
    for c in ("time_s", "value_deg", "u_deg"):
        assert by_pandas[c].dtype == np.float64, c
    loaded = exubio.load_study(study)
    _same(loaded, ref, 1e-9)
    tasks = loaded.groupby(["subject", "trial"], observed=True)["task"].first().astype(str).to_dict()
    assert tasks == {("S01", "abd"): "abd", ("S01", "flx"): "flexion", ("S02", "abd"): "abd"}


def test_the_gzipped_csv_holds_the_same_rows(study):
    _same(pd.read_csv(study / "angles.csv.gz", keep_default_na=False, na_values=["", "nan", "NaN"]),
          _expected(study), 1e-6)


def test_load_study_names_a_folder_without_the_table(tmp_path):
    with pytest.raises(exubio.InputError, match="angles.parquet"):
        exubio.load_study(tmp_path)


def test_study_csv_and_report_give_every_check_and_fail_reason(study):
    """study.csv's reasons: every check and fail reason of each trial's summary.json, and nothing of
    an ok trial; the study report writes them in the row."""
    import csv

    from exubio.report.calibration_page import short_paths
    from exubio.report.study_report import study_pages

    rows = list(csv.DictReader((study / "study.csv").open(encoding="utf-8")))
    assert "reasons" in rows[0]
    checked = 0
    for row in rows:
        summary = json.loads((Path(row["folder"]) / f"{Path(row['trial']).stem}.ls.summary.json").read_text(
            encoding="utf-8"))
        want = [r["message"] for r in summary["quality"]["reasons"] if r["level"] in ("check", "fail")]
        assert all(f"LS {level}: {m}" in row["reasons"] for m, level in
                   ((r["message"], r["level"]) for r in summary["quality"]["reasons"] if r["level"] in ("check", "fail")))
        assert "LS note:" not in row["reasons"]  # notes are not reasons to read before using the angles
        if row["ls_verdict"] == "ok":
            assert row["reasons"] == ""
        else:
            assert want and row["reasons"]
            checked += 1
    assert checked  # S02's calibration window moves: a check
    data = json.loads((study / "study.json").read_text(encoding="utf-8"))
    text = " ".join(t.get_text() for f in study_pages(data) for t in f.texts).replace("\n", "")
    for row in data["trials"]:
        if row["reasons"]:
            first = short_paths(row["reasons"].split(": ", 1)[1])[:25]  # the report writes files by their names
            assert first.replace(" ", "") in text.replace(" ", ""), first


def test_default_session_names_count_per_subject(tmp_path):
    from exubio.run.study import load_study

    for f in ("a.c3d", "b.c3d", "c.c3d"):
        (tmp_path / f).write_bytes(b"")
    spec = {"schema_version": 1, "sessions": [{"subject": "S01", "trials": ["a.c3d"]},
                                              {"subject": "S02", "trials": ["b.c3d"]},
                                              {"subject": "S01", "trials": ["c.c3d"]}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(spec), encoding="utf-8")
    got = [(s.subject, s.session) for s in load_study(tmp_path / "s.yaml").sessions]
    assert got == [("S01", "s1"), ("S02", "s1"), ("S01", "s2")]
