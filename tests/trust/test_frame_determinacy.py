"""The noise-gain flags of one live frame (exubio.trust.frame_determinacy) against the trial function
(exubio.trust.observability.determinacy) on that frame."""
from __future__ import annotations

import numpy as np


def test_one_frame_determinacy_is_the_trial_function_on_that_frame():
    """FrameDeterminacy (a live frame every 50 ms) gives determinacy's flags of that frame bit for bit,
    with markers missing and near a gimbal lock."""
    from exubio.protocol.bind import bind
    from exubio.run.inputs import load_model_and_protocol
    from exubio.trust.frame_determinacy import FrameDeterminacy
    from exubio.trust.observability import determinacy

    b = bind(*load_model_and_protocol())
    kin, points, weights, excluded = b.kin, b.points, b.protocol.weights, b.not_solved
    one = FrameDeterminacy(kin, points, weights, excluded=excluded)
    rng = np.random.default_rng(7)
    k, m = len(b.protocol.marker_names), b.model.n_coordinates
    seen_und = seen_lock = 0
    for trial in range(40):
        q = rng.uniform(-1.2, 1.2, m)
        if trial % 4 == 0:
            q[4] = np.pi / 2 - 0.05  # a spherical joint's middle angle near its lock
        present = rng.random(k) > (0.0 if trial % 3 == 0 else 0.5)  # some frames with half the markers gone
        det = determinacy(kin, points, q[None], present[None], weights, excluded=excluded)
        und, lock = one(q, present)
        assert np.array_equal(und, det.undetermined[0]) and np.array_equal(lock, det.near_gimbal_lock[0])
        seen_und += und.any()
        seen_lock += lock.any()
    assert seen_und and seen_lock  # both flags were exercised

