"""Model YAML loading: inertia from Winter's table, ellipsoid, and clear errors."""
from pathlib import Path

import numpy as np
import pytest

from exubio.errors import ModelError
from exubio.model.load import DEFAULT_MODEL, load_model


def test_generic_model_masses_follow_winter_and_scale_with_body_mass():
    m75 = load_model()
    m60 = load_model(body_mass_kg=60.0)
    assert m75.segment("humerus").mass_kg == pytest.approx(0.028 * 75)
    assert m60.segment("hand").mass_kg == pytest.approx(0.006 * 60)
    forearm = m75.segment("ulna").mass_kg + m75.segment("radius").mass_kg
    assert forearm == pytest.approx(0.016 * 75, rel=1e-3)
    for seg in m75.segments[1:]:
        eig = np.linalg.eigvalsh(seg.inertia_kgm2)
        assert np.all(eig > 0), seg.name


def test_reference_posture_contact_points_lie_on_the_ellipsoid():
    from exubio.model.kinematics import Kinematics

    kin = Kinematics(load_model())
    assert np.abs(kin.g(np.zeros(13))).max() < 1e-6


def _write(tmp_path, text):
    p = tmp_path / "m.yaml"
    p.write_text(text, encoding="utf-8")
    return p


def test_unknown_key_is_named(tmp_path):
    text = DEFAULT_MODEL.read_text(encoding="utf-8").replace("  radii_mm:", "  radius_mm:")
    with pytest.raises(ModelError, match="radius_mm"):
        load_model(_write(tmp_path, text))


def test_unknown_joint_type_lists_valid_types(tmp_path):
    text = DEFAULT_MODEL.read_text(encoding="utf-8").replace("type: cardan", "type: hinge")
    with pytest.raises(ModelError, match="hinge.*spherical"):
        load_model(_write(tmp_path, text))


def test_missing_model_file():
    with pytest.raises(ModelError, match="not found"):
        load_model(Path("/nonexistent/model.yaml"))
