"""The angles' noise gains, held shares, statuses and uncertainties are computed a block of frames at
a time (exubio.trust.observability.BLOCK_FRAMES, which bounds their per-frame matrices on a long
trial: issue 38's memory bound); the values are the same whatever the block size, gaps included."""
from __future__ import annotations

import numpy as np

from exubio.protocol.bind import bind
from exubio.run.inputs import load_model_and_protocol
from exubio.trust import observability


def test_the_values_do_not_depend_on_the_block_size(monkeypatch):
    model, protocol = load_model_and_protocol()
    binding = bind(model, protocol)
    kin, points = binding.kin, binding.points
    rng = np.random.default_rng(5)
    n, k = 61, len(protocol.markers)
    q = np.cumsum(rng.normal(0.0, 0.02, (n, kin.n_coordinates)), axis=0)  # a smooth-ish wander from zero
    q[17] = np.nan  # a frame the method did not solve
    present = np.ones((n, k), dtype=bool)
    present[20:26, 3] = False  # a gap: its frames are computed with the markers they have, then floored
    residuals = np.where(present, rng.uniform(0.0, 0.004, (n, k)), np.nan)
    held, excluded = binding.held, binding.not_solved

    def run():
        ang = observability.angle_determinacy(kin, points, q, present, protocol.weights, held=held,
                                              locked=excluded & ~held, every=2, residuals_m=residuals)
        det = observability.determinacy(kin, points, q, present, protocol.weights, excluded=excluded, every=2)
        return ang, det

    ang, det = run()
    monkeypatch.setattr(observability, "BLOCK_FRAMES", 4)  # many blocks, the last one short
    ang_b, det_b = run()
    for name in ("gain_deg_per_mm", "held_share", "status", "uncertainty_rad", "near_gimbal_lock"):
        assert np.array_equal(getattr(ang, name), getattr(ang_b, name), equal_nan=True), name
    assert np.array_equal(det.gain_deg_per_mm, det_b.gain_deg_per_mm, equal_nan=True)
    assert np.isfinite(ang.uncertainty_rad[~np.isnan(q).any(axis=1)]).any()  # the uncertainties were computed
