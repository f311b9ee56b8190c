"""Joint ranges of motion: inverse maps over the full range, the branch and wrap inside the range,
the limits inside LS and the calibration, and the frames at a limit reported."""
import dataclasses

import numpy as np
import pytest

from exubio.model.kinematics import Kinematics
from exubio.protocol.bind import tracked_points
from exubio.methods.ls import LSOptions, reconstruct_ls
from exubio.model.load import load_model, model_to_dict, save_model
from exubio.run.inputs import load_model_and_protocol
from exubio.model.ranges import limit_report, violation, wrap_into_range
from exubio.types import MarkerTargets


def _unbounded(model):
    segs = tuple(dataclasses.replace(s, joint=dataclasses.replace(s.joint, ranges_rad=None)) if s.joint else s
                 for s in model.segments)
    return dataclasses.replace(model, segments=segs)


UNBOUNDED = ("gh_abduction", "gh_flexion")
"""The glenohumeral sequence's first and last angles: no range a physiological posture respects (the
model file's note [13]: bone pins put them at -117 and -83 deg in an abduction)."""


def test_every_coordinate_has_a_cited_range_but_the_two_no_range_can_bound(model):
    rng = np.degrees(model.coordinate_ranges_rad)
    bounded = np.array([n not in UNBOUNDED for n in model.coordinate_names])
    assert rng.shape == (13, 2) and np.isfinite(rng[bounded]).all() and not np.isfinite(rng[~bounded]).any()
    assert (rng[:, 0] < 0).all() and (rng[:, 1] > 0).all()
    text = (load_model().source and open(load_model().source, encoding="utf-8").read())
    assert text.count("range_deg: [-") == 11 and "Greene WB, Heckman JD" in text and "Ludewig PM" in text
    assert text.count("no range: see [13]") == 2 and "#  [13]" in text


def test_calibrated_and_saved_models_keep_the_ranges(tmp_path, model):
    path = save_model(model, tmp_path / "m.yaml", calibration=None)
    assert np.array_equal(load_model(path).coordinate_ranges_rad, model.coordinate_ranges_rad)
    assert "range_deg" in model_to_dict(model)["segments"][1]["joint"]["coordinates"][0]


def test_round_trip_of_random_rotations_over_the_full_range():
    """Any rotation, including |q2| > 90 deg for the cardan wrist (the old inverse map returned
    q1 + 180 there): with the previous frame known, the exact angles come back; without it, the
    same rotations and angles inside the ranges."""
    model = load_model()
    kin_u = Kinematics(_unbounded(model))
    rng = np.random.default_rng(1)
    q = rng.uniform(-np.pi, np.pi, size=(3000, 13))
    R = kin_u.frames(q).R
    assert np.abs(kin_u.coordinates_from_rotations(R, q_previous=q) - q).max() < 1e-9
    back = kin_u.coordinates_from_rotations(R)
    assert np.abs(kin_u.frames(back).R - R).max() < 1e-9
    # within the model's ranges
    kin = Kinematics(model)
    lim = model.coordinate_ranges_rad
    q = rng.uniform(*np.clip(lim.T, -np.pi, np.pi), size=(3000, 13))
    back = kin.coordinates_from_rotations(kin.frames(q).R)
    assert np.abs(kin.frames(back).R - kin.frames(q).R).max() < 1e-9
    assert np.abs(violation(back, lim)).max() == 0.0  # inside the range whenever one triple is
    wrist = list(model.coordinate_names).index("wrist_flexion")
    q = np.zeros((1, 13))
    q[0, wrist] = np.radians(93.0)  # cardan middle angle beyond 90 deg
    q[0, wrist + 1] = np.radians(-30.0)
    assert np.abs(kin.coordinates_from_rotations(kin.frames(q).R) - q).max() < 1e-9


def test_angles_wrap_into_their_range_never_minus_341(model):
    lim = model.coordinate_ranges_rad
    j = model.coordinate_names.index("pronation")
    q = np.zeros(13)
    q[j] = np.radians(-341.0)
    assert np.degrees(wrap_into_range(q, lim)[j]) == pytest.approx(19.0)


def _exact_targets(model, protocol, q):
    kin = Kinematics(model)
    pos = kin.points(q, tracked_points(kin, protocol))
    return MarkerTargets(np.arange(len(q)) * 0.02, protocol.marker_names, pos, np.zeros_like(pos), np.zeros_like(pos))


def test_ls_keeps_a_coordinate_driven_beyond_its_range_at_the_limit_potentials_equilibrium():
    """Markers of an elbow flexed 10 deg beyond its range: LS stops where the markers' pull
    balances the limit potential (a fraction of a degree beyond), the other coordinates untouched;
    without limits it follows the markers. The frames are reported."""
    model, protocol = load_model_and_protocol()
    protocol = dataclasses.replace(protocol, held_coordinates=())
    names = model.coordinate_names
    e = names.index("elbow_flexion")
    hi = model.coordinate_ranges_rad[e, 1]
    q = np.zeros((5, 13))
    q[:, names.index("gh_flexion")] = np.radians(30)
    q[:, e] = hi + np.radians(10.0)
    targets = _exact_targets(model, protocol, q)
    free = reconstruct_ls(model, protocol, targets, options=LSOptions(limit_stiffness_nm_per_rad=None))
    assert np.abs(np.angle(np.exp(1j * (free.q_rad - q)))).max() < 1e-6  # the same posture (mod 2 pi)
    lim = reconstruct_ls(model, protocol, targets)
    beyond = np.degrees(lim.q_rad[:, e] - hi)
    assert (beyond > 0.01).all() and (beyond < 1.0).all(), beyond  # 0.08 deg with k_lim = 1e4 N m/rad
    # the limit torque balances the markers: kappa v = -(J^T W e)_elbow at the optimum
    kin = Kinematics(model)
    pts = tracked_points(kin, protocol)
    J = kin.point_jacobian(lim.q_rad[:1], pts)[0]
    err = kin.points(lim.q_rad[:1], pts)[0] - targets.positions_m[0]
    grad = np.einsum("kcm,kc,k->m", J, err, protocol.weights)
    from exubio.model.ranges import DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD, penalty_weight

    kappa = penalty_weight(DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD, protocol.default_stiffness_n_per_m)
    assert grad[e] == pytest.approx(-kappa * (lim.q_rad[0, e] - hi), rel=1e-3)
    rep = limit_report(lim.q_rad, model.coordinate_ranges_rad, names)
    assert [r.coordinate for r in rep] == ["elbow_flexion"] and rep[0].frames_at_limit == 5
