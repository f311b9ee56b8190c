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



def test_one_frame_noise_gains_are_the_trial_functions_to_round_off():
    """The compiled gains of one frame against observability._gains (the trial's numpy): finite ones to 1e-9
    relative, the same coordinates infinite (a direction no marker sees: a segment's markers all gone) and
    NaN (held coordinates, a frame that is not finite)."""
    from exubio.model import live_kernels
    from exubio.protocol.bind import bind
    from exubio.run.inputs import load_model_and_protocol
    from exubio.trust.frame_determinacy import FrameDeterminacy
    from exubio.trust.observability import _gains

    b = bind(*load_model_and_protocol())
    kin, points, excluded = b.kin, b.points, b.not_solved
    rng = np.random.default_rng(12)
    k, m = len(b.protocol.marker_names), b.model.n_coordinates
    weights = rng.uniform(0.5, 2.0, k)  # unequal weights (the protocol's are equal): W and W^2 apart
    one = FrameDeterminacy(kin, points, weights, excluded=excluded)
    hand = np.array([p.segment == "hand" for p in b.protocol.markers])
    seen_inf = 0
    for trial in range(60):
        q = rng.uniform(-1.5, 1.5, m)
        present = rng.random(k) > (0.0 if trial % 3 == 0 else 0.4)
        if trial % 5 == 0:
            present &= ~hand  # the hand's markers gone: its coordinates unseen
        if trial == 7:
            q[3] = np.nan
        want = _gains(kin, points, q[None], np.array([np.isfinite(q).all()]), present[None], weights, one.free, m)[0]
        got = np.empty(m)
        live_kernels.frame_noise_gains(q, *one.tables, present, one.free64, got)
        assert np.array_equal(np.isnan(got), np.isnan(want)) and np.array_equal(np.isinf(got), np.isinf(want))
        fin = np.isfinite(want)
        assert np.allclose(got[fin], want[fin], rtol=1e-9, atol=0.0), np.abs(got[fin] / want[fin] - 1).max()
        seen_inf += np.isinf(want).any()
    assert seen_inf  # the unseen directions were exercised
