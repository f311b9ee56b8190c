"""The quality verdict on trials broken on purpose: each defect is named, the verdict is 'check' or
'fail', and the exit code is 1 exactly when a verdict is 'fail' (docs/verdict.md)."""
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.synth.simulate import Motion, simulate_trial

pytestmark = pytest.mark.exudyn

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d"


@pytest.fixture(scope="module")
def trajectories():
    return simulate_trial(load_model(), Motion.ABDUCTION, duration_s=3.0, rate_hz=100.0, noise_mm=1.0, sta_mm=5.0,
                          seed=3).trajectories


def _swap(traj, a, b):
    labels = list(traj.labels)
    i, j = labels.index(a), labels.index(b)
    labels[i], labels[j] = b, a
    return dataclasses.replace(traj, labels=tuple(labels))


def _run(tmp_path, traj, name, *extra):
    path = write_c3d(tmp_path / f"{name}.c3d", traj)
    out = tmp_path / name
    code = main(["-q", "reconstruct", str(path), "--method", "both", "--out", str(out), "--no-report", *extra])
    summaries = {m: json.loads((out / f"{name}.{m}.summary.json").read_text(encoding="utf-8")) for m in ("pf", "ls")}
    return code, summaries


def _reasons(summ, code=None):
    return [r for r in summ["quality"]["reasons"] if code is None or r["code"] == code]


def test_a_clean_trial_is_ok_and_exits_0(tmp_path, trajectories):
    code, summ = _run(tmp_path, trajectories, "clean")
    assert code == 0
    for s in summ.values():
        assert s["quality"]["verdict"] == "ok", s["quality"]
        assert s["not_measured"] == []  # no coordinate held: the clavicle's axial rotation is solved
        # ... and reported as what it is: the two clavicle markers do not determine it
        assert s["anatomical_angles"]["status"]["SC_Z_posterior_rotation"] == "not measured"
        assert s["anatomical_angles"]["status"]["SC_X_elevation"] == "measured"


def test_two_markers_of_one_segment_swapped_are_named(tmp_path, trajectories):
    code, summ = _run(tmp_path, _swap(trajectories, "MET2", "MET5"), "met_swap")
    for s in summ.values():
        assert s["quality"]["verdict"] in ("check", "fail")
        labels = _reasons(s, "label")
        assert labels and any({"MET2", "MET5"} <= set(f["markers"]) for f in s["labels"]), s["labels"]
    assert code == (1 if "fail" in {s["quality"]["verdict"] for s in summ.values()} else 0)


def test_a_marker_on_another_segment_fails_when_calibrated_on_its_own_frames(tmp_path, trajectories):
    """ARM and MET2 swapped, the model calibrated on the trial's first frames: the calibration
    registers ARM on the humerus where the hand is; that is named and the trial fails."""
    code, summ = _run(tmp_path, _swap(trajectories, "ARM", "MET2"), "arm_met2", "--static-frames", "0:20")
    assert code == 1
    for s in summ.values():
        assert s["quality"]["verdict"] == "fail"
        off = _reasons(s, "calibration_off_segment")
        assert any("ARM" in r["message"] for r in off), s["quality"]


def test_a_moving_static_window_is_named(tmp_path, trajectories):
    """The first 0.5 s of an abduction are no static pose."""
    code, summ = _run(tmp_path, trajectories, "moving", "--static-frames", "0:50")
    for s in summ.values():
        assert s["quality"]["verdict"] in ("check", "fail")
        assert _reasons(s, "calibration_motion"), s["quality"]


def test_a_marker_far_from_its_landmark_is_named(tmp_path, trajectories):
    """EPI_lat stuck 60 mm off the lateral epicondyle (its protocol landmark): the calibration keeps
    the pose from the landmarks, registers EPI_lat where it is, and the verdict names it."""
    pos = trajectories.positions_m.copy()
    pos[:, list(trajectories.labels).index("EPI_lat")] += np.array([0.0, 0.06, 0.0])  # 60 mm along the lab Y
    code, summ = _run(tmp_path, dataclasses.replace(trajectories, positions_m=pos), "far", "--static-frames", "0:20")
    for s in summ.values():
        assert s["quality"]["verdict"] in ("check", "fail")
        far = _reasons(s, "calibration_landmark")
        assert [r for r in far if "EPI_lat" in r["message"]], s["quality"]
        assert not [r for r in far if "EPI_med" in r["message"] or "MET2" in r["message"]]


def test_a_subject_the_model_cannot_scale_to_is_named(tmp_path):
    """Markers so far off that a scale factor hits its bound: a subject whose upper arm and forearm
    are 1.7 times the generic ones (exubio.calibration.SCALE_BOUNDS stops at 1.4). The verdict
    names the bound; nothing is silently absorbed."""
    from exubio.calibration import SCALE_BOUNDS, scale_model

    big = scale_model(load_model(), {"humerus": 1.7, "ulna": 1.7, "radius": 1.7})
    traj = simulate_trial(big, Motion.ABDUCTION, duration_s=2.0, rate_hz=100.0, noise_mm=1.0, seed=5).trajectories
    code, summ = _run(tmp_path, traj, "giant", "--static-frames", "0:20")
    for s in summ.values():
        assert s["quality"]["verdict"] in ("check", "fail")
        scale = _reasons(s, "calibration_scale")
        assert any("humerus" in r["message"] and str(SCALE_BOUNDS) in r["message"] for r in scale), s["quality"]
    assert code == (1 if "fail" in {s["quality"]["verdict"] for s in summ.values()} else 0)


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data absent")
def test_another_subjects_static_is_named(tmp_path):
    """martin_dynamique calibrated on the first frames of another subject's trial (F0)."""
    static = SHARED / "bioptim_exo_F0_boire_05.c3d"
    trial = SHARED / "bioptim_exo_martin_dynamique.c3d"
    out = tmp_path / "other"
    code = main(["-q", "reconstruct", str(trial), "--static", str(static), "--static-frames", "0:20",
                 "--method", "ls", "--out", str(out), "--no-report"])
    s = json.loads((out / "bioptim_exo_martin_dynamique.ls.summary.json").read_text(encoding="utf-8"))
    assert s["quality"]["verdict"] in ("check", "fail")
    kinds = {f["kind"] for f in s["labels"]} | {r["code"] for r in s["quality"]["reasons"]}
    assert kinds & {"other_subject", "distance", "marker_residual", "residual"}, s["quality"]
    assert code == (1 if s["quality"]["verdict"] == "fail" else 0)


def _angles_inside_ranges(out: Path, stem: str, summ: dict) -> bool:
    from exubio.io.results import read_npz

    model = load_model(summ["calibration"]["model_file"]) if summ.get("calibration") else load_model()
    rng = model.coordinate_ranges_rad
    recon = read_npz(out / f"{stem}.{summ['method']}.npz")
    tol = np.radians(1.0)
    return bool(((recon.q_rad >= rng[:, 0] - tol) & (recon.q_rad <= rng[:, 1] + tol)).all())


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data absent")
@pytest.mark.parametrize("protocol", ["shipped", "session"])
def test_kinova_session_swap_is_named_and_the_session_protocol_fixes_it(tmp_path, protocol):
    """The issue's case: every kinova_martin trial has RADIUS and ULNA swapped. With the shipped
    protocol the swap is named and the trial fails (exit 1); with the session protocol that
    relabels them: verdict ok, PF-LS <= 2 deg on determined coordinates, residual <= 10 mm, every
    angle inside its range."""
    trial = SHARED / "bioptim_exo_kinova_martin_tete_f3_1.c3d"
    out = tmp_path / protocol
    args = ["-q", "reconstruct", str(trial), "--static", str(SHARED / "bioptim_exo_kinova_martin_statique.c3d"),
            "--method", "both", "--out", str(out), "--no-report"]
    if protocol == "session":
        args += ["--protocol", str(Path(__file__).resolve().parents[2] / "protocols" / "examples"
                                   / "kinova_martin_session.yaml")]
    code = main(args)
    stem = trial.stem
    summ = {m: json.loads((out / f"{stem}.{m}.summary.json").read_text(encoding="utf-8")) for m in ("pf", "ls")}
    if protocol == "shipped":
        assert code == 1
        for s in summ.values():
            assert s["quality"]["verdict"] == "fail"
            assert any(f["kind"] == "swap" and set(f["markers"]) == {"RADIUS", "ULNA"} for f in s["labels"])
        return
    assert code == 0
    agree = [v for v in summ["pf"]["pf_ls_agreement_deg"].values() if isinstance(v, float)]
    assert max(agree) <= 2.0
    for s in summ.values():
        assert s["quality"]["verdict"] == "ok", s["quality"]
        assert s["residual_mm"]["mean"] <= 10.0 and s["labels"] == []
        assert _angles_inside_ranges(out, stem, s)


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data absent")
@pytest.mark.parametrize("trial,calibration", [
    ("bioptim_exo_martin_dynamique.c3d", ["--static", str(SHARED / "bioptim_exo_martin_statique.c3d")]),
    ("bioptim_exo_F0_boire_05.c3d", ["--static-frames", "0:20"]),
])
def test_correctly_labelled_real_trials_agree_and_stay_in_range(tmp_path, trial, calibration):
    """PF and LS agree within 2 deg on the coordinates the markers determine, every angle inside
    its range (F0: pronation was -199 to -267 deg before), no label finding."""
    out = tmp_path / "real"
    main(["-q", "reconstruct", str(SHARED / trial), *calibration, "--method", "both", "--out", str(out),
          "--no-report"])
    stem = Path(trial).stem
    summ = {m: json.loads((out / f"{stem}.{m}.summary.json").read_text(encoding="utf-8")) for m in ("pf", "ls")}
    agree = [v for v in summ["pf"]["pf_ls_agreement_deg"].values() if isinstance(v, float)]
    assert max(agree) <= 2.0
    for s in summ.values():
        assert s["labels"] == [] and s["quality"]["verdict"] != "fail"
        assert _angles_inside_ranges(out, stem, s)
    if trial.startswith("bioptim_exo_martin_dynamique"):
        # a palm-down T-pose static (80-100 deg of internal rotation, 16-20 deg from the X-Y'-Z''
        # sequence's gimbal lock) is a posture, not a limit: 'ok' (it was 'check', gh_flexion on its old
        # lower limit, before those two GH coordinates lost their ranges: models/upper_extremity.yaml [13])
        for s in summ.values():
            assert s["quality"]["verdict"] == "ok", s["quality"]
            assert not s["limits"] and not s["calibration"].get("static_pose_at_limit_deg")


def test_gaps_are_handled_and_named(tmp_path, trajectories):
    """A 0.6 s gap of MET2 and SEML falling off for the last 40 % of the trial: both reconstructed,
    each marker named with how much is missing; nothing fails for it."""
    pos = trajectories.positions_m.copy()
    labels = list(trajectories.labels)
    pos[100:160, labels.index("MET2")] = np.nan
    pos[180:, labels.index("SEML")] = np.nan
    code, summ = _run(tmp_path, dataclasses.replace(trajectories, positions_m=pos), "gaps")
    assert code == 0
    for s in summ.values():
        gaps = {r["message"].split()[1] for r in _reasons(s, "gap")}
        assert gaps == {"MET2", "SEML"}, s["quality"]
        assert s["quality"]["verdict"] in ("ok", "check")
        assert {g["marker"] for g in s["gaps"]} == {"MET2", "SEML"}


def test_calibration_criteria_name_scale_at_bound_pose_at_limit_and_moving_window(make_report):
    from exubio.trust import quality as Q

    cal = make_report(source="static.c3d", scale_factors={"humerus": 0.7, "hand": 1.0},
                      static_pose_at_limit_deg={"pronation": -20.0}, window_motion_mm={"MET2": 9.0, "ARM": 1.0})
    reasons = Q.calibration_reasons(cal, scale_bounds=(0.7, 1.4), off_segment={"ARM": 0.2})
    codes = {r.code: r for r in reasons}
    assert "humerus" in codes["calibration_scale"].message and "hand" not in codes["calibration_scale"].message
    assert "pronation" in codes["calibration_pose"].message
    assert "MET2" in codes["calibration_motion"].message
    assert codes["calibration_off_segment"].level == "fail" and "200 mm" in codes["calibration_off_segment"].message
    q = Q.Quality.of(reasons)
    assert q.verdict == "fail" and q.reasons[0].level == "fail"
    assert Q.Quality.of([r for r in reasons if r.level != "fail"]).verdict == "check"
    assert Q.Quality.of([Q.Reason("gap", "note", "x")]).verdict == "ok"
