"""A protocol marker the trial lacks is left out with a check naming it when the other markers still
measure every angle the full set measures, and refused (exit 2, naming it, a near label and the
angles it would cost) when they do not (exubio.trust.missing_markers)."""
import dataclasses
import json

import pytest

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial


@pytest.fixture(scope="module")
def trial():
    return simulate_trial(load_model(), "abduction", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=2).trajectories


def _renamed(traj, old, new):
    return dataclasses.replace(traj, labels=tuple(new if lab == old else lab for lab in traj.labels))


def test_a_typo_on_a_redundant_marker_is_left_out_with_a_check(tmp_path, trial):
    """SCAP_Cor labelled CAP_Cor: the scapula keeps five markers and every angle stays measured in
    nearly as many frames as with every marker (fewer scapula markers average less of the skin's
    artefact: near HT 110 deg ST upward rotation's uncertainty passes the bound in a sixth of them, since
    the uncertainty carries the scapula and humerus clusters' artefacts moving together)."""
    path = write_c3d(tmp_path / "typo.c3d", _renamed(trial, "SCAP_Cor", "CAP_Cor"))
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(path), "--method", "ls", "--no-report", "--out", str(out)]) == 0
    summ = json.loads((out / "typo.ls.summary.json").read_text(encoding="utf-8"))
    reasons = [r for r in summ["quality"]["reasons"] if r["code"] == "missing_marker"]
    assert reasons and reasons[0]["level"] == "check" and "SCAP_Cor" in reasons[0]["message"]
    assert summ["quality"]["verdict"] == "check"
    whole = tmp_path / "whole"
    assert main(["-q", "reconstruct", str(write_c3d(tmp_path / "typo.c3d", trial)), "--method", "ls", "--no-report",
                 "--out", str(whole)]) == 0
    full = json.loads((whole / "typo.ls.summary.json").read_text(encoding="utf-8"))["anatomical_angles"]
    for name in ("ST_X_upward_rotation", "ST_Y_internal_rotation", "GH_phadke_X_elevation", "HT_X_elevation"):
        # measured: 0.83 of the frames for ST upward rotation without SCAP_Cor (1.0 with it), the rest as with it
        assert summ["anatomical_angles"]["frames_measured_fraction"][name] >= full["frames_measured_fraction"][name] - 0.2


def test_markers_whose_loss_costs_an_angle_are_refused(tmp_path, trial, capsys):
    """Both metacarpal markers mislabelled: the wrist would no longer be measured: one error naming
    them, the near labels the trial has and the wrist angles."""
    traj = _renamed(_renamed(trial, "MET2", "MET_2"), "MET5", "MET_5")
    path = write_c3d(tmp_path / "bad.c3d", traj)
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(path), "--method", "ls", "--no-report", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "MET2" in err and "MET5" in err and "wrist_flexion" in err and "'MET_2' for MET2" in err
    assert "Traceback" not in err
