"""Where a trial's memory goes: the resident memory of ``exubio reconstruct`` stage by stage.

    python benchmarks/memory_stages.py TRIAL --method pf             # peak RSS per stage
    python benchmarks/memory_stages.py TRIAL --method ls --allocations 8
    python benchmarks/memory_stages.py TRIAL --method pf --no-trim   # without giving the C heap back

Runs ``exubio reconstruct TRIAL --method M --no-report`` in this process while a thread samples, every
``--every`` seconds, the process's resident memory (/proc/self/statm) and the stage the main thread
is in, read from its stack: read (the C3D/TRC reader), label checks (before the targets are made),
prepare (thorax frame, filter, splines), method (the reconstruction's run), assessment (determinacy,
uncertainty, limits, verdict), files (the angles, .mot, .npz, summary). Prints, per stage, its time
and its largest sampled resident memory, then the process's peak (getrusage: it includes what the
sampling misses between samples; /usr/bin/time, as bench_memory.py reads it, agrees within a few MB).

``--allocations N``: with tracemalloc on (slower, and its own bookkeeping adds ~50 MB), also the N
largest live allocations (by source line) at each stage's highest traced memory: what holds it.
Linux only (/proc). The trial of issue 38's bound: ``bench_memory.py`` makes it (20 minutes at 200 Hz).
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import threading
import time
import tracemalloc
from pathlib import Path

STAGES = (  # (stage, a function on the main thread's stack that says it), the outermost match decides
    ("read", ("read_trial", "read_c3d", "read_trc")),
    ("label checks", ("drop_missing_markers", "check_thorax_labels", "find_partial_swaps", "repair_partial_swaps")),
    ("prepare", ("prepare_targets", "moment_inputs")),
    ("method", ("stream_reconstruct",)),
    ("assessment", ("assess_inputs", "assess_trial")),
    ("files", ("write_assessed", "write_outputs")),
)
_STAGE_OF = {fn: stage for stage, fns in STAGES for fn in fns}
_PAGE = os.sysconf("SC_PAGE_SIZE")


def _rss_mb() -> float:
    with open("/proc/self/statm", encoding="ascii") as fh:
        return int(fh.read().split()[1]) * _PAGE / 1e6


def _stage(frame) -> str:
    names = []
    while frame is not None:
        names.append(frame.f_code.co_name)
        frame = frame.f_back
    for name in reversed(names):  # outermost first
        if name in _STAGE_OF:
            return _STAGE_OF[name]
    return "other"


class Sampler(threading.Thread):
    def __init__(self, every_s: float, allocations: int) -> None:
        super().__init__(daemon=True)
        self.every_s, self.allocations = every_s, allocations
        self.main = threading.get_ident()
        self.stop = threading.Event()
        self.rows: dict[str, dict] = {}  # stage -> first/last time, peak RSS, peak traced, top allocations

    def run(self) -> None:
        t0 = time.perf_counter()
        while not self.stop.is_set():
            stage = _stage(sys._current_frames().get(self.main))
            row = self.rows.setdefault(stage, {"first_s": time.perf_counter() - t0, "peak_mb": 0.0, "traced_mb": 0.0,
                                               "top": []})
            row["last_s"] = time.perf_counter() - t0
            row["peak_mb"] = max(row["peak_mb"], _rss_mb())
            if self.allocations and tracemalloc.is_tracing():
                traced = tracemalloc.get_traced_memory()[0] / 1e6
                if traced > row["traced_mb"] + 5.0:  # a new high of this stage: what holds it
                    row["traced_mb"] = traced
                    stats = tracemalloc.take_snapshot().statistics("lineno")[:self.allocations]
                    row["top"] = [(s.size / 1e6, str(s.traceback[0])) for s in stats]
            self.stop.wait(self.every_s)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("trial")
    ap.add_argument("--method", default="pf", choices=("pf", "ls"))
    ap.add_argument("--out", default="/tmp/exubio_memory_stages", help="output folder (results replaced)")
    ap.add_argument("--every", type=float, default=0.1, help="sampling period, s")
    ap.add_argument("--allocations", type=int, default=0, help="with tracemalloc: the N largest allocations per stage")
    ap.add_argument("--no-trim", action="store_true", help="the C heap not given back between stages "
                    "(exubio.io.heap.release_freed_heap made a no-op): what the trimming saves")
    args = ap.parse_args(argv)
    from exubio.cli import main as exubio_main

    if args.no_trim:
        from exubio.io import heap

        heap._LIBC[:] = [None]  # as where there is no glibc

    if args.allocations:
        tracemalloc.start(1)
    sampler = Sampler(args.every, args.allocations)
    sampler.start()
    code = exubio_main(["-q", "reconstruct", str(Path(args.trial)), "--method", args.method, "--no-report",
                        "--out", args.out, "--overwrite"])
    sampler.stop.set()
    sampler.join()
    print(f"exubio reconstruct {args.trial} --method {args.method} --no-report: exit {code}")
    print(f"{'stage':<14}{'from s':>8}{'to s':>8}{'peak RSS MB':>13}" + (f"{'traced MB':>11}" if args.allocations else ""))
    for stage in sorted(sampler.rows, key=lambda s: sampler.rows[s]["first_s"]):
        r = sampler.rows[stage]
        print(f"{stage:<14}{r['first_s']:8.1f}{r['last_s']:8.1f}{r['peak_mb']:13.0f}"
              + (f"{r['traced_mb']:11.0f}" if args.allocations else ""))
        for size, where in r["top"]:
            print(f"    {size:7.1f} MB  {where}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3  # kB on Linux
    print(f"process peak (getrusage maxrss): {peak:.0f} MB")
    return int(code or 0)


if __name__ == "__main__":
    raise SystemExit(main())
