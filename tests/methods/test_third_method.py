"""Adding a method is one module and one line of exubio.method_registry.REGISTRY: with the stub of
tests/methods/stub_method.py registered, the CLI offers it and runs it (its failure said, exit 1), a study
file may name it and study.csv gets its columns, the study report, the trial report and the viewer
style it; nothing else was edited."""
from __future__ import annotations

import pytest
import stub_method

from exubio.cli import build_parser, main
from exubio.io.resources import shipped_file
from exubio.method_registry import REGISTRY, MethodSpec, Style, method_names, method_style

STUB = MethodSpec("stub", "a stub that raises (tests/methods/stub_method.py)", "stub_method", "StubOptions",
                  "reconstruct_stub", "stream_stub", Style("ST", "ST (a stub)", "tab:green"))


@pytest.fixture
def stub(monkeypatch):
    monkeypatch.setitem(REGISTRY, "stub", STUB)  # the one line a contributor adds


def test_without_it_the_cli_refuses_the_name(capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["reconstruct", "t.c3d", "--method", "stub", "--out", "o"])
    assert exit_.value.code == 2
    assert "invalid choice: 'stub'" in capsys.readouterr().err


def test_the_cli_offers_and_runs_it(stub, tmp_path, capsys):
    args = build_parser().parse_args(["reconstruct", "t.c3d", "--method", "stub", "--out", "o"])
    assert args.method == "stub"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["reconstruct", "--help"])
    assert "stub: a stub that raises" in " ".join(capsys.readouterr().out.split())  # wrapped by argparse
    trial = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    code = main(["-q", "reconstruct", str(trial), "--method", "stub", "--out", str(tmp_path / "out"), "--no-report"])
    assert code == 1
    assert stub_method.MESSAGE in capsys.readouterr().err
    assert not list((tmp_path / "out").glob("*.stub.*"))  # a failed method leaves no result set


def test_a_study_names_it_and_the_table_has_its_columns(stub, tmp_path):
    from exubio.run.study import load_study, study_columns

    assert method_names() == ("pf", "ls", "stub")
    assert {"stub_verdict", "stub_residual_mm"} <= set(study_columns())
    trial = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    (tmp_path / "study.yaml").write_text(f"schema_version: 1\nname: s\nmethods: [ls, stub]\nsessions:\n  - subject: a\n    trials: [{trial}]\n",
                                         encoding="utf-8")
    assert load_study(tmp_path / "study.yaml").sessions[0].methods == ("ls", "stub")


def test_the_reports_style_it(stub):
    from exubio.report.study_report import _columns, _worst

    assert "ST" in [c.head for c in _columns()] and "ST res mm" in [c.head for c in _columns()]
    assert _worst({"status": "done", "pf_verdict": "ok", "stub_verdict": "check"}) == "check"
    assert method_style("stub").colour == "tab:green" and method_style("stub").title == "ST (a stub)"


def test_the_registry_line_the_docs_show_is_one():
    """docs/architecture.md shows the one line a new method adds: it is a registry entry as written."""
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "architecture.md").read_text(encoding="utf-8")
    line = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    entry = eval("{" + line + "}", {"MethodSpec": MethodSpec, "Style": Style})  # noqa: S307 - the docs' own text
    (name, spec), = entry.items()
    assert spec.name == name and spec.module == f"exubio.methods.{name}" and spec.style.label
