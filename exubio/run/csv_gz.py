"""A study's long table as gzip-compressed CSV (``angles.csv.gz``): the text pandas'
``to_csv(index=False, float_format="%.<d>f")`` gives, written by polars (its writer is compiled and
prints the numbers 7 times faster, the same characters: correctly rounded, NaN as an empty field,
``inf``; tests/run/test_study_table.py compares the two on every kind of value), streamed a block of
rows at a time into gzip by ISA-L (``isal.igzip``: standard gzip that any reader opens; on a study's
946 MB of text 0.5 s at its level 1 against 7.7 s for zlib's default level 6, the file 3.5 % larger).
No file name and mtime 0 in the gzip header, so the same rows give the same bytes (a study run
twice, or resumed)."""
from __future__ import annotations

from typing import TYPE_CHECKING

from isal import igzip

if TYPE_CHECKING:
    import pandas

__all__ = ["write_csv_gz", "csv_text", "gzip_writer"]

BLOCK_ROWS = 1 << 20  # rows formatted at a time: the text of one block in memory, not the table's
LEVEL = 1  # ISA-L's levels are 0-3; 1 is its fastest that still compresses well (3 is 4x slower for 2.5 % less)


def csv_text(df: "pandas.DataFrame", decimals: int, /, *, header: bool = True) -> str:
    """The CSV text of ``df`` (its float columns with ``decimals`` decimals, NaN empty)."""
    import pandas as pd
    import polars as pl

    frame = pl.from_pandas(df)
    floats = [c for c, t in frame.schema.items() if t.is_float()]
    # pandas prints NaN and the empty string as an empty field; polars quotes the empty string ("")
    empty = [c for c in df.columns if isinstance(df[c].dtype, pd.CategoricalDtype) and "" in df[c].cat.categories
             or df[c].dtype == object]
    frame = frame.with_columns([pl.col(c).fill_nan(None) for c in floats]
                               + [pl.col(c).cast(pl.String).replace("", None) for c in empty])
    return frame.write_csv(include_header=header, float_precision=decimals, float_scientific=False)


def gzip_writer(raw):
    """A binary gzip stream into the open file ``raw``: no file name, mtime 0 (the same text gives
    the same bytes)."""
    return igzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0, compresslevel=LEVEL)


def write_csv_gz(path, df: "pandas.DataFrame", decimals: int, /) -> None:
    """``df`` as CSV (csv_text) gzip-compressed into ``path``."""
    with open(path, "wb") as raw, gzip_writer(raw) as gz:
        for start in range(0, max(len(df), 1), BLOCK_ROWS):
            gz.write(csv_text(df.iloc[start:start + BLOCK_ROWS], decimals, header=start == 0).encode("utf-8"))
