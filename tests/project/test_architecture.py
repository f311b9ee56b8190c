"""The architecture stays easy to see: each heavy third-party library has one owner module, the
report and the viewer never import a solver, and exubio's modules import each other without
cycles. Read from the source (ast), so a stray import anywhere fails here."""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "exubio"

# library -> the only modules (paths relative to exubio/) allowed to import it
OWNERS = {
    "exudyn": {"backend/exudyn_system.py", "backend/exudyn_limits.py", "backend/exudyn_integrate.py"},
    "ezc3d": {"io/c3d.py"},
    "matplotlib": {"report/trial_report.py", "report/page_figures.py", "report/study_report.py", "report/validation_report.py",
                   "report/validation_common.py", "report/validation_tables.py", "report/validation_summary.py",
                   "report/validation_paper_figures.py", "report/validation_exubio_figures.py",
                   "report/calibration_page.py", "report/rhythm_page.py", "report/moments_page.py"},
    "plotly": {"report/viewer.py", "report/viewer_page.py", "report/viewer_scene.py", "report/viewer_results.py"},
    "distributed": {"run/executors.py"},
    "dask": {"run/executors.py"},
    "pandas": {"api.py", "run/study_table.py", "run/study_moments.py", "run/csv_gz.py"},  # the study's angles table (Parquet, CSV) is a DataFrame
    "polars": {"run/csv_gz.py"},  # the study table's CSV writer
    "isal": {"run/csv_gz.py"},  # the study tables' gzip
    "pylsl": {"run/live/transport.py"},
    "numba": {"model/kernels.py",  # the compiled kernels, imported where used (0.2 s to import)
              "model/batch_kernels.py",  # those of the preparation and the checks (filter, chain fits), bit-identical
              "model/live_kernels.py"},  # one live frame's outputs in one call, bit-identical
}
VALIDATION_STUDY = tuple(f"exubio.validation.{m}" for m in ("run", "trials", "determinacy", "sensitivity", "residuals",
                                                              "sier", "invivo", "c3d_tasks", "agreement", "mismatch"))
SOLVERS = ("exubio.methods", "exubio.backend", "exudyn", "exubio.run.pipeline", "exubio.calibration",
           *VALIDATION_STUDY)


@functools.lru_cache(maxsize=None)  # the tree does not change during a run: read it once
def _modules() -> dict[str, Path]:
    return {str(p.relative_to(PACKAGE)): p for p in sorted(PACKAGE.rglob("*.py"))}


@functools.lru_cache(maxsize=None)
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


@pytest.mark.parametrize("module", [*sorted(str(p.relative_to(PACKAGE)) for p in (PACKAGE / "report").glob("*.py")),
                                    "validation/results.py", "validation/records_runs.py",
                                    "validation/records_comparisons.py", "io/records.py",
                                    "validation/settings.py", "validation/checks.py", "validation/paths.py"])
def test_what_draws_results_never_imports_a_solver(module):
    bad = sorted(m for m in _imports(PACKAGE / module) if m.startswith(SOLVERS))
    assert not bad, f"{module} imports {bad}"


# The layers, lowest first: a module imports only from its own layer or below (the longest prefix
# decides: the validation study's typed records sit below the report that draws them, the study
# itself above the run layer it drives).
LAYERS = (
    ("exubio.errors", "exubio.types", "exubio.short_repr", "exubio.method_registry"),
    ("exubio.io", "exubio.truth.sta_format"),  # the reader of bone-referenced trials is an io module
    ("exubio.model",),
    ("exubio.dynamics",),  # inverse dynamics: numpy on the model's kinematics, no solver, no Exudyn
    ("exubio.protocol",),
    ("exubio.prep", "exubio.export"),
    ("exubio.backend",),
    ("exubio.methods",),
    ("exubio.calibration",),
    ("exubio.literature",),
    ("exubio.synth",),
    ("exubio.trust",),
    ("exubio.scapulohumeral",),  # the scapulohumeral rhythm from result files (below the report that draws it)
    tuple(f"exubio.validation.{m}" for m in ("results", "records_runs", "records_comparisons", "settings",
                                               "checks", "paths")),
    ("exubio.report",),
    ("exubio.run",),
    ("exubio.truth",),  # bone truth: reads bone-referenced data, runs a lab's reconstruction of it, judges calibrations
    ("exubio.validation",),
    ("exubio.api", "exubio.cli"),
    ("exubio",),  # the package's face: its lazy names come from the API
)


@functools.lru_cache(maxsize=None)
def _graph() -> dict[str, set[str]]:
    """exubio module -> the exubio modules it imports, at module level or inside functions alike."""
    mods = _modules()
    name = {rel: "exubio." + rel[:-3].replace("/", ".").removesuffix(".__init__") for rel in mods}
    name = {rel: ("exubio" if n == "exubio.__init__" else n) for rel, n in name.items()}
    known = set(name.values())
    graph: dict[str, set[str]] = {}
    for rel, path in mods.items():
        deps = set()
        for m in _imports(path):
            while m and m not in known:
                m = m.rpartition(".")[0]
            if m and m != name[rel] and m != "exubio":
                deps.add(m)
        graph[name[rel]] = deps
    return graph


def _layer(module: str) -> int | None:
    best = None
    for i, prefixes in enumerate(LAYERS):
        for pre in prefixes:
            if (module == pre or module.startswith(pre + ".")) and (best is None or len(pre) > best[1]):
                best = (i, len(pre))
    return None if best is None else best[0]


def test_no_import_cycles():
    """No cycle among exubio's modules, counting the imports inside functions too (a deferred
    import hides a cycle from the interpreter, not from the design)."""
    graph = _graph()
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


def test_every_module_is_on_a_layer():
    graph = _graph()
    assert not [m for m in graph if _layer(m) is None and m != "exubio.data"]


def test_imports_point_down_the_layers():
    """A module imports only from its own layer or the layers below it (LAYERS)."""
    up = sorted(f"{a} (layer {_layer(a)}) imports {b} (layer {_layer(b)})" for a, deps in _graph().items()
                for b in deps if _layer(a) is not None and _layer(b) is not None and _layer(b) > _layer(a))
    assert not up, "\n".join(up)


def test_the_checker_sees_an_import_inside_a_function(tmp_path):
    """_imports reads the imports inside functions (what the cycle and layer tests rely on)."""
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from exubio.run.pipeline import reconstruct\n", encoding="utf-8")
    assert "exubio.run.pipeline" in _imports(f)
    assert "exubio.run.pipeline" not in _imports(f, top_level_only=True)


def _parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = fn.args
    n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
    return n - bool(a.args and a.args[0].arg in ("self", "cls"))


def test_no_function_of_the_run_layer_takes_more_than_8_parameters():
    """The run layer passes objects (Session, RunSettings, SessionCalibration, TrialJob), not long
    keyword lists."""
    long = sorted(f"{rel}:{fn.lineno} {fn.name} ({_parameters(fn)})" for rel, path in _modules().items()
                  if rel.startswith("run/") for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
                  if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) and _parameters(fn) > 8)
    assert not long, long


def test_every_subpackage_is_installed():
    """A package folder missing from pyproject's explicit package list works in the editable
    checkout and is absent from a real install (CI installs with `pip install .`)."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

    root = Path(__file__).resolve().parents[2]
    listed = set(tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(root).parts) for p in (root / "exubio").rglob("__init__.py")}
    assert found <= listed, f"add to [tool.setuptools] packages: {sorted(found - listed)}"


# What needs Exudyn: the backend, the PF method and the live loop built on it (its settings hold
# PF's, the offline causal run and the commands drive it); nothing else does (the trust layer, the
# pipeline, the API, the CLI, the live loop's outputs, monitor and intake, its display and the
# recording's writer import without it: it loads when PF runs).
NEEDS_EXUDYN = {"exubio.backend.exudyn_system", "exubio.backend.exudyn_limits", "exubio.backend.exudyn_integrate",
                "exubio.backend.exudyn_live", "exubio.methods.pf", "exubio.run.live.app", "exubio.run.live.loop",
                "exubio.run.live.offline", "exubio.run.live.options"}


def test_only_the_pf_engine_needs_exudyn_to_import():
    import subprocess
    import sys

    code = (
        "import sys, importlib, pkgutil\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] == 'exudyn': raise ImportError('blocked')\n"
        "sys.meta_path.insert(0, Block())\n"
        "import exubio\n"
        "bad = []\n"
        "for m in pkgutil.walk_packages(exubio.__path__, 'exubio.'):\n"
        "    try: importlib.import_module(m.name)\n"
        "    except ImportError: bad.append(m.name)\n"
        "print(' '.join(sorted(bad)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    assert set(out.stdout.split()) == NEEDS_EXUDYN


MAX_LINES = 500


def test_no_module_over_500_lines():
    """Small modules with one job: none over MAX_LINES (issue 34; the last five were split by job)."""
    long = [f"{rel} ({path.read_text(encoding='utf-8').count(chr(10))} lines)" for rel, path in _modules().items()
            if path.read_text(encoding="utf-8").count("\n") > MAX_LINES]
    assert not long, long
