"""The Python face a notebook user sees: the names dir() and help() show, the verdict of
exubio.reconstruct equal to the CLI's for the same trial, and the documented example running."""
from __future__ import annotations

import json
import textwrap

import pytest

import exubio
from exubio.cli import main
from exubio.io.resources import shipped_file

pytestmark = pytest.mark.exudyn

EXAMPLE = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
FACE = {"read_trial", "load_model", "load_protocol", "calibrate", "reconstruct", "assess", "angles", "angle_status",
        "to_dataframe", "write_results", "simulate", "rhythm", "load_study", "Trajectories", "Model", "Protocol", "Reconstruction"}


def test_dir_and_help_show_the_face():
    assert FACE <= set(dir(exubio))
    assert "ExubioError" in dir(exubio)
    for name in FACE:
        assert getattr(exubio, name) is not None, name
    text = exubio.__doc__ or ""
    assert all(name in text for name in FACE)


def test_the_stub_lists_every_name_of_the_face():
    from pathlib import Path

    stub = (Path(exubio.__file__).with_name("__init__.pyi")).read_text(encoding="utf-8")
    assert all(f"import {name} as {name}" in stub for name in FACE)
    assert (Path(exubio.__file__).with_name("py.typed")).is_file()


def _cli_verdicts(tmp_path, method: str) -> dict[str, str]:
    out = tmp_path / f"cli_{method}"
    code = main(["reconstruct", str(EXAMPLE), "--method", method, "--no-report", "--out", str(out), "--quiet"])
    assert code in (0, 1)
    return {m: json.loads((out / f"example_abduction.{m}.summary.json").read_text(encoding="utf-8"))["quality"]["verdict"]
            for m in (("pf", "ls") if method == "both" else (method,))}


@pytest.mark.parametrize("method", ["ls", "pf"])
def test_reconstruct_returns_the_clis_verdict(tmp_path, method):
    rec = exubio.reconstruct(EXAMPLE, method=method)
    assert rec.verdict in ("ok", "check", "fail")
    assert {method: rec.verdict} == _cli_verdicts(tmp_path, method)
    assert rec.quality.reasons is not None


def test_assess_of_both_methods_returns_the_clis_verdicts(tmp_path):
    trial = exubio.read_trial(EXAMPLE)
    recs = [exubio.reconstruct(trial, method="pf"), exubio.reconstruct(trial, method="ls")]
    assessment = exubio.assess(trial, recs)
    assert {m: assessment.quality[m].verdict for m in ("pf", "ls")} == _cli_verdicts(tmp_path, "both")
    assert assessment.agreement_deg  # the PF-LS agreement entered the verdicts


def test_the_documented_example_runs(tmp_path, monkeypatch):
    """The example at the top of exubio.api, run as written (the trial and static files replaced by
    the shipped example, calibrated on its first 0.5 s)."""
    import exubio.api

    doc = exubio.api.__doc__
    block = textwrap.dedent("\n".join(line for line in doc.splitlines() if line.startswith("    ")))
    block = block.replace('"trial.c3d"', repr(str(EXAMPLE))).replace(
        'exubio.read_trial("static.c3d"), model, protocol', f"exubio.read_trial({str(EXAMPLE)!r}), model, protocol, "
                                                           "frames=slice(0, 50)")
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(block, "exubio.api example", "exec"), scope)  # noqa: S102 - our own documented example
    assert scope["rec"].verdict in ("ok", "check", "fail")
    assert set(scope["both"].quality) == {"ls", "pf"}
    assert scope["df"].shape[0] == scope["rec"].n_frames
    assert (tmp_path / "out" / "trial.ls.csv").is_file()
    assert abs(scope["angles"]["HT_X_elevation"]).max() > 0.5  # the arm abducts (rad)
