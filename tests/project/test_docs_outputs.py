"""docs/outputs.md against what `exubio reconstruct` writes: the files its table lists are the files
of a run, and its tables of the angle CSV's columns, the .mot's, the .npz arrays and summary.json's
keys are those of the files written (LS on a short simulated trial, so no Exudyn). A column, array
or key added or renamed without the page fails here by name."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from exubio.cli import main

PAGE = Path(__file__).resolve().parents[2] / "docs" / "outputs.md"


def _section(text: str, start: str, end: str) -> str:
    i = text.index(start) + len(start)
    return text[i:text.index(end, i)]


def _first_cells(table: str) -> list[list[str]]:
    """The backticked names of each table row's first cell (header and rule rows left out)."""
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    return [re.findall(r"`([^`]+)`", row.split("|")[1]) for row in rows]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("outputs")
    assert main(["-q", "simulate", "--motion", "abduction", "--duration", "1", "--rate", "50", "--noise-mm", "0.5",
                 "--out", str(folder / "trial.c3d")]) == 0
    assert main(["-q", "reconstruct", str(folder / "trial.c3d"), "--method", "ls", "--out", str(folder / "results")]) == 0
    return folder / "results"


@pytest.fixture(scope="module")
def page() -> str:
    return PAGE.read_text(encoding="utf-8")


def test_the_files_table_lists_the_files_a_run_writes(run, page):
    table = _section(page, "## The files", "\n\n#")
    expected = set()
    for names in _first_cells(table):
        previous = None
        for name in names:
            if name.startswith(".") and previous is not None:  # `<trial>.report.pdf` / `.png`
                name = previous[: previous.rindex(".")] + name
            expected.add(name.replace("<trial>", "trial").replace("<method>", "ls"))
            previous = name
    assert expected == {p.name for p in run.iterdir()}


def test_the_csv_and_mot_columns_are_those_of_the_page(run, page):
    documented = [names[0] for names in _first_cells(_section(page, "<!-- csv-columns -->", "\n\n"))]
    header = next(line for line in (run / "trial.ls.csv").read_text(encoding="utf-8").splitlines()
                  if not line.startswith("#"))
    assert header.split(",") == documented
    mot = (run / "trial.ls.mot").read_text(encoding="utf-8").splitlines()
    columns = mot[mot.index("endheader") + 1].split("\t")
    thorax = [c for c in columns if c.startswith("thorax_")]  # the free thorax joint's (exubio.export.thorax)
    assert columns == ["time"] + [c.removesuffix("_deg") for c in documented[1:] if not c.endswith("_u_deg")] + thorax
    assert len(thorax) == 6 and all(f"`{c}`" in page for c in thorax)


def test_the_npz_arrays_are_those_of_the_page(run, page):
    documented = {n for names in _first_cells(_section(page, "<!-- npz-arrays -->", "\n\n")) for n in names}
    with np.load(run / "trial.ls.npz") as z:
        assert documented == set(z.files)


def test_the_summary_keys_are_those_of_the_page(run, page):
    documented = set(re.findall(r"`(\w+)`", _section(page, "<!-- summary-keys -->", "<!-- end -->")))
    summary = json.loads((run / "trial.ls.summary.json").read_text(encoding="utf-8"))
    assert documented == set(summary)
