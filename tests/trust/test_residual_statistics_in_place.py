"""residual_statistics squares its own copy of the residuals in place (issue 38's memory bound: no
second whole-trial copy): every figure equals the one numpy's expressions give on the residuals,
bit for bit, with gaps and a marker absent throughout."""
from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np

from exubio.trust.evaluate import residual_statistics


def test_the_statistics_are_numpys_on_the_residuals_and_leave_them_alone():
    rng = np.random.default_rng(5)
    res_m = np.abs(rng.normal(0.0, 0.002, (700, 6)))
    res_m[100:180, 2] = np.nan
    res_m[:, 4] = np.nan  # an optional marker absent throughout
    kept = res_m.copy()
    recon = SimpleNamespace(residuals_m=res_m, marker_names=tuple("abcdef"), time_s=np.arange(700) / 100.0)
    got = residual_statistics(recon)
    assert np.array_equal(res_m, kept, equal_nan=True)  # the reconstruction's residuals untouched
    r = kept * 1000.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        rmse = np.sqrt(np.nanmean(r**2, axis=0))
        frame_mean, frame_sd = np.nanmean(r, axis=1), np.nanstd(r, axis=1)
        peak = np.nanmax(r, axis=0)
    j = int(np.nanargmax(frame_mean))
    assert got["mean"] == float(np.nanmean(r)) and got["sd"] == float(np.nanstd(r))
    assert got["max"] == float(np.nanmax(r)) and got["max_marker"] == "abcdef"[int(np.nanargmax(peak))]
    assert got["max_frame_mean"] == float(frame_mean[j]) and got["max_frame_mean_sd"] == float(frame_sd[j])
    assert got["max_frame_mean_time_s"] == j / 100.0
    assert got["per_marker_rmse"] == {n: (None if np.isnan(v) else float(v)) for n, v in zip("abcdef", rmse)}
    assert got["per_marker_rmse"]["e"] is None and got["max_marker_rmse_marker"] == "abcdef"[int(np.nanargmax(rmse))]


def test_no_residual_at_all_gives_no_figures():
    recon = SimpleNamespace(residuals_m=np.full((5, 2), np.nan), marker_names=("a", "b"), time_s=np.arange(5.0))
    assert residual_statistics(recon) == {"mean": None, "sd": None, "max": None, "max_marker": None}
