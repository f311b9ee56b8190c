"""Model perturbations (exubio.synth.perturb): the perturbed model is what was asked, the words and the
truth file's header read back to the same perturbation, bad values are refused naming the key."""
from __future__ import annotations

import numpy as np
import pytest

from exubio.cli import main
from exubio.errors import InputError
from exubio.io.results import read_angles_csv
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.synth.perturb import ModelPerturbation


@pytest.fixture(scope="module")
def model():
    return load_model()


def _reference_points(model, segment):
    """Global positions (m) of a segment's named points in the reference posture (q = 0)."""
    kin = Kinematics(model)
    names = sorted(model.segment(segment).points)
    ps = kin.point_set([(segment, n) for n in names])
    return dict(zip(names, kin.points(np.zeros(model.n_coordinates), ps)))


def test_ellipsoid_centre_and_radii_are_what_was_asked(model):
    p = ModelPerturbation(ellipsoid_centre_mm=(-10, 0, 2), ellipsoid_radii_scale=(1.08, 1.08, 1.08))
    out = p.apply(model)
    assert np.allclose(out.ellipsoid.centre_m, np.asarray(model.ellipsoid.centre_m) + [-0.010, 0.0, 0.002], atol=1e-15)
    assert np.allclose(out.ellipsoid.radii_m, np.asarray(model.ellipsoid.radii_m) * 1.08, rtol=1e-15)
    assert out.ellipsoid.contact_points == model.ellipsoid.contact_points
    assert np.all(model.ellipsoid.radii_m == load_model().ellipsoid.radii_m)  # the input model is not changed


def test_segment_length_scale_scales_the_segment_and_not_the_others(model):
    out = ModelPerturbation(segment_length_scale={"humerus": 1.1}).apply(model)
    a, b = _reference_points(model, "humerus"), _reference_points(out, "humerus")
    gh_ejc = np.linalg.norm(a["EJC"] - a["GH"])
    assert np.linalg.norm(b["EJC"] - b["GH"]) == pytest.approx(1.1 * gh_ejc, rel=1e-12)
    assert np.allclose(b["GH"], a["GH"], atol=1e-12)  # scaled about its origin, the glenohumeral centre
    ua, ub = _reference_points(model, "ulna"), _reference_points(out, "ulna")
    # the forearm is carried 10 % further down but keeps its own length
    assert np.allclose(ub["EJC"] - ua["EJC"], b["EJC"] - a["EJC"], atol=1e-12)
    assert np.linalg.norm(ub["WJC"] - ub["EJC"]) == pytest.approx(np.linalg.norm(ua["WJC"] - ua["EJC"]), rel=1e-12)


def test_joint_centre_moves_the_rotation_centre_and_keeps_the_points(model):
    d = np.array([0.0, 0.015, -0.010])
    out = ModelPerturbation(joint_centre_mm={"humerus": tuple(d * 1e3)}).apply(model)
    for seg in ("humerus", "ulna", "hand"):  # in the reference posture nothing moves
        a, b = _reference_points(model, seg), _reference_points(out, seg)
        assert all(np.allclose(a[k], b[k], atol=1e-12) for k in a)
    ka, kb = Kinematics(model), Kinematics(out)
    hi = model.segment_index("humerus")
    q0 = np.zeros(model.n_coordinates)
    assert np.allclose(kb.frames(q0).p[hi], ka.frames(q0).p[hi] + d, atol=1e-12)
    # turning the glenohumeral joint keeps every humerus point's distance to the NEW centre
    q = q0.copy()
    q[model.coordinate_names.index("gh_abduction")] = 0.8
    q[model.coordinate_names.index("gh_flexion")] = 0.3
    ps = kb.point_set([("humerus", "EJC"), ("humerus", "EPI_lat")])
    before, after = kb.points(q0, ps), kb.points(q, ps)
    centre = kb.frames(q0).p[hi]
    assert np.allclose(np.linalg.norm(after - centre, axis=1), np.linalg.norm(before - centre, axis=1), atol=1e-12)
    assert np.linalg.norm(kb.points(q, ps) - ka.points(q, ps), axis=1).min() > 1e-3  # and it is not the old centre


def test_marker_offset_moves_only_that_point(model):
    out = ModelPerturbation(marker_offset_mm={"SCAP_IA": (0, -20, 5)}).apply(model)
    a, b = _reference_points(model, "scapula"), _reference_points(out, "scapula")
    assert np.allclose(b["SCAP_IA"] - a["SCAP_IA"], [0.0, -0.020, 0.005], atol=1e-15)
    assert all(np.allclose(a[k], b[k], atol=0) for k in a if k != "SCAP_IA")


def test_words_and_header_read_back_to_the_same_perturbation():
    words = ["ellipsoid_centre_mm=-10,0,0", "ellipsoid_radii_scale=1.08", "length.humerus=1.05",
             "joint.humerus=0,0,8", "marker.SCAP_IA=0,0,10"]
    p = ModelPerturbation.parse(words)
    assert p.ellipsoid_radii_scale == (1.08, 1.08, 1.08) and p.segment_length_scale == {"humerus": 1.05}
    assert ModelPerturbation.parse(p.words()) == p
    assert ModelPerturbation.from_header(["# " + line for line in p.header_lines()]) == p
    assert ModelPerturbation().is_empty and ModelPerturbation.from_header(ModelPerturbation().header_lines()).is_empty


@pytest.mark.parametrize("word, named", [
    ("ellipsoid_radii_scale=x", "ellipsoid_radii_scale"),
    ("ellipsoid_radii_scale=0", "ellipsoid_radii_scale"),
    ("ellipsoid_centre_mm=1,2", "ellipsoid_centre_mm"),
    ("length.humerus=-1", "length.humerus"),
    ("joint.humerus=1,nan,0", "joint.humerus"),
    ("radius_mm=3", "radius_mm"),
    ("nonsense", "KEY=VALUE"),
])
def test_bad_values_are_an_input_error_naming_the_key(word, named):
    with pytest.raises(InputError, match=named.replace(".", r"\.")):
        ModelPerturbation.parse([word])


def test_unknown_segment_or_point_lists_the_valid_ones(model):
    with pytest.raises(InputError, match="its segments are"):
        ModelPerturbation(segment_length_scale={"femur": 1.1}).apply(model)
    with pytest.raises(InputError, match="no point 'NOPE'"):
        ModelPerturbation(marker_offset_mm={"NOPE": (1, 0, 0)}).apply(model)


def test_cli_simulate_writes_the_perturbation_into_the_truth_header(tmp_path, capsys):
    out = tmp_path / "p.c3d"
    assert main(["-q", "simulate", "--motion", "abduction", "--duration", "1", "--rate", "20",
                 "--perturb", "ellipsoid_centre_mm=-10,0,0", "ellipsoid_radii_scale=1.08", "--out", str(out)]) == 0
    truth = tmp_path / "p.truth.csv"
    head = [line for line in truth.read_text().splitlines() if line.startswith("#")]
    assert ModelPerturbation.from_header(head) == ModelPerturbation.parse(["ellipsoid_centre_mm=-10,0,0",
                                                                          "ellipsoid_radii_scale=1.08"])
    t, names, q = read_angles_csv(truth)  # still a truth file
    assert q.shape == (20, 13)
    assert main(["-q", "simulate", "--motion", "abduction", "--duration", "1", "--perturb", "length.femur=1.1",
                 "--out", str(tmp_path / "bad.c3d")]) == 2
    assert "femur" in capsys.readouterr().err
