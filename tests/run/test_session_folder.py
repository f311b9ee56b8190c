"""One session folder across calls (issue 23): a second trial of the session reconstructed into the
folder where the first one's calibration was written reuses it (the same static file, labels,
protocol, model and options: read from the file, not fitted again, not refused), and gives the
results a fresh calibration gives; other inputs are refused, never silently reused."""
from __future__ import annotations

import json

import numpy as np
import pytest

from exubio.cli import main

pytestmark = [pytest.mark.slow, pytest.mark.exudyn]


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    d = tmp_path_factory.mktemp("session")
    for name, args in (("static", ["--motion", "abduction", "--duration", "1.5", "--seed", "3"]),
                       ("t1", ["--motion", "abduction", "--duration", "2", "--seed", "4"]),
                       ("t2", ["--motion", "flexion", "--duration", "2", "--seed", "5"])):
        assert main(["-q", "simulate", *args, "--rate", "50", "--noise-mm", "0.5", "--out", str(d / f"{name}.c3d")]) == 0
    return d


def _run(trials, trial, out, *extra):
    return main(["reconstruct", str(trials / f"{trial}.c3d"), "--static", str(trials / "static.c3d"),
                 "--static-frames", "0:40", "--method", "ls", "--out", str(out), "-q", "--no-report", *extra])


def _close(a, b, skip=frozenset()):
    """Equal, numbers to 1e-3 (mm, deg), keys in ``skip`` aside."""
    if isinstance(a, dict):
        return isinstance(b, dict) and set(a) == set(b) and all(_close(a[k], b[k]) for k in a if k not in skip)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)):
        return abs(a - b) <= 1e-3 or (np.isnan(a) and np.isnan(b))
    return a == b


def _summary(folder, trial):
    return json.loads((folder / f"{trial}.ls.summary.json").read_text())


def test_a_second_trial_reuses_the_session_folders_calibration(trials, tmp_path, capsys):
    folder = tmp_path / "session"
    assert _run(trials, "t1", folder) == 0
    model_file = folder / "static.model.yaml"
    written, stamp = model_file.read_bytes(), model_file.stat().st_mtime_ns
    capsys.readouterr()
    assert _run(trials, "t2", folder) == 0
    assert "calibration reused" in capsys.readouterr().out
    assert model_file.read_bytes() == written and model_file.stat().st_mtime_ns == stamp  # not fitted again
    assert _run(trials, "t2", tmp_path / "fresh") == 0  # the same trial with a calibration of its own
    reused, fresh = _summary(folder, "t2"), _summary(tmp_path / "fresh", "t2")
    assert reused["quality"] == fresh["quality"]
    # the reused report is the file's: its values as written (residuals to the µm), the rest the same
    assert _close(reused["calibration"]["report"], fresh["calibration"]["report"])
    assert _close(reused["calibration"], fresh["calibration"], skip={"model_file", "report"})
    with np.load(folder / "t2.ls.npz") as a, np.load(tmp_path / "fresh" / "t2.ls.npz") as b:
        assert np.array_equal(a["q_rad"], b["q_rad"])


def test_a_calibration_from_other_inputs_is_refused_not_reused(trials, tmp_path, capsys):
    folder = tmp_path / "session"
    assert _run(trials, "t1", folder) == 0
    capsys.readouterr()
    args = ["reconstruct", str(trials / "t2.c3d"), "--static", str(trials / "static.c3d"), "--static-frames", "0:30",
            "--method", "ls", "--out", str(folder), "-q", "--no-report"]
    assert main(args) == 2  # other static frames: another calibration, which would replace the file
    err = capsys.readouterr().err
    assert "static.model.yaml" in err and "--overwrite" in err
    assert not (folder / "t2.ls.summary.json").exists()
