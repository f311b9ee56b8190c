"""Each anatomical angle is measured, modelled (by a named rule) or not measured, and the labels
follow from the markers: the noise-gain criterion on the angle itself, and, for a held coordinate,
the share of the angle's variance the hold decides (exubio.trust.observability.angle_determinacy)."""
import dataclasses

import numpy as np
import pytest

from exubio.protocol.bind import bind
from exubio.model.angles import ANATOMICAL_COLUMNS, anatomical_table
from exubio.trust.assess import angle_status_of_protocol
from exubio.model.kinematics import Kinematics
from exubio.protocol.bind import tracked_points
from exubio.protocol.bind import held_mask
from exubio.trust.angle_uncertainty import U_BOUND_DEG
from exubio.trust.observability import MODELLED_SHARE, AngleStatus, angle_determinacy
from exubio.run.inputs import load_model_and_protocol, protocol_for_model
from exubio.io.resources import shipped_file
from exubio.synth.simulate import reference_postures

pytestmark = pytest.mark.exudyn

SHOULDER_MEASURED = ("SC_Y_protraction", "SC_X_elevation", "ST_Y_internal_rotation", "ST_X_upward_rotation",
                     "ST_Z_posterior_tilt", "GH_phadke_X_elevation", "GH_phadke_Z_flexion",
                     "GH_phadke_Y_internal_rotation", "HT_X_elevation", "elbow_flexion", "forearm_pronation",
                     "wrist_flexion", "wrist_radial_deviation")


@pytest.fixture(scope="module")
def setup():
    model, protocol = load_model_and_protocol()
    kin = Kinematics(model)
    return model, protocol, kin, tracked_points(kin, protocol), reference_postures(model)


def _measured_but_for_the_bound(det, name) -> bool:
    """The markers determine the angle in every frame: where it is not measured, that is the stated
    uncertainty bound (u > U_BOUND_DEG) or its sequence's gimbal lock, never the noise gain, a hold
    or a missing segment (the reference postures reach HT 120 deg, where the bone-pin artefact makes
    some shoulder angles' uncertainty exceed the bound: tests/trust/test_angle_uncertainty.py)."""
    j = det.names.index(name)
    col = det.status[:, j]
    bounded = (np.degrees(det.uncertainty_rad[:, j]) > U_BOUND_DEG) | det.near_gimbal_lock[:, j]
    return bool(((col == AngleStatus.MEASURED) | bounded).all() and det.gain_deg_per_mm[:, j].max() < 2.0
                and (col[~bounded] == AngleStatus.MEASURED).all())


def _status(model, protocol, kin, pts, q, present=None):
    held = held_mask(model, protocol)
    if present is None:
        present = np.ones((q.shape[0], len(protocol.markers)), dtype=bool)
    return angle_determinacy(kin, pts, q, present, protocol.weights, held=held,
                             locked=bind(model, protocol).locked)


def test_two_clavicle_markers_measure_its_direction_not_its_axial_rotation(setup):
    """Shipped 21-marker protocol, nothing held: SC elevation and protraction (the SC->AC direction)
    are measured, the clavicle's axial rotation is not, nor the AC rotation that trades against it;
    every scapulothoracic, glenohumeral, humerothoracic and distal angle is."""
    model, protocol, kin, pts, q = setup
    assert protocol.held_coordinates == ()
    det = _status(model, protocol, kin, pts, q)
    status = det.trial_status()
    assert list(status) == list(ANATOMICAL_COLUMNS)
    assert status["SC_Z_posterior_rotation"] == status["AC_X_upward_rotation"] == "not measured"
    for name in SHOULDER_MEASURED:
        assert _measured_but_for_the_bound(det, name), (name, status[name])
    j = det.names.index("SC_Z_posterior_rotation")
    assert det.gain_deg_per_mm[:, j].min() > 2.0  # ~2.7 deg per mm: the markers are ~15 mm off its axis
    assert det.gain_deg_per_mm[:, det.names.index("SC_X_elevation")].max() < 0.3
    assert angle_status_of_protocol(bind(model, protocol)) == status  # known before the trial: the same postures


def test_a_hold_makes_what_it_decides_modelled_and_leaves_the_scapula_measured(setup):
    model, protocol, kin, pts, q = setup
    held = dataclasses.replace(protocol, held_coordinates=("sc_posterior_rotation",))
    det = _status(model, held, kin, pts, q)
    status = det.trial_status()
    for name in ("SC_Z_posterior_rotation", "AC_X_upward_rotation", "AC_Z_posterior_tilt"):
        assert status[name] == "modelled", (name, status[name])
        assert "sc_posterior_rotation" in det.rule[name]
    for name in SHOULDER_MEASURED:
        assert _measured_but_for_the_bound(det, name), (name, status[name])
        assert det.held_share[:, det.names.index(name)].max() < 0.1 < MODELLED_SHARE


def test_a_segment_without_markers_is_not_measured(setup):
    """The hand markers fall off: the wrist angles are not measured in those frames, and nothing
    else changes."""
    model, protocol, kin, pts, q = setup
    present = np.ones((q.shape[0], len(protocol.markers)), dtype=bool)
    names = [m.name for m in protocol.markers]
    present[: q.shape[0] // 2, [names.index(m) for m in ("MET2", "MET5", "SEML")]] = False
    det = _status(model, protocol, kin, pts, q, present)
    half = q.shape[0] // 2
    for name in ("wrist_flexion", "wrist_radial_deviation"):
        col = det.status[:, det.names.index(name)]
        assert (col[:half] == AngleStatus.NOT_MEASURED).all() and (col[half:] == AngleStatus.MEASURED).all()
        assert np.isinf(det.uncertainty_rad[:half, det.names.index(name)]).all()
    assert det.trial_status()["elbow_flexion"] == "measured"


def test_gh_in_isb_sequence_is_not_measured_near_its_gimbal_lock(setup):
    """ISB's Y-X'-Y'' GH sequence is singular with the arm along the scapula's Y axis: there its
    first and third angles are not separable (infinite gain), while Phadke's sequence is measured."""
    model, protocol, kin, pts, _ = setup
    names, ref = anatomical_table(model, np.zeros(model.n_coordinates))
    det = _status(model, protocol, kin, pts, np.zeros((1, model.n_coordinates)))
    elevation = np.degrees(abs(ref[names.index("GH_X_elevation")]))
    assert elevation < 10  # hanging arm: near the lock
    assert det.gain_deg_per_mm[0, names.index("GH_Y_axial_rotation")] > det.gain_deg_per_mm[
        0, names.index("GH_phadke_Y_internal_rotation")]
    assert det.trial_status()["GH_phadke_X_elevation"] == "measured"


def test_a_protocol_without_clavicle_markers_models_its_hold():
    """The thoracoscapular set has no clavicle marker and holds the clavicle's axial rotation: that
    rotation is modelled (by its hold), the SC direction and the scapula measured."""
    model, _ = load_model_and_protocol()
    protocol = protocol_for_model(model, shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols"))
    assert "sc_posterior_rotation" in protocol.held_coordinates
    status = angle_status_of_protocol(bind(model, protocol))
    assert status["SC_Z_posterior_rotation"] == "modelled"
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "HT_X_elevation"):
        assert status[name] in ("measured", "partly not measured"), (name, status[name])
    kin = Kinematics(model)
    q = reference_postures(model)
    det = _status(model, protocol, kin, tracked_points(kin, protocol), q)
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "HT_X_elevation"):
        assert _measured_but_for_the_bound(det, name), name
