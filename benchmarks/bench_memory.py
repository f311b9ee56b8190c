"""Peak memory of `exubio reconstruct` on a long trial, PF and LS, and the streamed result against one pass.

    python benchmarks/bench_memory.py                  # 20 minutes at 200 Hz (240,000 frames)
    python benchmarks/bench_memory.py --minutes 2      # a quicker look

1. Simulates the trial once (``exubio simulate --motion abduction --duration ... --rate 200 --noise-mm 1
   --sta-mm 10 --seed 1``) into ``--work`` (kept for the next run).
2. Runs ``exubio reconstruct TRIAL --method pf|ls --no-report`` under ``/usr/bin/time -v`` and prints
   its peak resident memory (maximum RSS) and wall time. The method streams its result in chunks
   (exubio.methods.common.CHUNK_FRAMES frames) to its result files (exubio.io.streamed).
3. Reconstructs the same trial in one pass in this process (``exubio.run.pipeline.reconstruct``: one
   chunk of every frame, memory not measured) and prints the largest difference of q, q̇, q̈ to
   the files of step 2.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def _peak(cmd: list[str], log: Path) -> tuple[float, float]:
    t0 = time.perf_counter()
    res = subprocess.run(["/usr/bin/time", "-v", *cmd], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    log.write_text(res.stdout + res.stderr, encoding="utf-8")
    if res.returncode not in (0, 1):
        sys.exit(f"{' '.join(cmd)} failed ({res.returncode}); see {log}")
    kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", res.stderr).group(1))
    return kb / 1e6, wall


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--work", default="/tmp/exubio_bench_memory", help="folder for the trial and the results")
    ap.add_argument("--methods", default="pf,ls")
    ap.add_argument("--no-compare", action="store_true", help="skip the one-pass comparison (step 3)")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    trial = work / f"long_{args.minutes:g}min.c3d"
    if not trial.exists():
        print(f"simulating {trial} ...", flush=True)
        subprocess.run(["exubio", "-q", "simulate", "--motion", "abduction", "--duration", str(args.minutes * 60),
                        "--rate", "200", "--noise-mm", "1", "--sta-mm", "10", "--seed", "1", "--out", str(trial)],
                       check=True)
    n = int(round(args.minutes * 60 * 200)) + 1
    print(f"trial: {trial} ({n} frames at 200 Hz)")
    for method in args.methods.split(","):
        out = work / f"out_{args.minutes:g}_{method}"
        gb, wall = _peak(["exubio", "-q", "reconstruct", str(trial), "--method", method, "--no-report", "--out",
                          str(out), "--overwrite"], work / f"{method}.time.log")
        print(f"{method}: peak memory {gb:.2f} GB, wall {wall:.0f} s  (exubio reconstruct --method {method} "
              f"--no-report under /usr/bin/time -v)", flush=True)
        if args.no_compare:
            continue
        from exubio.io.results import read_npz
        from exubio.run.pipeline import load_inputs, reconstruct

        streamed = read_npz(out / f"{trial.stem}.{method}.npz")
        inp = load_inputs(trial)
        one = reconstruct(inp.model, inp.protocol, inp.targets, method=method)
        diffs = {k: float(np.nanmax(np.abs(getattr(one, k) - getattr(streamed, k))))
                 for k in ("q_rad", "qd_rad_s", "qdd_rad_s2")}
        print(f"{method}: streamed vs one pass, max |difference|: q {diffs['q_rad']:.1e} rad, "
              f"q̇ {diffs['qd_rad_s']:.1e} rad/s, q̈ {diffs['qdd_rad_s2']:.1e} rad/s²", flush=True)
        del streamed, one, inp
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
