"""Which coordinates the markers determine: noise gains on the generic model and the shipped
protocol, against what the marker set can see."""

import numpy as np

from exubio.model.kinematics import Kinematics
from exubio.protocol.bind import tracked_points
from exubio.trust.observability import UNDETERMINED_DEG_PER_MM, determinacy
from exubio.run.inputs import load_model_and_protocol


def _pose(names, **deg):
    q = np.zeros((1, len(names)))
    for k, v in deg.items():
        q[0, names.index(k)] = np.radians(v)
    return q


def test_two_clavicle_markers_do_not_determine_its_axial_rotation_and_the_hold_fixes_it():
    model, protocol = load_model_and_protocol()
    kin = Kinematics(model)
    pts = tracked_points(kin, protocol)
    names = model.coordinate_names
    q = _pose(names, gh_flexion=30, elbow_flexion=45)
    present = np.ones((1, len(pts.names)), dtype=bool)
    free = determinacy(kin, pts, q, present, protocol.weights)
    gain = dict(zip(names, free.gain_deg_per_mm[0]))
    assert gain["sc_posterior_rotation"] > UNDETERMINED_DEG_PER_MM
    assert free.undetermined[0, names.index("sc_posterior_rotation")]
    hold = np.array([n == "sc_posterior_rotation" for n in names])
    held = determinacy(kin, pts, q, present, protocol.weights, excluded=hold)
    gain_h = dict(zip(names, held.gain_deg_per_mm[0]))
    assert np.isnan(gain_h["sc_posterior_rotation"]) and "sc_posterior_rotation" in held.excluded
    assert max(gain_h[n] for n in names if n.startswith(("sc_protraction", "sc_elevation", "ac_"))) < 0.5
    assert not held.undetermined.any()


def test_a_segment_without_markers_is_undetermined_and_a_gimbal_lock_is_named():
    model, protocol = load_model_and_protocol()
    kin = Kinematics(model)
    pts = tracked_points(kin, protocol)
    names = model.coordinate_names
    excl = np.array([n == "sc_posterior_rotation" for n in names])  # the clavicle's axial rotation held
    q = _pose(names, gh_flexion=30)
    present = np.ones((1, len(pts.names)), dtype=bool)
    present[0, [pts.names.index(m) for m in ("MET2", "MET5", "SEML")]] = False  # the hand markers fell off
    d = determinacy(kin, pts, q, present, protocol.weights, excluded=excl)
    assert np.isinf(d.gain_deg_per_mm[0, names.index("wrist_flexion")])
    assert d.undetermined[0, names.index("wrist_radial_deviation")]
    assert not d.undetermined[0, names.index("elbow_flexion")]
    # GH axial rotation at 89 deg: abduction and flexion act about one axis
    q = _pose(names, gh_abduction=40, gh_internal_rotation=89, gh_flexion=20)
    d = determinacy(kin, pts, q, np.ones((1, len(pts.names)), dtype=bool), protocol.weights, excluded=excl)
    for n in ("gh_abduction", "gh_flexion"):
        assert d.undetermined[0, names.index(n)] and d.near_gimbal_lock[0, names.index(n)]
    assert d.trial_undetermined() == []  # a gimbal lock is not the markers' fault
    assert set(d.fraction_gimbal()) == {"gh_abduction", "gh_flexion"}


def test_the_angle_jacobian_skips_the_frames_for_distal_coordinates_to_the_bit():
    """A distal coordinate (elbow, pronation, wrist) moves none of the ISB frames: its row of the
    finite-difference Jacobian is set without them, the same numbers as through the whole table."""
    from exubio.model.angles import anatomical_table, distal_only_coordinates
    from exubio.trust.observability import _angle_jacobian

    model, _ = load_model_and_protocol()
    kin = Kinematics(model)
    distal = distal_only_coordinates(model, kin)
    names = model.coordinate_names
    assert sorted(names[j] for j in distal) == sorted(["elbow_flexion", "pronation", "wrist_flexion",
                                                       "wrist_radial_deviation"])
    table = lambda qq: anatomical_table(model, qq, kinematics=kin, unwrap=False)[1]
    q = np.random.default_rng(3).uniform(-1.2, 1.2, (40, model.n_coordinates))
    got, want = _angle_jacobian(table, q, distal), _angle_jacobian(table, q)
    assert np.array_equal(got, want) and got.strides == want.strides
    cols = anatomical_table(model, q[:1], kinematics=kin)[0]
    for j, col in distal.items():  # a truth neither computes: a distal angle is its coordinate
        assert cols[col] in ("elbow_flexion", "forearm_pronation", "wrist_flexion", "wrist_radial_deviation")
        assert np.allclose(got[:, col, j], 1.0) and not got[:, :, j][:, np.arange(len(cols)) != col].any()
