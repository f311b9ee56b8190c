"""A protocol checked before a trial (issue 35, item 3): `exubio protocols FILE [--trial T]
[--static S]` says per angle what the set can measure (and why not), refuses (exit 2) or warns,
naming the marker and the key: metres in a _mm key, a segment left without markers, the wrong
side, a relabel key that matches nothing (with the near labels), markers declared on landmarks
where the static puts them elsewhere (with the distances). Each message here is the one
docs/troubleshooting-protocols.md quotes."""
import dataclasses
import re

import numpy as np
import pytest

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial

HEAD = "schema_version: 1\nthorax_frame: {ij: MAN, px: XYP, c7: C7, t8: T10}\n"
MARKERS = {  # the 21-marker set's markers at the shipped places (upper_limb_21)
    "CLAV_SC": "{segment: clavicle, point: CLAV_SC}", "CLAV_AC": "{segment: clavicle, point: CLAV_AC}",
    "SCAP_Cor": "{segment: scapula, point: SCAP_Cor}", "SCAP_AA": "{segment: scapula, point: SCAP_AA}",
    "SCAP_AC": "{segment: scapula, point: SCAP_AC}", "SCAP_IA": "{segment: scapula, point: SCAP_IA}",
    "ARM": "{segment: humerus, point: ARM}", "EPI_lat": "{segment: humerus, point: EPI_lat}",
    "EPI_med": "{segment: humerus, point: EPI_med}", "ULNA": "{segment: ulna, point: ULNA}",
    "RADIUS": "{segment: radius, point: RADIUS}", "MET2": "{segment: hand, point: MET2}",
    "MET5": "{segment: hand, point: MET5}",
}


def _write(tmp_path, markers=MARKERS, extra="", name="my.yaml"):
    body = HEAD + extra + "markers:\n" + "".join(f"  {k}: {v}\n" for k, v in markers.items())
    path = tmp_path / name
    path.write_text(body, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def trial():
    return simulate_trial(load_model(), "abduction", duration_s=2.0, rate_hz=50.0, seed=4).trajectories


def _run(capsys, *argv):
    code = main(["protocols", *map(str, argv)])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return code, out.out, out.err


def test_per_angle_what_the_set_measures_and_why_not(capsys):
    code, out, _ = _run(capsys, "thoracoscapular_9")
    assert code == 0
    assert re.search(r"elbow_flexion\s+not measured: no marker on ulna or below it", out)
    assert re.search(r"AC_X_upward_rotation\s+modelled: set by the protocol's hold \(sc_posterior_rotation\)", out)
    assert re.search(r"HT_X_elevation\s+measured\n", out)
    # measured but where the uncertainty (the bone-pin artefact and the girdle's error) passes the bound, and said so
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation"):
        assert re.search(name + r"\s+partly not measured: its standard uncertainty under the bone-pin soft-tissue "
                         r"artefact and the model girdle's error above 10 deg in \d+ of 24 reference postures "
                         r"\(HT \d+-\d+ deg\)", out), name


def test_metres_in_a_mm_key_are_refused(tmp_path, capsys):
    path = _write(tmp_path, {**MARKERS, "ARM": "{segment: humerus, local_position_mm: [0.012, -0.063, 0.043]}"})
    code, _, err = _run(capsys, path)
    assert code == 2
    assert "markers.ARM.local_position_mm" in err and "looks like metres" in err and "[12.0, -63.0, 43.0]" in err


def test_a_metre_landmark_offset_is_refused(tmp_path, capsys):
    path = _write(tmp_path, {**MARKERS, "CLAV_AC": "{segment: clavicle, point: CLAV_AC, landmark: AC, "
                                                   "landmark_offset_mm: 0.015}"})
    code, _, err = _run(capsys, path)
    assert code == 2 and "markers.CLAV_AC.landmark_offset_mm" in err and "looks like metres" in err


def test_a_segment_left_without_markers_is_named(tmp_path, capsys):
    markers = {k: v for k, v in MARKERS.items() if "humerus" not in v}
    code, out, _ = _run(capsys, _write(tmp_path, markers))
    assert code == 0
    assert "warning: segment 'humerus' has no marker" in out and "ulna, radius, hand below it" in out
    assert re.search(r"GH_Y_axial_rotation\s+not measured: no marker on humerus", out)


def test_the_wrong_side_is_refused_with_a_trial(tmp_path, trial, capsys):
    path = _write(tmp_path, extra="side: left\n")
    c3d = write_c3d(tmp_path / "right_arm.c3d", trial)
    code, _, err = _run(capsys, path, "--trial", c3d)
    assert code == 2
    assert "side: left" in err and "thorax's right side" in err and "set side: right" in err and "EPI_lat" in err
    code, _, _ = _run(capsys, _write(tmp_path, name="right.yaml"), "--trial", c3d)
    assert code == 0


def test_one_marker_on_the_wrong_side_is_named(tmp_path, trial, capsys):
    pos = trial.positions_m.copy()  # the lab frame: thorax Z (right) is lab -Y rotated by the lab yaw
    from exubio.synth.simulate import _lab_transform

    rot, origin = _lab_transform()
    j = trial.labels.index("MET5")
    local = (pos[:, j] - origin) @ rot  # thorax frame
    local[:, 2] = -local[:, 2]
    pos[:, j] = local @ rot.T + origin
    c3d = write_c3d(tmp_path / "one_left.c3d", dataclasses.replace(trial, positions_m=pos))
    code, out, _ = _run(capsys, _write(tmp_path), "--trial", c3d)
    assert code == 0
    assert "warning: markers.MET5: on the thorax's left side" in out


def test_a_relabel_key_that_matches_nothing_is_refused_with_the_near_labels(tmp_path, trial, capsys):
    path = _write(tmp_path, extra="relabel: {RADUIS: ULNA, ULNA: RADIUS}\n")
    c3d = write_c3d(tmp_path / "t.c3d", trial)
    code, _, err = _run(capsys, path, "--trial", c3d)
    assert code == 2
    assert "relabel.RADUIS" in err and "has no label 'RADUIS'" in err and "'RADIUS'" in err


def test_a_relabel_to_no_marker_is_named_without_a_trial(tmp_path, capsys):
    code, out, _ = _run(capsys, _write(tmp_path, extra="relabel: {RAD: RADUIS}\n"))
    assert code == 0 and "warning: relabel.RAD: reads 'RAD' as 'RADUIS', which is no marker" in out and "RADIUS" in out


def test_a_missing_marker_is_named_with_its_near_label(tmp_path, trial, capsys):
    t = dataclasses.replace(trial, labels=tuple("CAP_Cor" if lab == "SCAP_Cor" else lab for lab in trial.labels))
    code, _, err = _run(capsys, _write(tmp_path), "--trial", write_c3d(tmp_path / "t.c3d", t))
    assert code == 2 and "'CAP_Cor' for SCAP_Cor?" in err and "--relabel CAP_Cor=SCAP_Cor" in err


def test_markers_declared_on_landmarks_the_static_puts_elsewhere(tmp_path, trial, capsys):
    """The guide's case: the girdle markers declared on SC, AC and the coracoid (point = landmark),
    while the data put them 13-16 mm away (where the 21-marker set's points are)."""
    on_bone = {**MARKERS, "CLAV_SC": "{segment: clavicle, point: SC, landmark: SC}",
               "CLAV_AC": "{segment: clavicle, point: AC, landmark: AC}",
               "SCAP_Cor": "{segment: scapula, point: PC, landmark: PC}",
               "SCAP_IA": "{segment: scapula, point: SCAP_IA, landmark: AI}"}
    static = write_c3d(tmp_path / "static.c3d", trial)
    code, out, _ = _run(capsys, _write(tmp_path, on_bone), "--static", static)
    assert code == 0
    line = next(x for x in out.splitlines() if "declared on their landmark" in x)
    named = set(re.findall(r"(\w+) (\d+) mm from (\w+)", line))
    assert {"CLAV_SC", "CLAV_AC"} <= {n for n, _, _ in named} <= {"CLAV_SC", "CLAV_AC", "SCAP_Cor"}, line
    assert all(10 <= int(d) <= 25 for _, d, _ in named), line
    assert "markers.CLAV_SC.point" in line
    # declared where the markers are: nothing named
    code, out, _ = _run(capsys, _write(tmp_path, {**MARKERS, "SCAP_IA": "{segment: scapula, point: SCAP_IA, "
                                                                        "landmark: AI}"}, name="ok.yaml"),
                        "--static", static)
    assert code == 0 and "declared on their landmark" not in out


def test_the_check_needs_a_protocol(capsys, tmp_path, trial):
    code, _, err = _run(capsys, "--trial", write_c3d(tmp_path / "t.c3d", trial))
    assert code == 2 and "give the protocol" in err


def test_a_thorax_landmark_is_found_by_its_alias(tmp_path, trial, capsys):
    markers = {**MARKERS}
    body = ("schema_version: 1\nthorax_frame: {ij: IJ, px: XYP, c7: C7, t8: T10}\nmarkers:\n  IJ: {segment: thorax, "
            "aliases: [SJN, MAN]}\n" + "".join(f"  {k}: {v}\n" for k, v in markers.items()))
    path = tmp_path / "alias.yaml"
    path.write_text(body, encoding="utf-8")
    code, _, _ = _run(capsys, path, "--trial", write_c3d(tmp_path / "t.c3d", trial))
    assert code == 0
    assert np.isfinite(trial.positions_m).all()
