"""``spline_derivatives(..., overwrite_positions=True)`` (what prepare_targets asks, issue 38's memory
bound: no whole-trial copy of the positions) gives what the copying call gives, bit for bit: the
samples of every valid run as they are, NaN everywhere else (a sample with one coordinate missing
included), and the same velocities and accelerations."""
from __future__ import annotations

import numpy as np

from exubio.prep.targets import spline_derivatives


def test_overwriting_gives_what_copying_gives():
    rng = np.random.default_rng(11)
    n = 120
    t = np.arange(n) / 100.0
    pos = np.cumsum(rng.normal(0.0, 0.001, (n, 4, 3)), axis=0)
    pos[10:14, 0] = np.nan  # a gap
    pos[30, 1, 2] = np.nan  # one coordinate missing: the whole sample is missing
    pos[50:52, 2] = np.nan
    pos[53:60, 2] = np.nan  # an isolated sample at 52
    pos[:, 3] = np.nan  # a marker never seen
    copied = spline_derivatives(t, pos.copy())
    mine = pos.copy()
    inplace = spline_derivatives(t, mine, overwrite_positions=True)
    assert np.shares_memory(inplace[0], mine)
    for a, b in zip(copied, inplace):
        assert np.array_equal(a, b, equal_nan=True)
    assert np.isnan(inplace[0][30, 1]).all() and np.isnan(inplace[0][10:14, 0]).all()
    assert inplace[0][52, 2].tolist() == pos[52, 2].tolist() and (inplace[1][52, 2] == 0).all()


def test_resampling_never_overwrites():
    t = np.arange(20) / 100.0
    pos = np.linspace(0.0, 1.0, 60).reshape(20, 1, 3)
    mine = pos.copy()
    out = spline_derivatives(t, mine, at=np.arange(0, 0.19, 0.005), overwrite_positions=True)
    assert np.array_equal(mine, pos) and not np.shares_memory(out[0], mine)
