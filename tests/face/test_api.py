"""The Python API exported from ``exubio``: the docs' notebook example (docs/python-api.md) runs as written, and the
names do what the command line does (same angles as the pipeline, DataFrame in degrees, files
written atomically and not overwritten)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import exubio
from exubio.cli import main

pytestmark = pytest.mark.exudyn

PAGE = Path(__file__).resolve().parents[2] / "docs" / "python-api.md"


def _example() -> str:
    text = PAGE.read_text(encoding="utf-8")
    m = re.search(r"<!-- api-example -->\s*```python\n(.*?)```", text, re.S)
    assert m, f"{PAGE} has no API example block"
    return m.group(1)


def test_readme_api_example_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["-q", "simulate", "--motion", "abduction", "--duration", "4", "--rate", "50", "--noise-mm", "0.5",
                 "--out", "trial.c3d"]) == 0
    scope: dict = {}
    exec(compile(_example(), str(PAGE), "exec"), scope)
    df, rec, paths = scope["df"], scope["rec"], scope["paths"]
    assert isinstance(rec, exubio.Reconstruction) and len(df) == rec.n_frames == 200
    from exubio.model.angles import anatomical_table
    from exubio.io.results import read_angles_csv

    names, ang = anatomical_table(scope["model"], rec.q_rad)
    np.testing.assert_allclose(df["HT_X_elevation_deg"].to_numpy(), np.degrees(ang[:, names.index("HT_X_elevation")]))
    assert set(df["SC_Z_posterior_rotation_status"]) == {"not measured"}
    assert set(df["HT_X_elevation_status"]) == {"measured"}
    assert {"csv", "mot", "npz", "summary"} <= set(paths) and all(Path(p).is_file() for p in paths.values())
    # the files the API wrote carry the same angles as the DataFrame
    _, csv_names, csv_ang = read_angles_csv(paths["csv"])
    assert np.abs(np.degrees(csv_ang) - df[list(csv_names)].to_numpy()).max() < 1e-5
    # the truth the simulation wrote: the API's reconstruction recovers the measured angles
    _, _, q_true = read_angles_csv(tmp_path / "trial.truth.csv")
    _, truth = anatomical_table(scope["model"], q_true)
    i = names.index("HT_X_elevation")
    assert np.degrees(np.sqrt(np.mean((ang[:, i] - truth[:, i]) ** 2))) < 2.0


def test_api_names_are_exported():
    for name in ("read_trial", "load_model", "load_protocol", "calibrate", "reconstruct", "assess", "angles", "simulate",
                 "angle_status", "to_dataframe", "write_results", "Reconstruction"):
        assert name in exubio.__all__ and getattr(exubio, name) is not None
    with pytest.raises(AttributeError):
        exubio.no_such_name  # noqa: B018


def test_write_results_refuses_to_overwrite(tmp_path):
    model = exubio.load_model()
    from exubio.io.resources import shipped_file

    c3d = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    rec = exubio.reconstruct(exubio.read_trial(c3d), model, method="ls")
    exubio.write_results(rec, tmp_path, "t")
    with pytest.raises(exubio.InputError):
        exubio.write_results(rec, tmp_path, "t")


def test_calibrate_returns_a_bound_model_and_protocol():
    from exubio.io.resources import shipped_file

    trial = exubio.read_trial(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"))
    model, protocol, report = exubio.calibrate(trial, frames=slice(0, 20))
    assert model.metadata.get("calibration") is not None or report.frames == (0, 20)
    rec = exubio.reconstruct(trial, model, protocol, method="ls")
    assert np.nanmean(rec.residuals_m) < 0.01


def test_methods_come_from_one_registry_and_options_are_checked():
    """Every method of the registry runs through the same entry point; a misspelt option is one
    InputError naming it and the method's options (not a TypeError from deep inside)."""
    from exubio.methods import REGISTRY
    from exubio.types import Method
    from exubio.io.resources import shipped_file

    assert {Method.PF, Method.LS} <= set(REGISTRY)  # the shipped two; tests/methods/test_third_method.py adds one
    trial = exubio.read_trial(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"))
    with pytest.raises(exubio.InputError, match=r"unknown option\(s\) \['tol'\].*tol_rad"):
        exubio.reconstruct(trial, method="ls", tol=1e-6)
    with pytest.raises(exubio.InputError, match="valid methods"):
        exubio.reconstruct(trial, method="kalman")
    rec = exubio.reconstruct(trial, method="ls", tol_rad=1e-6)
    assert rec.method == "ls"


def test_typed_options_objects_are_accepted_and_checked():
    """The entry point takes the method's options object; another method's options are refused."""
    from exubio.methods.ls import LSOptions
    from exubio.methods.pf import PFOptions
    from exubio.run.pipeline import load_inputs, reconstruct
    from exubio.io.resources import shipped_file

    inp = load_inputs(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"))
    rec = reconstruct(inp.model, inp.protocol, inp.targets, method="ls", options=LSOptions(tol_rad=1e-6))
    assert rec.info["options"]["tol_rad"] == 1e-6
    with pytest.raises(exubio.InputError, match="expected LSOptions"):
        reconstruct(inp.model, inp.protocol, inp.targets, method="ls", options=PFOptions())
    with pytest.raises(exubio.InputError, match="not both"):
        reconstruct(inp.model, inp.protocol, inp.targets, method="ls", options=LSOptions(), tol_rad=1e-6)
