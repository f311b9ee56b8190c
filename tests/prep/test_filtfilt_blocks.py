"""The low-pass filter's series filtered a few at a time (FILTFILT_VALUES, issue 38's memory bound:
filtfilt's copies of a long trial stay small) give what one filtfilt call over every series gives,
bit for bit; and the residual analysis's cut-offs with them."""
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


def test_a_run_filtered_row_block_by_row_block_is_one_call_bit_for_bit(monkeypatch):
    seg = _markers()[:, [0, 2, 4]]  # one run each (what _filter_group hands it)
    b, a = _butter(2, 6.0, 100.0)
    monkeypatch.setattr(filtering, "FILTFILT_VALUES", 10**12)  # every series in one call, as before
    whole = _filtfilt_run(seg, b, a, rate_hz=100.0, cutoff_hz=6.0).copy()
    monkeypatch.setattr(filtering, "FILTFILT_VALUES", 1)  # one series per call
    one_by_one = _filtfilt_run(seg, b, a, rate_hz=100.0, cutoff_hz=6.0)
    assert one_by_one.shape == seg.shape and np.array_equal(whole, one_by_one)
    # and the one call is scipy's filtfilt of the extended series, untouched
    n, pad = seg.shape[0], max(int(round(filtering.PAD_PERIODS * 100.0 / 6.0)), 1)
    flat = seg.reshape(n, -1)
    window = min(n, max(int(round(filtering.FIT_PERIODS * 100.0 / 6.0)), filtering._MIN_FIT_SAMPLES))
    ext = np.concatenate([filtering._polynomial_extension(flat[:window], pad),
                          flat, filtering._polynomial_extension(flat[::-1][:window], pad)[::-1]]).T
    ref = filtfilt(b, a, np.ascontiguousarray(ext), axis=1, padtype=None)[:, pad:pad + n].T.reshape(seg.shape)
    assert np.array_equal(whole, ref)


def test_lowpass_and_the_residual_analysis_do_not_depend_on_the_block(monkeypatch):
    pos = _markers()
    results = []
    for values in (10**12, 7000, 1):
        monkeypatch.setattr(filtering, "FILTFILT_VALUES", values)
        results.append((lowpass(pos, rate_hz=100.0, cutoff_hz=[4.0, 6.0, 6.0, 8.0, 5.0], order=2),
                        *residual_cutoffs(pos, rate_hz=100.0)))
    for other in results[1:]:
        for x, y in zip(results[0], other):
            assert np.array_equal(x, y, equal_nan=True)
    assert np.isfinite(results[0][1]).all() and np.isnan(results[0][0][200:260, 1]).all()
