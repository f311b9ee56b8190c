"""The package's house, measured with the project's own rules (tests/project/test_architecture.py's layers
and import reading): ``draw`` pictures the rooms (subpackages and top modules) by layer with the
import arrows between them, at this checkout or at a git revision, and prints the counts;
``walk`` follows one trial (the shipped example, PF, no report) through the package at run time and
counts its stops (a call from one module into another), the rooms it enters, and the climbs back
up (a call from a lower layer into a higher one: a callback).

    python docs/house.py draw --out reports/screenshots/house_after.png
    python docs/house.py draw --rev e2c0947 --out reports/screenshots/house_before.png
    python docs/house.py walk

The figures and counts are on the docs' Architecture page."""
from __future__ import annotations

import argparse
import collections
import importlib.util
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _rules():
    spec = importlib.util.spec_from_file_location("architecture_rules", ROOT / "tests" / "project" / "test_architecture.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _package_at(rev: str | None, work: Path) -> Path:
    """The exubio/ folder of this checkout, or of ``rev`` unpacked into ``work``."""
    if rev is None:
        return ROOT / "exubio"
    archive = work / "rev.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(archive), rev, "exubio"], check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(work / "tree", filter="data")
    return work / "tree" / "exubio"


def _graph(package: Path, rules) -> tuple[dict[str, set[str]], dict[str, int]]:
    """module -> the exubio modules it imports (also inside functions); module -> its lines."""
    files = {p: "exubio." + str(p.relative_to(package))[:-3].replace("/", ".").removesuffix(".__init__")
             for p in sorted(package.rglob("*.py"))}
    files = {p: ("exubio" if n == "exubio.__init__" else n) for p, n in files.items()}
    known = set(files.values())
    graph, lines = {}, {}
    for path, name in files.items():
        deps = set()
        for m in rules._imports(path):
            while m and m not in known:
                m = m.rpartition(".")[0]
            if m and m not in (name, "exubio"):
                deps.add(m)
        graph[name] = deps
        lines[name] = path.read_text(encoding="utf-8").count("\n")
    return graph, lines


def room(module: str) -> str:
    """A module's room: its subpackage (exubio.trust), or the module itself at the top (exubio.api)."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else module


def draw(rev: str | None, out: Path | None) -> dict:
    rules = _rules()
    with tempfile.TemporaryDirectory() as tmp:
        graph, lines = _graph(_package_at(rev, Path(tmp)), rules)
    lay = {m: rules._layer(m) if rules._layer(m) is not None else len(rules.LAYERS) for m in graph}
    spans = collections.defaultdict(set)
    for m in graph:
        spans[room(m)].add(lay[m])
    # a package whose modules sit on two layers (truth's reader is an io module) is two rooms
    where = {m: room(m) if len(spans[room(m)]) == 1 else f"{room(m)} (layer {lay[m]})" for m in graph}
    rooms = collections.defaultdict(list)
    for m in graph:
        rooms[where[m]].append(m)
    layer = {r: lay[ms[0]] for r, ms in rooms.items()}
    arrows = collections.Counter((where[a], where[b]) for a, deps in graph.items() for b in deps if where[a] != where[b])
    up = {(a, b): n for (a, b), n in arrows.items() if layer[b] > layer[a]}
    up_modules = sorted(f"{a} -> {b}" for a, deps in graph.items() for b in deps
                        if (rules._layer(a) is not None and rules._layer(b) is not None and rules._layer(b) > rules._layer(a)))
    counts = {"revision": rev or "this checkout", "modules": len(graph), "rooms": len(rooms), "lines": sum(lines.values()),
              "module imports": sum(len(d) for d in graph.values()), "room arrows": len(arrows),
              "arrows up (rooms)": len(up), "imports up (modules)": len(up_modules),
              "modules over 500 lines": sorted(f"{m} ({n})" for m, n in lines.items() if n > 500)}
    if out is not None:
        _picture(rooms, layer, arrows, up, lines, counts, out)
    return counts


def _picture(rooms, layer, arrows, up, lines, counts, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_layer = collections.defaultdict(list)
    for r in sorted(rooms):
        by_layer[layer[r]].append(r)
    pos = {}
    for y, (_, rs) in enumerate(sorted(by_layer.items())):
        for x, r in enumerate(rs):  # a lone room alternates left and right of the middle: its arrows show
            pos[r] = ((x + 0.5) / len(rs) if len(rs) > 1 else (0.42 if y % 2 else 0.58), y)
    fig, ax = plt.subplots(figsize=(12, 0.55 * len(by_layer) + 1.5))
    for (a, b), n in arrows.items():
        (x0, y0), (x1, y1) = pos[a], pos[b]
        colour, width = ("tab:red", 1.6) if (a, b) in up else ("0.6", 0.3 + 0.15 * min(n, 10))
        ax.annotate("", xy=(x1, y1), xytext=(x0, y0), arrowprops=dict(arrowstyle="->", color=colour, lw=width,
                                                                       alpha=0.9 if (a, b) in up else 0.35))
    for r, (x, y) in pos.items():
        size = sum(lines[m] for m in rooms[r])
        ax.text(x, y, f"{r.removeprefix('exubio.')}\n{len(rooms[r])} mod, {size} lines", ha="center", va="center",
                fontsize=7, bbox=dict(boxstyle="round", fc="white", ec="0.3"))
    ax.set_ylim(-0.7, len(by_layer) - 0.3)
    ax.set_xlim(-0.02, 1.02)
    ax.axis("off")
    ax.set_title(f"exubio at {counts['revision']}: {counts['modules']} modules in {counts['rooms']} rooms, "
                 f"{counts['room arrows']} arrows between rooms (grey, down the layers), {counts['arrows up (rooms)']} "
                 f"up (red); layers from the bottom (tests/project/test_architecture.py)", fontsize=9)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def walk() -> dict:
    """One trial through the package at run time (module docstring)."""
    rules = _rules()
    from exubio.io.resources import shipped_file
    from exubio.run.inputs import load_session
    from exubio.run.job import TrialJob, run_job

    trial = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    session = load_session()
    stops: collections.Counter = collections.Counter()
    stack: list[str] = []

    def profile(frame, event, arg):  # noqa: ARG001
        name = frame.f_globals.get("__name__", "")
        if event == "call":
            here = name if name.startswith("exubio") else (stack[-1] if stack else "")
            if name.startswith("exubio") and stack and stack[-1] != name and stack[-1]:
                stops[(stack[-1], name)] += 1
            stack.append(here)
        elif event == "return" and stack:
            stack.pop()

    with tempfile.TemporaryDirectory() as tmp:
        job = TrialJob(trial, Path(tmp) / "out", methods=("pf",), session=session, report=False)
        sys.setprofile(profile)
        try:
            run_job(job)
        finally:
            sys.setprofile(None)
    climbs = {k: n for k, n in stops.items() if (rules._layer(k[1]) or 0) > (rules._layer(k[0]) or 0)}
    return {"distinct stops (caller module -> callee module)": len(stops), "calls across modules": sum(stops.values()),
            "rooms entered": len({room(m) for k in stops for m in k}), "modules entered": len({m for k in stops for m in k}),
            "distinct climbs back up": len(climbs), "calls climbing back up": sum(climbs.values()),
            "climbs": sorted(f"{a} -> {b} ({n} calls)" for (a, b), n in climbs.items())}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="what", required=True)
    d = sub.add_parser("draw")
    d.add_argument("--rev", help="a git revision (default: this checkout)")
    d.add_argument("--out", type=Path, help="PNG to write")
    sub.add_parser("walk")
    args = p.parse_args()
    result = draw(args.rev, args.out) if args.what == "draw" else walk()
    for k, v in result.items():
        print(f"{k}: " + ("\n  " + "\n  ".join(v) if isinstance(v, list) and v else str(v)))


if __name__ == "__main__":
    main()
