"""JoinedRows (PFSystem.run's lead-in before a trial's targets, without their copy) reads exactly
as the concatenation of its two arrays reads, row by row and by arrays of rows."""
from __future__ import annotations

import numpy as np
import pytest

from exubio.backend.pf_numerics import JoinedRows, finite_rows


def _parts(h: int, t: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    head, tail = rng.normal(size=(h, 4, 3)), rng.normal(size=(t, 4, 3))
    if h:
        head[0, 1, 2] = np.nan
    tail[t // 2, 3, 0] = np.nan
    return head, tail


@pytest.mark.parametrize("h", [0, 1, 20])
def test_joined_rows_read_as_their_concatenation(h):
    head, tail = _parts(h, 57)
    joined, whole = JoinedRows(head, tail), np.concatenate([head, tail])
    assert joined.shape == whole.shape and joined.ndim == whole.ndim and len(joined) == len(whole)
    for i in list(range(whole.shape[0])) + [-1, -whole.shape[0], np.int64(h)]:
        assert np.array_equal(joined[i], whole[i], equal_nan=True)
    rng = np.random.default_rng(1)
    for rows in (np.arange(whole.shape[0]), rng.integers(0, whole.shape[0], 40), np.array([h, h + 1]),
                 np.array([], dtype=int), np.array([-1, 0]), np.arange(0, whole.shape[0], 2)[:, None]):
        got = joined[rows]
        assert got.shape == whole[rows].shape and np.array_equal(got, whole[rows], equal_nan=True)
    assert np.array_equal(finite_rows(joined), np.isfinite(whole).all(axis=2))
    assert np.array_equal(finite_rows(whole), np.isfinite(whole).all(axis=2))


def test_joined_rows_refuse_what_the_concatenation_would():
    head, tail = _parts(3, 10)
    joined = JoinedRows(head, tail)
    for bad in (13, -14):
        with pytest.raises(IndexError):
            joined[bad]
    with pytest.raises(IndexError):
        joined[np.array([0, 13])]
    with pytest.raises(IndexError):
        joined[np.array([0.5])]
    with pytest.raises(ValueError, match="cannot precede"):
        JoinedRows(head[:, :2], tail)
