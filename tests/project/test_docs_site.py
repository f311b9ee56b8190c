"""The documentation site (mkdocs.yml, docs/): built with warnings as errors by the command its
Getting started page gives, so a broken link, a missing anchor or figure, a page left out of the
nav or a docstring mkdocstrings cannot render fails the test suite (and so CI); a broken link put
in on purpose is shown to fail the build. Every fenced block of the README and the pages is one
that a test runs or checks, and the README keeps exactly the two set-up commands CI runs."""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import exubio

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PAGES = ["README.md", *sorted(f"docs/{p.name}" for p in DOCS.glob("*.md"))]
BLOCK = re.compile(r"(<!-- api-example -->\s*)?```(\w*)\n(.*?)```", re.S)

pytest.importorskip("mkdocs", reason="the docs tools come with the test extra: pip install '.[test]'")


def build_command() -> list[str]:
    """The build line of docs/getting-started.md's bash block, as written."""
    text = (DOCS / "getting-started.md").read_text(encoding="utf-8")
    line = next(line.split("  #")[0].strip() for block in re.findall(r"```bash\n(.*?)```", text, re.S)
                for line in block.splitlines() if line.startswith("python -m mkdocs build"))
    return shlex.split(line)


def _build(config_root: Path, site: Path) -> subprocess.CompletedProcess:
    argv = build_command()
    assert argv[:5] == ["python", "-m", "mkdocs", "build", "--strict"] and argv[5] == "--site-dir", argv
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, *argv[1:6], str(site)], cwd=config_root, env=env, capture_output=True,
                          text=True, timeout=300)


def test_the_docs_build_with_warnings_as_errors(tmp_path):
    done = _build(ROOT, tmp_path / "site")
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-4000:]
    assert "WARNING" not in log, log[-4000:]
    site = tmp_path / "site"
    for page in DOCS.glob("*.md"):
        built = site / ("index.html" if page.stem == "index" else f"{page.stem}/index.html")
        assert built.is_file(), page
    assert (site / "benchmarks" / "index.html").is_file()  # benchmarks/README.md, shown by docs/hooks.py
    assert (site / "measurements" / "index.html").is_file()  # studies/README.md
    assert sorted(p.name for p in (site / "figures").glob("*.png")) == sorted(
        p.name for folder in ("reports/validation", "reports/screenshots") for p in (ROOT / folder).glob("*.png"))
    api = (site / "python-api" / "index.html").read_text(encoding="utf-8")
    public = [name for name in exubio.__all__ if name != "__version__"]
    missing = [name for name in public if not re.search(rf'id="exubio\.(api|types|errors)\.{name}"', api)]
    assert not missing, f"the API reference lacks {missing}"


def test_a_broken_link_fails_the_build(tmp_path):
    """The build really is strict: a copy of the docs with one link to a missing page does not build."""
    shutil.copytree(DOCS, tmp_path / "docs")
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    for name in ("exubio", "benchmarks", "studies", "reports"):
        (tmp_path / name).symlink_to(ROOT / name)
    page = tmp_path / "docs" / "live.md"
    page.write_text(page.read_text(encoding="utf-8") + "\nSee [the missing page](missing.md).\n", encoding="utf-8")
    done = _build(tmp_path, tmp_path / "site")
    assert done.returncode != 0
    assert "missing.md" in done.stdout + done.stderr


def blocks() -> list[tuple[str, str, str, bool]]:
    """(page, language, body, marked as the API example) of every fenced block."""
    return [(page, m.group(2), m.group(3), bool(m.group(1)))
            for page in PAGES for m in BLOCK.finditer((ROOT / page).read_text(encoding="utf-8"))]


def _checked(page: str, lang: str, body: str, api: bool) -> str | None:
    """Which test runs or checks this block, or None."""
    if lang == "bash":
        lines = [line.split("  #")[0].strip() for line in body.splitlines() if line.strip()]
        runs = [line for line in lines if not (line.startswith("exubio ") or line.startswith("python3 -m venv ")
                                               or line.startswith("python -m mkdocs build"))]
        return None if runs else "tests/project/test_readme_examples.py, .ci/run, this file"
    if lang == "python" and page == "docs/architecture.md" and "MethodSpec(" in body:
        return "tests/methods/test_third_method.py (the registry line, evaluated)"
    if lang == "python":
        return "tests/face/test_api.py" if api and page == "docs/python-api.md" else None
    if lang == "yaml" and "name: lab_15" in body and page == "docs/protocols.md":
        return "tests/protocol/test_protocol_guide.py"
    if lang == "yaml" and "sessions:" in body and page == "docs/studies.md":
        return "tests/project/test_readme_examples.py (the exubio study examples run it)"
    if lang == "yaml":  # a shipped file quoted whole (its comments aside): what the file says, the page says
        if _shipped_file(body):
            return "a shipped file"
        return "lines of a shipped file" if _shipped_lines(body) else None
    if lang == "" and page == "docs/architecture.md":
        return "test_the_architecture_block_names_what_is_there"
    return None


def _shipped_file(body: str) -> Path | None:
    for path in sorted((ROOT / "protocols").rglob("*.yaml")):
        kept = [line for line in path.read_text(encoding="utf-8").splitlines() if line and not line.startswith("#")]
        quoted = [re.split(r"\s+#", line)[0].rstrip() for line in body.splitlines() if line.strip()]
        if kept == quoted:
            return path
    return None


def _shipped_lines(body: str) -> Path | None:
    """A shipped protocol that holds every quoted line (its spacing and comments aside): a part of
    a file quoted, e.g. three markers of protocols/examples/guide_21_skin.yaml."""
    norm = lambda line: re.sub(r"\s+", " ", re.split(r"\s+#", line)[0]).strip()
    quoted = [norm(line) for line in body.splitlines() if line.strip()]
    for path in sorted((ROOT / "protocols").rglob("*.yaml")):
        kept = {norm(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()}
        if quoted and all(q in kept for q in quoted):
            return path
    return None


def test_every_block_of_the_docs_is_run_or_checked_by_a_test():
    found = blocks()
    assert len(found) >= 10
    unchecked = [(page, lang, body[:80]) for page, lang, body, api in found if _checked(page, lang, body, api) is None]
    assert not unchecked, unchecked


def test_the_readme_keeps_exactly_the_two_set_up_commands():
    """The README's two commands (the demo's and the tests'), verbatim in Getting started, and the
    test command as CI runs it."""
    readme = [line for page, lang, body, _ in blocks() if page == "README.md" and lang == "bash"
              for line in body.splitlines() if line.startswith("python3 -m venv")]
    assert readme == ['python3 -m venv .venv && . .venv/bin/activate && pip install . && exubio demo',
                      'python3 -m venv .venv && . .venv/bin/activate && pip install ".[test]" && pytest -q']
    started = (DOCS / "getting-started.md").read_text(encoding="utf-8")
    assert all(line in started for line in readme)
    assert 'pip install ".[test]" && pytest -q' in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_the_architecture_block_names_what_is_there():
    """Each module or folder the architecture page's layer drawing starts a line with exists."""
    text = (DOCS / "architecture.md").read_text(encoding="utf-8")
    drawing = re.search(r"```\n(.*?)```", text, re.S).group(1)
    named = [n for line in drawing.splitlines() if line and not line.startswith(" ")
             for n in re.findall(r"([\w]+(?:\.py|/))", line.split("  ")[0])]
    assert len(named) >= 15
    missing = [n for n in named if not (ROOT / "exubio" / n.rstrip("/")).exists()]
    assert not missing, missing


def inline_commands() -> list[str]:
    """The `exubio ...` commands written inline in the README's and the pages' prose."""
    found = []
    for page in PAGES:
        text = BLOCK.sub("", (ROOT / page).read_text(encoding="utf-8"))
        found += re.findall(r"`(exubio [a-z][^`]*)`", text)
    return sorted(set(found))


def test_every_inline_command_is_one_the_cli_takes(capsys):
    """A command quoted in the prose names a subcommand the CLI has, and every option and choice it
    is written with is one the CLI takes (a fragment may leave out required arguments; the blocks'
    commands are run whole by tests/project/test_readme_examples.py)."""
    import argparse

    from exubio.cli import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    quoted = inline_commands()
    assert len(quoted) >= 15
    wrong = []
    for command in quoted:
        argv = shlex.split(command)[1:]
        argv = argv[: next((i for i, a in enumerate(argv) if a in {">", "|", "&&"}), len(argv))]  # the shell's part
        if argv[0] not in commands:
            wrong.append((command, "no such command"))
            continue
        if len(argv) == 1:
            continue
        try:
            parser.parse_args(argv)
        except SystemExit as stop:
            error = capsys.readouterr().err.strip().splitlines()[-1] if stop.code else ""
            if error and "the following arguments are required" not in error:
                wrong.append((command, error))
    assert not wrong, wrong
