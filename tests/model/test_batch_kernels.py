"""The compiled kernels of the preparation and the checks (exubio.model.batch_kernels) against their
numpy and scipy references, to the bit (np.array_equal): they are meant to do the same operations
in the same order, so that the outputs of a trial do not change by a rounding."""
import numpy as np
import pytest
from scipy.signal import butter, filtfilt, lfilter_zi

from exubio.model import batch_kernels as K


@pytest.mark.parametrize("order, cutoff_hz, series", [(2, 2.0, 66), (2, 11.75, 1), (1, 3.0, 7), (3, 5.0, 12),
                                                      (4, 30.0, 3)])
def test_filtfilt_columns_is_scipys_filtfilt_to_the_bit(order, cutoff_hz, series):
    rng = np.random.default_rng(order * 100 + series)
    x = rng.normal(scale=1e-3, size=(1700, series)).cumsum(axis=0) + rng.normal(size=series)
    b, a = butter(order, cutoff_hz, btype="low", fs=200.0)
    want = filtfilt(b, a, x, axis=0, padtype=None)
    got = np.empty_like(x)
    K.filtfilt_columns(b, a, lfilter_zi(b, a), x, got)
    assert np.array_equal(got, want)
    # in place (as exubio.prep.filtering runs it): each row is read before it is written
    y = x.copy()
    K.filtfilt_columns(b, a, lfilter_zi(b, a), y, y)
    assert np.array_equal(y, want)
    # a column's result does not depend on the columns beside it
    one = np.empty((x.shape[0], 1))
    K.filtfilt_columns(b, a, lfilter_zi(b, a), np.ascontiguousarray(x[:, -1:]), one)
    assert np.array_equal(one[:, 0], want[:, -1])


def test_filtfilt_columns_passes_a_constant_and_a_line():
    """A truth neither computes: a zero-lag low-pass keeps a constant, and a line away from the ends
    (where the start from a steady state has died out: 6 cut-off periods, 150 samples)."""
    b, a = butter(2, 4.0, btype="low", fs=100.0)
    t = np.arange(500.0)
    x = np.stack([np.full(500, 0.25), 1e-3 * t], axis=1)
    out = np.empty_like(x)
    K.filtfilt_columns(b, a, lfilter_zi(b, a), x, out)
    assert np.abs(out[:, 0] - 0.25).max() < 1e-12
    assert np.abs(out[150:-150, 1] - x[150:-150, 1]).max() < 1e-12
