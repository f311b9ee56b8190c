"""The architecture stays easy to see: each heavy third-party library has one owner module, the
report and the viewer never import a solver, and exubio's modules import each other without
cycles. Read from the source (ast), so a stray import anywhere fails here."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "exubio"

# library -> the only modules (paths relative to exubio/) allowed to import it
OWNERS = {
    "exudyn": {"backend/exudyn_system.py"},
    "ezc3d": {"io/c3d.py"},
    "matplotlib": {"report/trial_report.py", "report/validation_report.py", "report/study_report.py"},
    "plotly": {"report/viewer.py"},
    "distributed": {"run/study.py"},
    "dask": {"run/study.py"},
    "pandas": {"api.py"},
    "pylsl": {"run/live/transport.py"},
}
VALIDATION_STUDY = tuple(f"exubio.validation.{m}" for m in ("run", "trials", "determinacy", "sensitivity", "residuals",
                                                              "sier", "invivo", "c3d_tasks", "agreement", "mismatch"))
SOLVERS = ("exubio.methods", "exubio.backend", "exudyn", "exubio.run.pipeline", "exubio.calibration",
           *VALIDATION_STUDY)


def _modules() -> dict[str, Path]:
    return {str(p.relative_to(PACKAGE)): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(path: Path, *, top_level_only: bool = False) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    out = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


@pytest.mark.parametrize("library", sorted(OWNERS))
def test_each_library_has_one_owner(library):
    users = {rel for rel, path in _modules().items()
             if any(m == library or m.startswith(library + ".") for m in _imports(path))}
    assert users <= OWNERS[library], f"{library} imported outside its owner(s): {sorted(users - OWNERS[library])}"


@pytest.mark.parametrize("module", ["report/trial_report.py", "report/validation_report.py", "report/study_report.py",
                                    "report/viewer.py", "validation/results.py", "validation/codec.py",
                                    "validation/settings.py", "validation/checks.py", "validation/paths.py"])
def test_what_draws_results_never_imports_a_solver(module):
    bad = sorted(m for m in _imports(PACKAGE / module) if m.startswith(SOLVERS))
    assert not bad, f"{module} imports {bad}"


def test_no_import_cycles_at_module_level():
    """Module-level imports between exubio modules form no cycle (imports inside functions are
    deferred on purpose and do not count)."""
    mods = _modules()
    name = {rel: "exubio." + rel[:-3].replace("/", ".").removesuffix(".__init__") for rel in mods}
    known = set(name.values())
    graph: dict[str, set[str]] = {}
    for rel, path in mods.items():
        deps = set()
        for m in _imports(path, top_level_only=True):
            while m and m not in known:
                m = m.rpartition(".")[0]
            if m and m != name[rel] and m != "exubio":
                deps.add(m)
        graph[name[rel]] = deps
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> None:
        state[n] = 1
        stack.append(n)
        for d in sorted(graph.get(n, ())):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(d):] + [d]))
            if d not in state:
                visit(d)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n)


def test_every_subpackage_is_installed():
    """A package folder missing from pyproject's explicit package list works in the editable
    checkout and is absent from a real install (CI installs with `pip install .`)."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

    root = Path(__file__).resolve().parents[1]
    listed = set(tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(root).parts) for p in (root / "exubio").rglob("__init__.py")}
    assert found <= listed, f"add to [tool.setuptools] packages: {sorted(found - listed)}"
