"""A run's zero-lag filter is scipy's filtfilt of the series extended by their end fits, bit for bit
(the compiled kernel filters in place, without filtfilt's copies: issue 38's memory bound); a gap
stays a gap."""
from __future__ import annotations

import numpy as np
from scipy.signal import filtfilt

from exubio.prep import filtering
from exubio.prep.filtering import _butter, _filtfilt_run, lowpass, residual_cutoffs


def _markers(n: int = 1500, k: int = 5, seed: int = 4) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    pos = 0.1 * np.sin(2 * np.pi * rng.uniform(0.2, 1.5, (k, 3)) * t[:, None, None] + rng.uniform(0, 6, (k, 3)))
    pos += rng.normal(0.0, 0.001, pos.shape)
    pos[200:260, 1] = np.nan  # a gap: two runs of one marker
    pos[900:, 3] = np.nan
    return pos


def test_a_run_is_scipys_filtfilt_of_the_extended_series():
    seg = _markers()[:, [0, 2, 4]]  # one run each (what _filter_group hands it)
    b, a, zi = _butter(2, 6.0, 100.0)
    got = _filtfilt_run(seg, b, a, zi, rate_hz=100.0, cutoff_hz=6.0)
    n, pad = seg.shape[0], max(int(round(filtering.PAD_PERIODS * 100.0 / 6.0)), 1)
    flat = seg.reshape(n, -1)
    window = min(n, max(int(round(filtering.FIT_PERIODS * 100.0 / 6.0)), filtering._MIN_FIT_SAMPLES))
    ext = np.concatenate([filtering._polynomial_extension(flat[:window], pad),
                          flat, filtering._polynomial_extension(flat[::-1][:window], pad)[::-1]]).T
    ref = filtfilt(b, a, np.ascontiguousarray(ext), axis=1, padtype=None)[:, pad:pad + n].T.reshape(seg.shape)
    assert got.shape == seg.shape and np.array_equal(got, ref)


def test_a_gap_stays_a_gap_and_the_residual_analysis_finds_every_cut_off():
    pos = _markers()
    filtered = lowpass(pos, rate_hz=100.0, cutoff_hz=[4.0, 6.0, 6.0, 8.0, 5.0], order=2)
    cut = residual_cutoffs(pos, rate_hz=100.0)[0]
    assert np.isnan(filtered[200:260, 1]).all() and np.isfinite(filtered[:200, 1]).all()
    assert np.isfinite(cut).all()
