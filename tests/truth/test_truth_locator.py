"""exubio.truth.locator: the scapula-locator reader, the calibrations and their leave-postures-out
evaluation; on synthetic scapulae with a known answer and on the shared locator file (skipped
where absent)."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from exubio.cli import main
from exubio.errors import InputError
from exubio.truth.locator import (Frame, LocatorTrial, System, apply_calibration, calibrate, calibration_trials,
                                  locator_displaced, orientation_error, parse_posture, read_locator_csv,
                                  recommended_calibration, scapula_frame, upward_rotation)
from exubio.truth.locator_eval import RECOMMENDED, evaluate

SHARED = Path(__file__).resolve().parents[3] / "shared"
LOCATOR_CSV = SHARED / "data" / "truth" / "scapula_locator" / "scapula_locator_P9-P12.csv"
HEADER = ["", "participant", "essai", "file", "system", "AA_x", "AI_x", "TS_x", "AA_y", "AI_y", "TS_y", "AA_z", "AI_z",
          "TS_z", "AA_mean", "AI_mean", "TS_mean"]


def real_file() -> Path:
    if not LOCATOR_CSV.is_file():
        pytest.skip(f"shared locator file {LOCATOR_CSV} not available")
    return LOCATOR_CSV


# ---------------------------------------------------------------------------------------------
# A synthetic left scapula: lab X forward, Y up, Z to the right; AA lateral (left = -Z), TS medial,
# AI inferior. rotate(theta) turns it about its plane normal (upward rotation).
# ---------------------------------------------------------------------------------------------
BONE = np.array([[0.0, 0.0, -0.20], [-0.01, -0.02, -0.09], [-0.02, -0.14, -0.12]])  # AA, TS, AI (m)


def rotate(points: np.ndarray, theta: float, about: np.ndarray) -> np.ndarray:
    a = about / np.linalg.norm(about)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    R = np.eye(3) + math.sin(theta) * K + (1 - math.cos(theta)) * K @ K
    return (points - points[0]) @ R.T + points[0]


def row(participant: str, file: str, system: str, pts_mm: np.ndarray) -> list[str]:
    """A file row of landmarks (3, 3) rows AA, TS, AI in mm, written as the writer transposed them."""
    aa, ts, ai = pts_mm
    cols = {"AA_x": aa[0], "AI_x": aa[1], "TS_x": aa[2], "AA_y": ai[0], "AI_y": ai[1], "TS_y": ai[2],
            "AA_z": ts[0], "AI_z": ts[1], "TS_z": ts[2]}
    means = {"AA_mean": aa.mean(), "AI_mean": ai.mean(), "TS_mean": ts.mean()}
    return ["0", participant, file[-1], file, system, *(repr(float(cols[c])) for c in HEADER[5:14]),
            *(repr(float(means[c])) for c in HEADER[14:])]


def write(path: Path, rows: list[list[str]], header: list[str] = HEADER) -> Path:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


def synthetic_trials(thetas: dict[str, float], slide_per_rad: np.ndarray) -> list[LocatorTrial]:
    """Skin triad rigid, rotating upwards by theta; the bone lies at an offset from it (in the skin's
    ISB frame) that grows linearly with theta: d(theta) = d0 + theta * slide_per_rad."""
    d0 = np.array([[0.0, 0.01, 0.0], [0.005, 0.0, 0.01], [-0.01, 0.02, 0.0]])
    normal = scapula_frame(BONE)[0][:, 0]
    out = []
    for file, th in thetas.items():
        skin = rotate(BONE, th, normal)
        R, o = scapula_frame(skin)
        bone = o + (d0 + th * slide_per_rad) @ R.T
        out.append(LocatorTrial("S1", parse_posture(file), {System.SKIN: skin, System.LOCATOR: bone,
                                                           System.CLUSTER: skin.copy()}))
    return out


def test_scapula_frame_of_a_left_scapula_points_forward_up_and_medial_and_mirrors_the_right():
    R, o = scapula_frame(BONE, side="left")
    assert np.allclose(R.T @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(o, BONE[0])
    assert R[0, 0] > 0.9 and R[1, 1] > 0.9 and R[2, 2] > 0.9  # X forward, Y up, Z to the right (medial)
    mirror = np.diag([1.0, 1.0, -1.0])
    Rr, _ = scapula_frame(BONE @ mirror, side="right")
    assert np.allclose(Rr, mirror @ R @ mirror)  # the right scapula's frame is the mirror image


def test_orientation_error_and_upward_rotation_measure_a_known_rotation():
    normal = scapula_frame(BONE)[0][:, 0]
    turned = rotate(BONE, math.radians(20), normal)
    assert math.isclose(math.degrees(float(orientation_error(BONE, turned))), 20.0, abs_tol=1e-9)
    assert math.isclose(abs(math.degrees(float(upward_rotation(turned, BONE)))), 20.0, abs_tol=1e-9)
    other_axis = rotate(BONE, math.radians(20), scapula_frame(BONE)[0][:, 2])  # about Z: no upward rotation
    assert abs(float(upward_rotation(other_axis, BONE))) < 1e-9


def test_single_calibration_is_exact_on_its_posture_and_where_the_offset_does_not_change():
    trials = synthetic_trials({"flex_45_1": 0.0, "flex_90_1": 0.3, "flex_120_1": 0.6}, np.zeros((3, 3)))
    for frame in Frame:
        cal = calibrate(trials[:1], frame=frame)
        for t in trials:  # a rigid offset: one calibration carries it everywhere
            assert np.allclose(apply_calibration(cal, t.positions_m[System.SKIN]), t.positions_m[System.LOCATOR],
                               atol=1e-12)


def test_double_calibration_recovers_an_offset_that_slides_with_upward_rotation_where_single_does_not():
    slide = np.array([[0.0, 0.02, 0.0], [0.0, 0.0, 0.03], [0.04, -0.02, 0.0]])  # m per rad
    trials = synthetic_trials({"flex_45_1": 0.0, "flex_90_1": -0.25, "flex_120_1": -0.5, "flex_max_1": -0.7},
                              slide)
    single = calibrate(trials[:1])
    double = calibrate([trials[0], trials[2]])
    assert double.kind == "double" and single.kind == "single"
    mid = trials[1]
    err_double = np.linalg.norm(apply_calibration(double, mid.positions_m[System.SKIN]) - mid.positions_m[System.LOCATOR],
                                axis=1)
    err_single = np.linalg.norm(apply_calibration(single, mid.positions_m[System.SKIN]) - mid.positions_m[System.LOCATOR],
                                axis=1)
    assert err_double.max() < 1e-12
    assert np.allclose(err_single, np.linalg.norm(0.25 * slide, axis=1))  # the slide it cannot know
    beyond = trials[3]  # outside the calibrated range the correction is held at its last node
    est = apply_calibration(double, beyond.positions_m[System.SKIN])
    R, o = scapula_frame(beyond.positions_m[System.SKIN])
    held = o + double.offsets_m[double.postures.index("flex_120_1")] @ R.T
    assert np.allclose(est, held, atol=1e-12)


def test_apply_calibration_leaves_a_posture_with_a_missing_landmark_missing():
    trials = synthetic_trials({"flex_45_1": 0.0}, np.zeros((3, 3)))
    skin = trials[0].positions_m[System.SKIN].copy()
    skin[0] = np.nan
    out = apply_calibration(calibrate(trials), np.stack([trials[0].positions_m[System.SKIN], skin]))
    assert np.isfinite(out[0]).all() and np.isnan(out[1]).all()


def test_calibrate_refuses_a_posture_without_its_landmarks():
    trials = synthetic_trials({"flex_45_1": 0.0}, np.zeros((3, 3)))
    bad = LocatorTrial("S1", trials[0].posture, {**trials[0].positions_m,
                                                  System.SKIN: np.full((3, 3), np.nan)})
    with pytest.raises(InputError, match=r"S1, file flex_45_1: no skin AA, TS, AI"):
        calibrate([bad])


# ---------------------------------------------------------------------------------------------
# The reader
# ---------------------------------------------------------------------------------------------
def test_reader_reads_the_transposed_columns_and_checks_them_against_the_means(tmp_path):
    pts = np.array([[100.0, 200.0, 1300.0], [110.0, 190.0, 1200.0], [90.0, 320.0, 1150.0]])
    path = write(tmp_path / "loc.csv", [row("P1", "abd_90_1", s, pts + k) for k, s in enumerate(("locator", "skin",
                                                                                                  "cluster"))])
    data = read_locator_csv(path)
    (trial,) = data.trials
    assert trial.posture.name == "abd_90" and trial.posture.repeat == 1
    assert np.allclose(trial.positions_m[System.LOCATOR], pts / 1000)
    assert np.allclose(trial.positions_m[System.CLUSTER], (pts + 2) / 1000)
    lines = (tmp_path / "loc.csv").read_text().splitlines()
    lines[1] = lines[1].replace(repr(float(pts[0].mean())), repr(float(pts[0].mean() + 1.0)))
    (tmp_path / "bad.csv").write_text("\n".join(lines))
    with pytest.raises(InputError, match=r"bad.csv: line 2, column 'AA_mean'.*not transposed"):
        read_locator_csv(tmp_path / "bad.csv")


@pytest.mark.parametrize("change, message", [
    (lambda h, r: (h[:5] + h[6:], [x[:5] + x[6:] for x in r]), r"no column 'AA_x'"),
    (lambda h, r: (h, [r[0][:6] + ["abc"] + r[0][7:]] + r[1:]), r"line 2, column 'AI_x': 'abc' is not a number"),
    (lambda h, r: (h, [r[0][:4] + ["bone"] + r[0][5:]] + r[1:]), r"line 2, column 'system': 'bone'"),
    (lambda h, r: (h, [r[0][:3] + ["abd_ninety_1"] + r[0][4:]] + r[1:]), r"line 2, column 'file'"),
    (lambda h, r: (h, r + [r[0]]), r"line 5: participant P1, file abd_90_1, system locator is given twice"),
])
def test_reader_says_which_file_line_and_column_is_wrong(tmp_path, change, message):
    pts = np.array([[100.0, 200.0, 1300.0], [110.0, 190.0, 1200.0], [90.0, 320.0, 1150.0]])
    rows = [row("P1", "abd_90_1", s, pts) for s in ("locator", "skin", "cluster")]
    header, rows = change(list(HEADER), rows)
    path = write(tmp_path / "loc.csv", rows, header)
    with pytest.raises(InputError, match=message) as info:
        read_locator_csv(path)
    assert "loc.csv" in str(info.value)


def test_reader_on_the_shared_file_transposition_and_missing_landmarks():
    path = real_file()
    with path.open(newline="") as f:
        raw = list(csv.DictReader(f))
    data = read_locator_csv(path)
    assert len(raw) == 189 and len(data.trials) == 63 and data.participants == ("P9", "P10", "P11", "P12")
    by_key = {(t.participant, t.posture.file): t for t in data.trials}
    for r in raw:  # AA = (AA_x, AI_x, TS_x), as SOURCES.md says, and AA_mean is their mean
        aa = [float(r[c]) if r[c] else math.nan for c in ("AA_x", "AI_x", "TS_x")]
        got = by_key[(r["participant"], r["file"])].positions_m[System(r["system"])][0] * 1000
        if all(math.isfinite(v) for v in aa):
            assert math.isclose(sum(aa) / 3, float(r["AA_mean"]), abs_tol=1e-9)
            assert np.allclose(got, aa, rtol=0, atol=1e-9)
        else:
            assert np.isnan(got).all()
    # read transposed, every triad is a scapula: its sides 8-22 cm; read as written (AA = AA_x, AA_y,
    # AA_z), from 4 cm to 1.9 m
    as_written = []
    for t in data.trials:
        for pts in t.positions_m.values():
            if np.isfinite(pts).all():
                sides = np.linalg.norm(pts - np.roll(pts, 1, axis=0), axis=1)
                assert (sides > 0.07).all() and (sides < 0.25).all(), (t.participant, t.posture.file, sides)
                wrong = pts[[0, 2, 1]].T  # rows: (AA_x, AA_y, AA_z), (AI_x, ...), (TS_x, ...)
                as_written.append(np.linalg.norm(wrong - np.roll(wrong, 1, axis=0), axis=1))
    assert np.max(as_written) > 1.0 and np.min(as_written) < 0.05
    missing = [(t.participant, t.posture.file) for t in data.trials if not np.isfinite(t.positions_m[System.SKIN]).all()]
    assert missing == [("P9", "flex_max_1"), ("P11", "flex_120_2")]


# ---------------------------------------------------------------------------------------------
# The calibrations on the shared file
# ---------------------------------------------------------------------------------------------
def test_only_the_displaced_locator_trial_is_left_out():
    data = read_locator_csv(real_file())
    assert [(t.participant, t.posture.file) for t in data.trials if locator_displaced(t)] == [("P11", "flex_90_avant_1")]


def test_each_calibration_is_exact_on_its_own_calibration_trials():
    data = read_locator_csv(real_file())
    for participant in data.participants:
        for elevations in (("45",), ("45", "120"), ("all",)):
            for tracked in (System.SKIN, System.CLUSTER):
                chosen, absent = calibration_trials(data.of(participant), plane="flex", elevations=elevations,
                                                    tracked=tracked)
                assert not absent and chosen
                for frame in Frame:
                    cal = calibrate(chosen, tracked=tracked, frame=frame)
                    est = apply_calibration(cal, np.stack([t.positions_m[tracked] for t in chosen]))
                    truth = np.stack([t.positions_m[System.LOCATOR] for t in chosen])
                    assert np.abs(est - truth).max() < 1e-9, (participant, elevations, tracked, frame)


def _median_mean_distance(ev, participant: str, method: str) -> float:
    d = np.array([r.distance_m for r in ev.results if r.participant == participant and r.method == method and r.common])
    assert len(d) >= 4
    return float(np.nanmedian(np.nanmean(d, axis=1)))


def test_on_held_out_postures_the_double_calibration_beats_single_and_no_calibration():
    """Measured on P9-P12, calibrated on the flexion statics, judged on the postures no calibration
    used (abduction, flexion 90 forward/back): the skin slides over the scapula as it rotates upward,
    so an offset calibrated at 45 deg alone leaves the slide at higher elevations; the second posture
    (120 deg) gives its linear part. Per participant the median over those postures of the mean
    AA/TS/AI distance is 8.0-13.5 mm (double) against 9.7-21.5 (single) and 25-35 (none); P11's skin
    slides least, where the two are closest."""
    ev = evaluate(read_locator_csv(real_file()), plane="flex")
    for p in ("P9", "P10", "P11", "P12"):
        none = _median_mean_distance(ev, p, "skin")
        single = _median_mean_distance(ev, p, "skin single 45")
        double = _median_mean_distance(ev, p, RECOMMENDED.name)
        assert double <= single < none, (p, double, single, none)
        ori = {m: np.nanmedian([r.orientation_rad for r in ev.results if r.participant == p and r.method == m
                                and r.common]) for m in ("skin", RECOMMENDED.name)}
        assert ori[RECOMMENDED.name] < 0.6 * ori["skin"], (p, ori)


def test_recommended_calibration_is_the_double_flexion_calibration_and_names_what_is_missing():
    data = read_locator_csv(real_file())
    cal = recommended_calibration(data.of("P10"))
    assert cal.postures == ("flex_45_1", "flex_120_1") or cal.postures == ("flex_120_1", "flex_45_1")
    assert cal.tracked is System.SKIN and cal.kind == "double"
    without = [t for t in data.of("P10") if t.posture.name != "flex_120"]
    with pytest.raises(InputError, match=r"participant P10 has no static flex_120"):
        recommended_calibration(without)


# ---------------------------------------------------------------------------------------------
# exubio locator
# ---------------------------------------------------------------------------------------------
def test_cli_prints_the_table_and_writes_json(tmp_path, capsys):
    out = tmp_path / "loc.json"
    assert main(["locator", str(real_file()), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"| all | {RECOMMENDED.name} (recommended) | common held-out | 35 |" in text
    assert "P11 flex_90_avant_1: left out" in text
    doc = json.loads(out.read_text())
    assert doc["recommended"] == RECOMMENDED.name and doc["landmarks"] == ["AA", "TS", "AI"]
    rec = [r for r in doc["held_out"] if r["calibration"] == RECOMMENDED.name]
    assert rec and all(len(r["distance_mm"]) == 3 for r in rec)
    assert not any(r["file"] in ("flex_45_1", "flex_45_2", "flex_120_1", "flex_120_2") for r in rec)


def test_cli_bad_file_is_exit_2_naming_the_column(tmp_path, capsys):
    path = write(tmp_path / "loc.csv", [["0", "P1", "1", "abd_90_1", "locator"]], HEADER[:5])
    assert main(["locator", str(path)]) == 2
    err = capsys.readouterr().err
    assert "loc.csv: no column 'AA_x'" in err and "Traceback" not in err


def test_cli_help_shows_an_example_and_the_exit_codes(capsys):
    with pytest.raises(SystemExit) as info:
        main(["locator", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "exubio locator" in out and "exit codes" in out and "2 bad input" in out
