"""Hints that fix a labelling mistake the first time (issue 35, item 4): a missing marker with a near
label is proposed and left out also when the trial is calibrated on its own frames; a static
marker missing from most frames is named as missing (exit 2), not a "nan" calibration; a swap seen
in both the static and the trial gets one fix for both (--relabel and --static-relabel), which does
fix both."""
import dataclasses
import json

import numpy as np
import pytest

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial


@pytest.fixture(scope="module")
def trial():
    return simulate_trial(load_model(), "abduction", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=3).trajectories


def _renamed(traj, mapping):
    return dataclasses.replace(traj, labels=tuple(mapping.get(lab, lab) for lab in traj.labels))


def _reasons(summary_path, code=None):
    summ = json.loads(summary_path.read_text(encoding="utf-8"))
    return [r for r in summ["quality"]["reasons"] if code is None or r["code"] == code]


def test_a_near_label_is_proposed_and_the_marker_left_out_when_calibrating_on_the_trials_frames(tmp_path, trial):
    """SCAP_Cor labelled CAP_Cor, calibrated on the trial's own frames: before, the calibration
    refused the trial ("needs marker 'SCAP_Cor'") without naming CAP_Cor."""
    path = write_c3d(tmp_path / "typo.c3d", _renamed(trial, {"SCAP_Cor": "CAP_Cor"}))
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(path), "--static-frames", "0:10", "--method", "ls", "--no-report",
                 "--out", str(out)]) == 0
    reasons = _reasons(out / "typo.ls.summary.json", "missing_marker")
    assert len(reasons) == 1 and reasons[0]["level"] == "check"
    assert "SCAP_Cor" in reasons[0]["message"] and "--relabel CAP_Cor=SCAP_Cor" in reasons[0]["message"]


def test_the_proposed_relabel_fixes_it(tmp_path, trial):
    path = write_c3d(tmp_path / "typo.c3d", _renamed(trial, {"SCAP_Cor": "CAP_Cor"}))
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(path), "--static-frames", "0:10", "--method", "ls", "--no-report",
                 "--relabel", "CAP_Cor=SCAP_Cor", "--out", str(out)]) == 0
    assert not _reasons(out / "typo.ls.summary.json", "missing_marker")


def test_a_static_marker_missing_from_most_frames_is_named_as_missing(tmp_path, trial, capsys):
    """SCAP_IA has a sample in 3 of the static's 100 frames: before, the calibration residual was
    "nan" and the run ended with exit 1."""
    pos = trial.positions_m.copy()
    j = trial.labels.index("SCAP_IA")
    keep = pos[[2, 40, 90], j].copy()
    pos[:, j] = np.nan
    pos[[2, 40, 90], j] = keep
    static = write_c3d(tmp_path / "static.c3d", dataclasses.replace(trial, positions_m=pos))
    path = write_c3d(tmp_path / "trial.c3d", trial)
    code = main(["-q", "reconstruct", str(path), "--static", str(static), "--method", "ls", "--no-report",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "SCAP_IA" in err and "is missing" in err and "static.c3d" in err and "2, 40, 90" in err
    assert "nan" not in err and "Traceback" not in err


@pytest.mark.slow  # a calibration and a reconstruction end to end (about 6-11 s)
def test_a_swap_in_the_static_and_the_trial_gets_one_fix_for_both(tmp_path, trial):
    swap = {"ULNA": "RADIUS", "RADIUS": "ULNA"}
    static = write_c3d(tmp_path / "static.c3d", _renamed(trial, swap))
    path = write_c3d(tmp_path / "trial.c3d", _renamed(trial, swap))
    out = tmp_path / "out"
    main(["-q", "reconstruct", str(path), "--static", str(static), "--static-frames", "0:10", "--method", "ls",
          "--no-report", "--out", str(out)])
    swaps = [r for r in _reasons(out / "trial.ls.summary.json", "label") if "swap" in r["message"]]
    assert len(swaps) == 1, swaps  # one reason, not one for the static and one for the trial
    msg = swaps[0]["message"]
    assert "--relabel ULNA=RADIUS,RADIUS=ULNA --static-relabel ULNA=RADIUS,RADIUS=ULNA" in msg \
        or "--relabel RADIUS=ULNA,ULNA=RADIUS --static-relabel RADIUS=ULNA,ULNA=RADIUS" in msg
    fix = msg.split("to fix both: ")[1].split(" (")[0].split()
    out2 = tmp_path / "fixed"
    assert main(["-q", "reconstruct", str(path), "--static", str(static), "--static-frames", "0:10", "--method", "ls",
                 "--no-report", "--out", str(out2), *fix]) == 0
    assert not [r for r in _reasons(out2 / "trial.ls.summary.json", "label") if "swap" in r["message"]]


@pytest.mark.slow  # a reconstruction end to end (about 3-6 s)
def test_a_swap_when_calibrating_on_the_trials_own_frames_gets_only_relabel(tmp_path, trial):
    """No separate static: the fix is --relabel alone (it is applied before the calibration)."""
    path = write_c3d(tmp_path / "trial.c3d", _renamed(trial, {"ULNA": "RADIUS", "RADIUS": "ULNA"}))
    out = tmp_path / "out"
    main(["-q", "reconstruct", str(path), "--static-frames", "0:10", "--method", "ls", "--no-report", "--out", str(out)])
    swaps = [r for r in _reasons(out / "trial.ls.summary.json", "label") if "swap" in r["message"]]
    assert len(swaps) == 1 and "to fix: --relabel" in swaps[0]["message"]
    assert "--static-relabel" not in swaps[0]["message"]
