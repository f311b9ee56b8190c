"""A run with a protocol that names a lab's uncertainty model (``uncertainty_model:``): its angles'
uncertainties come from that model, every output says so, and the result is keyed on the file's
content (a changed model is other inputs, not a set to keep)."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.io.results import read_angles_csv
from exubio.model.load import load_model
from exubio.synth.simulate import Motion, simulate_trial
from exubio.trust.sta_amplitude import shipped_amplitude

pytestmark = [pytest.mark.exudyn, pytest.mark.slow]


def _model_file(path: Path, k: float) -> Path:
    a = shipped_amplitude()
    sd = lambda d: {s: np.asarray(v) * k for s, v in d.items()}
    mom = lambda d: {s: np.asarray(v) * k * k for s, v in d.items()}
    scaled = dataclasses.replace(a, rotation=sd(a.rotation), translation=sd(a.translation), nonrigid=sd(a.nonrigid),
                                 rigid=mom(a.rigid), cross=mom(a.cross), girdle=a.girdle * k * k,
                                 source=f"the shipped model x {k:g}")
    path.write_text(json.dumps(scaled.to_json()))
    return path


def test_the_labs_model_makes_the_uncertainty_and_is_named_and_keyed(tmp_path, capsys):
    trial = write_c3d(tmp_path / "abd.c3d", simulate_trial(load_model(), Motion.ABDUCTION, duration_s=2.0, rate_hz=50.0,
                                                           noise_mm=0.5, seed=3).trajectories)
    u_file = _model_file(tmp_path / "lab_u.json", 2.0)
    protocol = tmp_path / "lab.yaml"
    protocol.write_text("schema_version: 1\nextends: upper_limb_21\nuncertainty_model: lab_u.json\n")
    run = lambda out, *extra: main(["-q", "reconstruct", str(trial), "--method", "ls", "--no-report", "--out",
                                    str(tmp_path / out), *extra])
    assert run("shipped") == 0 and run("lab", "--protocol", str(protocol)) == 0
    _, names, _, u_shipped = read_angles_csv(tmp_path / "shipped" / "abd.ls.csv", uncertainty=True)
    _, _, _, u_lab = read_angles_csv(tmp_path / "lab" / "abd.ls.csv", uncertainty=True)
    both = np.isfinite(u_shipped) & np.isfinite(u_lab)
    assert both.any(axis=0).sum() >= 20
    assert (u_lab[both] >= u_shipped[both] - 1e-12).all()  # twice the artefact and girdle: never a smaller u
    st = names.index("ST_X_upward_rotation_deg")  # an angle whose u is mostly the artefact's: near twice
    assert np.nanmedian(u_lab[:, st] / u_shipped[:, st]) > 1.5
    said = f"{u_file.resolve()} (the shipped model x 2)"
    header = (tmp_path / "lab" / "abd.ls.csv").read_text().splitlines()
    assert any(said in line for line in header if line.startswith("#"))
    assert not any("lab's, not the shipped" in line for line in (tmp_path / "shipped" / "abd.ls.csv").read_text().splitlines())
    summary = json.loads((tmp_path / "lab" / "abd.ls.summary.json").read_text())
    assert summary["anatomical_angles"]["uncertainty_model"] == said
    assert "uncertainty_model" not in json.loads((tmp_path / "shipped" / "abd.ls.summary.json").read_text())[
        "anatomical_angles"]
    capsys.readouterr()
    assert run("lab", "--protocol", str(protocol)) == 0  # the same inputs: kept
    assert "[ls] kept" in capsys.readouterr().out
    _model_file(u_file, 3.0)  # the lab refits its model: other inputs
    assert run("lab", "--protocol", str(protocol)) == 2
    assert "abd.ls.csv: result file already exists" in capsys.readouterr().err
    assert run("lab", "--protocol", str(protocol), "--overwrite") == 0
    assert json.loads((tmp_path / "lab" / "abd.ls.summary.json").read_text())["anatomical_angles"][
        "uncertainty_model"].endswith("(the shipped model x 3)")
