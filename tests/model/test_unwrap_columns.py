"""The anatomical angles are unwrapped a column at a time (issue 38's memory bound: np.unwrap of the
whole (frames, 22) table made ~6 temporaries of its size): the table is, bit for bit, numpy's
unwrap of the whole table along the frames."""
from __future__ import annotations

import numpy as np

from exubio.model.angles import anatomical_table


def test_column_unwrap_is_the_whole_table_unwrap(model):
    rng = np.random.default_rng(7)
    q = np.cumsum(rng.normal(0.0, 0.4, (400, model.n_coordinates)), axis=0)  # large steps: many 2 pi wraps
    names, raw = anatomical_table(model, q, unwrap=False)
    _, table = anatomical_table(model, q)
    assert np.array_equal(table, np.unwrap(raw, axis=0), equal_nan=True)
    assert not np.array_equal(table, raw, equal_nan=True)  # there were wraps to remove
