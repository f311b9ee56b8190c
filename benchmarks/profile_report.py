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
import sys
import tempfile
import time
from pathlib import Path

PAGE_DPI = 100
_MODELS: dict[str, object] = {}


def _report(folder: Path, out: Path, pages: list[str] | None) -> float:
    from exubio.report import trial_report
    from exubio.scapulohumeral.files import model_of

    npz = sorted(folder.glob("*.npz"))
    if not npz:
        raise SystemExit(f"{folder}: no <trial>.<method>.npz")
    original = trial_report.PdfPages

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
    trial_report.PdfPages = Recording
    try:
        t0 = time.process_time()
        trial_report.draw_trial_report(results, out / f"{folder.name}.report.pdf")
        return time.process_time() - t0
    finally:
        trial_report.PdfPages = original


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dirs", nargs="*", type=Path)
    ap.add_argument("--profile", type=int, metavar="N")
    ap.add_argument("--pages", type=Path, metavar="OUT")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
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
