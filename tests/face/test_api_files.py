"""The API writes the CLI's files (issue 23): ``exubio.write_results(rec, out, stem, trial=T)`` of
``exubio.reconstruct(T, method=...)`` gives the same CSV and .mot bytes, the same summary.json and
the same .npz arrays as ``exubio reconstruct T --method ...``, apart from the wall-clock timings."""
from __future__ import annotations

import json

import numpy as np
import pytest

import exubio
from exubio.cli import main
from exubio.io.resources import shipped_file

pytestmark = pytest.mark.exudyn

TIMINGS = {"wall_time_s", "ms_per_frame", "timings_s", "exudyn_cpu_times_s"}


def _without_timings(obj):
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items() if k not in TIMINGS}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


@pytest.mark.parametrize("method", ["ls", "pf"])
def test_write_results_writes_the_files_of_the_cli(tmp_path, monkeypatch, method):
    trial = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    monkeypatch.chdir(tmp_path)
    assert main(["reconstruct", str(trial), "--method", method, "--out", "cli", "-q", "--no-report"]) == 0
    rec = exubio.reconstruct(str(trial), method=method)
    paths = exubio.write_results(rec, tmp_path / "api", trial.stem, trial=str(trial))
    cli = tmp_path / "cli"
    assert sorted(p.name for p in paths.values()) == sorted(p.name for p in cli.iterdir())
    for kind in ("csv", "mot"):
        assert paths[kind].read_bytes() == (cli / paths[kind].name).read_bytes(), kind
    a = json.loads((cli / paths["summary"].name).read_text())
    b = json.loads(paths["summary"].read_text())
    assert a["quality"]["verdict"] == b["quality"]["verdict"] == rec.verdict
    assert _without_timings(a) == _without_timings(b)
    with np.load(cli / paths["npz"].name) as na, np.load(paths["npz"]) as nb:
        assert set(na.files) == set(nb.files)
        for key in na.files:
            if key == "timings_json":
                continue
            if key.endswith("_json"):
                assert _without_timings(json.loads(str(na[key]))) == _without_timings(json.loads(str(nb[key]))), key
                continue
            assert np.array_equal(na[key], nb[key], equal_nan=na[key].dtype.kind == "f"), key
