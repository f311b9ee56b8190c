"""The live verdict's running figures, taken a batch of frames at a time (LiveMonitor.running), are those
of the frames taken one after the other, bit for bit: the residual sums and counts per marker, each
frame's mean residual, the frames at a joint's range limit (how many, the first, how far beyond), with
markers missing, a frame without any, and coordinates at and beyond their limits."""
import numpy as np
import pytest

from exubio.model.load import load_model
from exubio.protocol.bind import bind
from exubio.run.inputs import protocol_for_model
from exubio.run.live.monitor import AT_LIMIT_TOLERANCE_RAD, LiveMonitor
from exubio.run.live.options import LiveOptions

pytestmark = pytest.mark.exudyn  # the live options hold PF's


def _one_by_one(monitor, g0, q, res):
    """The figures a frame at a time, numpy's per-frame operations written out."""
    lo, hi = monitor.ranges[:, 0], monitor.ranges[:, 1]
    s, sq, n = np.zeros(res.shape[1]), np.zeros(res.shape[1]), np.zeros(res.shape[1], dtype=int)
    means, count, first, beyond = [], np.zeros(q.shape[1], int), np.zeros(q.shape[1], int), np.zeros(q.shape[1])
    for i, (qi, ri) in enumerate(zip(q, res)):
        ok = np.isfinite(ri)
        s += np.where(ok, ri, 0.0)
        sq += np.where(ok, ri * ri, 0.0)
        n += ok
        means.append(float(ri[ok].mean()) * 1e3 if ok.any() else np.nan)
        at = ((qi >= hi - AT_LIMIT_TOLERANCE_RAD) | (qi <= lo + AT_LIMIT_TOLERANCE_RAD)) & ~monitor.excluded
        for j in np.flatnonzero(at):
            first[j] = g0 + i if count[j] == 0 else first[j]
            count[j] += 1
            beyond[j] = max(beyond[j], max(qi[j] - hi[j], lo[j] - qi[j], 0.0))
    return s, sq, n, np.array(means), count, first, beyond


def test_running_figures_of_a_batch_are_those_frame_by_frame():
    model = load_model()
    binding = bind(model, protocol_for_model(model))
    k, m = len(binding.protocol.marker_names), model.n_coordinates
    monitor = LiveMonitor(binding, 200.0, LiveOptions(), np.ones(k, bool), lambda *args: None)
    rng = np.random.default_rng(8)
    n = 5000  # more frames than the means' first array holds: it grows
    res = rng.gamma(2.0, 2e-3, size=(n, k)) * 10.0 ** rng.uniform(-2, 1, size=(n, k))
    res[rng.random((n, k)) < 0.05] = np.nan
    res[100] = np.nan
    lo, hi = np.clip(monitor.ranges.T, -3.0, 3.0)
    q = rng.uniform(lo - 0.05, hi + 0.05, size=(n, m))
    q[200:210, 3] = monitor.ranges[3, 1]  # at a limit exactly
    start = 0
    for size in rng.integers(1, 17, size=n):  # batches of 1 to 16 frames, as the loop's flushes
        if start >= n:
            break
        monitor.running(start, q[start:start + size], res[start:start + size])
        start += size
    s, sq, cnt, means, count, first, beyond = _one_by_one(monitor, 0, q, res)
    assert np.array_equal(monitor.res_sum, s) and np.array_equal(monitor.res_sq, sq)
    assert np.array_equal(monitor.res_n, cnt)
    assert monitor.n_means == n and np.array_equal(monitor.frame_means[:n], means, equal_nan=True)
    assert np.array_equal(monitor.lim_count, count) and np.array_equal(monitor.lim_first, first)
    assert np.array_equal(monitor.lim_beyond, beyond) and count.sum() > 0 and (beyond > 0).any()
