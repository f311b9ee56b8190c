"""The study table's CSV (exubio.run.csv_gz) is the text pandas writes with ``float_format="%.6f"``
(the reference: an independent writer), on every kind of value a table holds; the table built from
codes (exubio.run.study_table.study_table) is the frame pandas makes from the rows' strings."""
from __future__ import annotations

import gzip

import numpy as np
import pandas as pd
import pytest

from exubio.run import study_table
from exubio.run.csv_gz import csv_text, write_csv_gz

EDGE = [0.0078125, -0.0078125, 0.0234375, 3 / 128, -1e-9, -0.0, 0.0, 5e-7, 1.5e-6, 2.5e-6, 123456789.123456789,
        1e20, -1e20, np.inf, -np.inf, np.nan, 0.1234565, 7.0000005, 179.99999949999, -180.0]


def _frame(n: int, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    x = np.concatenate([EDGE, rng.normal(0, 90, n), rng.uniform(-1e-6, 1e-6, n)])
    y = x[::-1].copy()
    names = np.array(["a", "b,c", 'q"uote', "ü", ""], dtype=object)[rng.integers(0, 5, x.size)]
    return pd.DataFrame({"name": pd.Categorical(names), "x": x, "y": y, "status": pd.Categorical(
        names[::-1], categories=["a", "b,c", 'q"uote', "ü", "", "never"])})


@pytest.mark.parametrize("decimals", [6, 3])
def test_csv_text_is_pandas_text(decimals):
    df = _frame(20000, decimals)
    assert csv_text(df, decimals) == df.to_csv(index=False, float_format=f"%.{decimals}f")


def test_written_in_blocks_is_one_text(tmp_path, monkeypatch):
    import exubio.run.csv_gz as mod

    df = _frame(3000, 1)
    monkeypatch.setattr(mod, "BLOCK_ROWS", 777)  # several blocks, the last one short
    write_csv_gz(tmp_path / "t.csv.gz", df, 6)
    with gzip.open(tmp_path / "t.csv.gz", "rt", encoding="utf-8", newline="") as f:
        assert f.read() == df.to_csv(index=False, float_format="%.6f")
    first = (tmp_path / "t.csv.gz").read_bytes()
    write_csv_gz(tmp_path / "u.csv.gz", df, 6)
    assert (tmp_path / "u.csv.gz").read_bytes() == first  # no name nor time in the header


def test_empty_table_is_its_header(tmp_path):
    df = _frame(0, 2).iloc[:0]
    write_csv_gz(tmp_path / "e.csv.gz", df, 6)
    assert gzip.open(tmp_path / "e.csv.gz", "rt").read() == df.to_csv(index=False)


def test_categorical_from_codes_is_pandas_categorical_of_rows():
    values, sizes = ["S02", "S01", "S03", "S02", "S04"], [3, 0, 2, 4, 1]  # S01 on no row: not a category
    rows = np.repeat(np.array(values, dtype=object), sizes)
    got = study_table.categorical_runs(([v], n) for v, n in zip(values, sizes))
    pd.testing.assert_series_equal(pd.Series(got), pd.Series(pd.Categorical(rows, categories=list(dict.fromkeys(rows)))))
    fixed = ("ok", "check", "fail", "")
    got = study_table.categorical_runs([(["ok"], 2), ([""], 1), (["check"], 2)], fixed)  # "fail" on no row: still a category
    want = pd.Categorical(np.repeat(np.array(["ok", "", "check"], dtype=object), [2, 1, 2]), categories=fixed)
    pd.testing.assert_series_equal(pd.Series(got), pd.Series(want))
    got = study_table.categorical_runs([(["x", "y"], 2), (["y", "z"], 0), (["z", "x"], 1)])  # runs of several values
    want = pd.Categorical(["x", "x", "y", "y", "z", "x"], categories=["x", "y", "z"])
    pd.testing.assert_series_equal(pd.Series(got), pd.Series(want))
