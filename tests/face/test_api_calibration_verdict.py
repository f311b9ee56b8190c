"""The API's verdict after ``exubio.calibrate`` is the CLI's: a simulated static and task pair (the
static's hand moves, so the calibration gives a check) reconstructed by ``exubio reconstruct
--static`` and by ``exubio.calibrate`` + ``exubio.reconstruct``: the same verdict and the same
reasons (level, code, message), the calibration's included."""
from __future__ import annotations

import json

import pytest

import exubio
from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.io.records import to_json

pytestmark = pytest.mark.exudyn


def _reasons(q: dict) -> list[tuple[str, str, str]]:
    return [(r["level"], r["code"], r["message"]) for r in q["reasons"]]


def test_the_api_verdict_after_calibrate_equals_the_clis(tmp_path):
    model = exubio.load_model()
    static = exubio.simulate("abduction", model, duration_s=0.4, rate_hz=50.0, noise_mm=0.5, seed=5).trajectories
    task = exubio.simulate("flexion", model, duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=6).trajectories
    write_c3d(tmp_path / "static.c3d", static)
    write_c3d(tmp_path / "task.c3d", task)
    assert main(["-q", "reconstruct", str(tmp_path / "task.c3d"), "--static", str(tmp_path / "static.c3d"),
                 "--method", "ls", "--no-report", "--out", str(tmp_path / "cli")]) in (0, 1)
    cli = json.loads((tmp_path / "cli" / "task.ls.summary.json").read_text(encoding="utf-8"))["quality"]
    assert any(r["code"].startswith("calibration") for r in cli["reasons"])  # the pair's calibration has a reason

    calibrated, protocol, report = exubio.calibrate(exubio.read_trial(tmp_path / "static.c3d"))
    rec = exubio.reconstruct(exubio.read_trial(tmp_path / "task.c3d"), calibrated, protocol, method="ls")
    api = to_json(rec.quality)
    assert api["verdict"] == cli["verdict"] == rec.verdict
    assert _reasons(api) == _reasons(cli)
    # the files the API writes for the same trial carry the same verdict and reasons
    paths = exubio.write_results(rec, tmp_path / "api", "task", model=calibrated, protocol=protocol,
                                 trial=tmp_path / "task.c3d")
    written = json.loads(paths["summary"].read_text(encoding="utf-8"))["quality"]
    assert _reasons(written) == _reasons(cli)
    # a model not made by exubio.calibrate (the generic one) carries no calibration: no such reason
    plain = exubio.reconstruct(exubio.read_trial(tmp_path / "task.c3d"), model, method="ls")
    assert not any(r.code.startswith("calibration") for r in plain.quality.reasons)
