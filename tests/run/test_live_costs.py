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
