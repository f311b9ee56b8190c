"""What the live loop does to keep its frames short (issue 38): the recording grows in blocks without
copying, and the noise gains of one frame skip the trial's frame selection (the collector's freeze
is tested in tests/run/test_live.py, with Exudyn)."""
from __future__ import annotations


import numpy as np
import pytest

from exubio.run.live.outputs import _Growing


@pytest.mark.parametrize("shape, fill, dtype", [((4, 3), np.nan, float), ((5,), False, bool), ((), -1, int)])
def test_growing_rows_are_kept_across_blocks_and_unset_rows_hold_the_fill(shape, fill, dtype):
    rng = np.random.default_rng(3)
    n = 3 * _Growing.BLOCK_ROWS + 17
    ref = np.full((n,) + shape, fill, dtype=dtype)
    grow = _Growing(shape, fill, dtype)
    for i in sorted(rng.choice(n - 1, size=n // 2, replace=False)):  # every other row left unset (a gap)
        row = rng.normal(size=shape) > 0 if dtype is bool else rng.integers(0, 9, size=shape) if dtype is int \
            else rng.normal(size=shape)
        grow.set(int(i), row)
        ref[i] = row
        assert np.array_equal(grow.get(int(i)), ref[i])
    grow.set(5, ref[5])  # a row set again
    grow.grow_to(n)
    got = grow.view(n)
    assert got.shape == ref.shape and got.dtype == ref.dtype
    assert np.array_equal(got, ref, equal_nan=dtype is float)
    assert grow.view(0).shape == (0,) + shape


def test_a_block_is_never_copied_as_the_recording_grows():
    grow = _Growing((3,))
    grow.set(0, [1.0, 2.0, 3.0])
    first = grow.blocks[0]
    for i in range(1, 4 * _Growing.BLOCK_ROWS):
        grow.set(i, [i, i, i])
    assert grow.blocks[0] is first and first[0].tolist() == [1.0, 2.0, 3.0]


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


def test_mean_of_the_finite_residuals_is_numpys_to_the_bit():
    """mean_finite (every live frame's mean residual) = x[np.isfinite(x)].mean(), NaN when none is finite."""
    from exubio.run.live.monitor import mean_finite

    rng = np.random.default_rng(11)
    for size in (1, 7, 21, 200):
        x = rng.normal(size=size) ** 2 * 1e-3
        assert mean_finite(x) == float(x.mean())
        x[rng.random(size) < 0.3] = np.nan
        ok = np.isfinite(x)
        assert (mean_finite(x) == float(x[ok].mean())) if ok.any() else np.isnan(mean_finite(x))
    assert np.isnan(mean_finite(np.full(5, np.nan))) and np.isnan(mean_finite(np.zeros(0)))
