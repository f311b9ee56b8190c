"""The tests are laid out like the package (tests/<layer>/test_*.py), and a test file that finds the
repository or ../shared by counting parent folders counts right: a wrong count does not fail, it
makes the real-data tests skip as if the data were absent (it happened when the files moved)."""
from __future__ import annotations

import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent.parent
PARENTS = re.compile(r'Path\(__file__\)\.resolve\(\)\.parents\[(\d)\](\s*/\s*"(\w+)")?')


def test_every_test_file_sits_in_a_folder_of_its_layer():
    assert not sorted(p.name for p in TESTS.glob("test_*.py"))


def test_every_parent_count_reaches_the_repository_or_shared():
    wrong = []
    for path in sorted(TESTS.rglob("*.py")):
        depth = len(path.relative_to(TESTS.parent).parts)  # tests/trust/x.py: 3; parents[2] is the repository
        for m in PARENTS.finditer(path.read_text(encoding="utf-8")):
            n, name = int(m.group(1)), m.group(3)
            expected = depth if name == "shared" else depth - 1
            if n != expected:
                wrong.append(f"{path.relative_to(TESTS.parent)}: parents[{n}] {name or ''} (expected parents[{expected}])")
    assert not wrong, wrong
