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
