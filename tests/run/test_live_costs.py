"""What the live loop does to keep its frames short (issue 38): the recording grows in blocks without
copying, the mean residual of a frame is numpy's without its copy (the collector's freeze is tested
in tests/run/test_live.py, with Exudyn; the one-frame noise gains in tests/trust/test_frame_determinacy.py)."""
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


def test_staged_rows_are_written_whole_with_gaps_and_at_the_end():
    """FrameRecord writes a frame's inputs and published outputs a block of frames at a time: the arrays it
    hands over are every frame's as given, frames never given hold the fill, a part-filled block is written
    at the end (STAGED_FRAMES frames and more, one frame skipped)."""
    from types import SimpleNamespace

    from exubio.run.live.outputs import STAGED_FRAMES, FrameRecord

    rng = np.random.default_rng(5)
    L, k, m, n = 4, 3, 2, 3 * STAGED_FRAMES + 5
    rec = FrameRecord(L, k, m)
    frames = [g for g in range(n) if g != 20]  # frame 20 never given
    want = {}
    for g in frames:
        raw, p, v, a = rng.normal(size=(L, 3)), rng.normal(size=(k, 3)), rng.normal(size=(k, 3)), rng.normal(size=(k, 3))
        sample = None if g % 7 == 0 else SimpleNamespace(timestamp=g * 0.01, received=g * 0.01 + 1e-4)
        isb, rate, meas = rng.normal(size=15), rng.normal(size=15), rng.random(15) > 0.5
        rec.input(g, raw, sample, SimpleNamespace(positions_m=p, velocities_m_s=v, accelerations_m_s2=a))
        rec.published(g, g * 0.01 + 2e-4, sample, isb, rate, meas)
        want[g] = (raw, np.nan if sample is None else sample.timestamp, p, v, a, isb, rate, meas)
    got = rec.arrays(n)
    for g, (raw, ts, p, v, a, isb, rate, meas) in want.items():
        assert np.array_equal(got["raw_m"][g], raw) and np.array_equal(got["positions_m"][g], p)
        assert np.array_equal(got["velocities_m_s"][g], v) and np.array_equal(got["accelerations_m_s2"][g], a)
        assert np.array_equal(got["timestamps_s"][g], ts, equal_nan=True) and got["published_s"][g] == g * 0.01 + 2e-4
        assert np.array_equal(got["isb_rad"][g], isb) and np.array_equal(got["isb_rate_rad_s"][g], rate)
        assert np.array_equal(got["measured"][g], meas)
    assert np.isnan(got["raw_m"][20]).all() and np.isnan(got["published_s"][20]) and not got["measured"][20].any()
    assert (got["velocities_m_s"][20] == 0).all()  # the fill of a frame never given
    assert len(rec.latency) == sum(1 for g in frames if g % 7) and np.allclose(rec.latency, 1e-4)
