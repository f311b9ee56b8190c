"""The per-trial report's CPU, its profile, and its pages as pixels (to prove a change draws the same).

    python benchmarks/profile_report.py DIR [DIR ...] [--profile N] [--pages OUT]

Each DIR holds one trial's results (``<trial>.<method>.npz`` with its .csv and summary.json, as
``exubio reconstruct --no-report`` or a study writes them); the report of DIR is drawn from all its
.npz (PF alone or PF and LS) into a temporary folder with draw_trial_report, each result holding
its model in memory as a study's run gives it (loaded once per model file, outside the timing, as
is the reading of the files). The first DIR is drawn once more first (a warm-up: imports, fonts,
the re-used figures). Prints the CPU seconds of each report and their median. ``--profile N``: cProfile of the reports, the N costliest
functions by own time and by cumulative time. ``--pages OUT``: writes OUT (JSON): for each report,
the SHA-256 of every PDF page rendered to RGBA pixels by Agg at 100 dpi just after the PDF saved it,
of the PNG of page 1, and of the PDF (written with a fixed creation date). Two such files (before
and after a change, same inputs) are compared with ``--compare A.json B.json``.

``--against CHECKOUT --rounds N``: the reports drawn by two processes, one importing exubio from
CHECKOUT (a worktree of the commit before a change) and one from this checkout, alternately (the
order swapped every round), N rounds over the DIRs after a warm-up of each; prints each side's
median and the median of the paired ratios (this checkout / CHECKOUT), the figure a noisy machine
disturbs least. Run it from outside the checkouts (``cd /tmp``) so that PYTHONPATH decides.
"""
from __future__ import annotations

import argparse
import cProfile
import dataclasses
import hashlib
import io
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PAGE_DPI = 100
_MODELS: dict[str, object] = {}


def _report(folder: Path, out: Path, pages: list[str] | None) -> float:
    from exubio.report import page_figures, trial_report
    from exubio.scapulohumeral.files import model_of

    npz = sorted(folder.glob("*.npz"))
    if not npz:
        raise SystemExit(f"{folder}: no <trial>.<method>.npz")
    owner = page_figures if hasattr(page_figures, "pdf_pages") else trial_report  # (before 2026-12-06: trial_report's)
    original = owner.PdfPages

    class Recording(original):  # every page as pixels, right after the PDF saved it
        def savefig(self, figure=None, **kw):
            super().savefig(figure, **kw)
            if pages is not None:
                buf = io.BytesIO()
                figure.savefig(buf, format="rgba", dpi=PAGE_DPI)
                pages.append(f"{figure.get_size_inches().tolist()} {hashlib.sha256(buf.getvalue()).hexdigest()}")

    results = []
    for p in npz:
        r = trial_report.read_result(p)
        key = str(r.metadata.get("model"))
        if key not in _MODELS:
            _MODELS[key] = model_of(r.metadata)[0]
        results.append(dataclasses.replace(r, model=_MODELS[key]))
    owner.PdfPages = Recording
    try:
        t0 = time.process_time()
        trial_report.draw_trial_report(results, out / f"{folder.name}.report.pdf")
        return time.process_time() - t0
    finally:
        owner.PdfPages = original


def _serve(dirs: list[Path]) -> None:
    """--serve: draw the report of the DIR index read from stdin, print its CPU seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        for line in sys.stdin:
            print(_report(dirs[int(line)], Path(tmp), None), flush=True)


def _against(base: Path, dirs: list[Path], rounds: int) -> None:
    here = Path(__file__).resolve()
    sides = {}
    for label, checkout in (("base", base.resolve()), ("this", here.parents[1])):
        env = dict(os.environ, PYTHONPATH=str(checkout))
        sides[label] = subprocess.Popen([sys.executable, str(here), "--serve", *map(str, dirs)], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, env=env, cwd=tempfile.gettempdir())

    def draw(label: str, k: int) -> float:
        p = sides[label]
        p.stdin.write(f"{k}\n")
        p.stdin.flush()
        line = p.stdout.readline()
        if not line:
            raise SystemExit(f"the {label} process stopped (exit code {p.wait()})")
        return float(line)

    for label in sides:  # warm-up
        draw(label, 0)
    cpu: dict[str, list[float]] = {"base": [], "this": []}
    ratios = []
    for r in range(rounds):
        k = r % len(dirs)
        got = {label: draw(label, k) for label in (("base", "this") if r % 2 == 0 else ("this", "base"))}
        for label, v in got.items():
            cpu[label].append(v)
        ratios.append(got["this"] / got["base"])
    for p in sides.values():
        p.stdin.close()
        p.wait()
    q = statistics.quantiles(ratios, n=4) if len(ratios) > 1 else [ratios[0]] * 3
    print(f"CPU per report, median of {rounds}: {base} {statistics.median(cpu['base']):.3f} s, this checkout "
          f"{statistics.median(cpu['this']):.3f} s; paired ratio (this / base) median {q[1]:.3f}, quartiles "
          f"{q[0]:.3f}-{q[2]:.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dirs", nargs="*", type=Path)
    ap.add_argument("--profile", type=int, metavar="N")
    ap.add_argument("--pages", type=Path, metavar="OUT")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    ap.add_argument("--against", type=Path, metavar="CHECKOUT")
    ap.add_argument("--rounds", type=int, default=24)
    ap.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.compare:
        a, b = (json.loads(p.read_text()) for p in args.compare)
        bad = [k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        for k in bad:
            print(f"DIFFERENT: {k}\n  {a.get(k)}\n  {b.get(k)}")
        print(f"{len(a)} reports, {sum(len(v['pages']) for v in a.values())} pages: "
              + ("identical" if not bad else f"{len(bad)} differ"))
        return 1 if bad else 0
    if not args.dirs:
        ap.error("give at least one DIR")
    if args.serve:
        _serve(args.dirs)
        return 0
    if args.against:
        _against(args.against, args.dirs, args.rounds)
        return 0
    os.environ.setdefault("SOURCE_DATE_EPOCH", "0")  # the PDF's creation date fixed: its bytes comparable
    record: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        _report(args.dirs[0], out, None)  # warm-up
        prof = cProfile.Profile() if args.profile else None
        cpu = []
        for d in args.dirs:
            pages: list[str] | None = [] if args.pages else None
            if prof:
                prof.enable()
            cpu.append(_report(d, out, pages))
            if prof:
                prof.disable()
            print(f"{d}: {cpu[-1]:.3f} s CPU")
            if args.pages:
                pdf = out / f"{d.name}.report.pdf"
                record[str(d)] = {"pages": pages, "png": hashlib.sha256(pdf.with_suffix(".png").read_bytes()).hexdigest(),
                                  "pdf": hashlib.sha256(pdf.read_bytes()).hexdigest()}
    print(f"median CPU per report: {statistics.median(cpu):.3f} s over {len(cpu)} reports")
    if prof:
        for key in ("tottime", "cumulative"):
            pstats.Stats(prof, stream=sys.stdout).sort_stats(key).print_stats(args.profile)
    if args.pages:
        args.pages.write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
