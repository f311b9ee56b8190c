"""The API's types print short in a notebook: arrays as their dtype and shape, long sequences
counted, every field named; a Reconstruction of 2000 frames prints in one short line."""
from __future__ import annotations

import numpy as np

import exubio
from exubio.types import Reconstruction


def _reconstruction(n: int = 2000, m: int = 12, k: int = 21) -> Reconstruction:
    rng = np.random.default_rng(0)
    return Reconstruction(method="pf", time_s=np.arange(n) / 100.0, coordinate_names=tuple(f"q{i}" for i in range(m)),
                          q_rad=rng.normal(size=(n, m)), qd_rad_s=np.zeros((n, m)), qdd_rad_s2=np.zeros((n, m)),
                          marker_names=tuple(f"M{i}" for i in range(k)), model_points_m=np.zeros((n, k, 3)),
                          measured_m=None, residuals_m=np.zeros((n, k)), constraint=np.zeros((n, 2)),
                          constraint_velocity=np.zeros((n, 2)), status=np.zeros(n, dtype=int))


def test_a_reconstruction_prints_its_shapes_not_its_arrays():
    r = _reconstruction()
    text = repr(r)
    assert len(text) < 800, len(text)
    assert "q_rad=<float64 array 2000x12>" in text and "model_points_m=<float64 array 2000x21x3>" in text
    assert "coordinate_names=<12 items: 'q0', 'q1', 'q2', ...>" in text
    assert "measured_m=None" in text and text.startswith("Reconstruction(method='pf'")
    assert str(r) == text and f"{r.q_rad[0, 0]:.4f}"[:6] not in text  # no number of an array


def test_the_loaded_types_print_short():
    model = exubio.load_model()
    protocol = exubio.load_protocol(model=model)
    trial = exubio.simulate("abduction", model, duration_s=3.0, rate_hz=50.0).trajectories
    for obj, name in ((model, "Model"), (protocol, "Protocol"), (trial, "Trajectories")):
        text = repr(obj)
        assert text.startswith(f"{name}(") and len(text) < 900, (name, len(text))
        assert "array([" not in text and "\n" not in text
    assert "positions_m=<float64 array 150x" in repr(trial)
    assert "segments=<" in repr(model) and "thorax" in repr(model)
