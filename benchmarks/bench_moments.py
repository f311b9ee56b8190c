"""What the joint moments cost: the same trial reconstructed by `exubio reconstruct`'s pipeline
(exubio.run.pipeline.reconstruct_file: read, prepare, the method, the checks, the result set) without
and with ``--body-mass`` (the inverse dynamics, the moments CSV and .sto, summary.json's entry),
runs alternated, the process's CPU time of each run (steadier than the wall time on a shared
machine), median over ``--runs``; prints one JSON line per method and the share the moments add.
No report (the report's moments page is drawn only with a report; its cost is the report's).

    python benchmarks/bench_moments.py                  # the shipped example (10 s at 100 Hz), 5 runs
    python benchmarks/bench_moments.py --duration 25 --rate 200 --runs 3   # a simulated 5000-frame trial
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from exubio.io.c3d import write_c3d
from exubio.io.resources import shipped_file
from exubio.model.load import load_model
from exubio.run.inputs import load_session
from exubio.run.pipeline import RunSettings, reconstruct_file
from exubio.synth.simulate import simulate_trial

BODY_MASS_KG = 70.0


def one_run(trial: Path, out: Path, method: str, moments: bool, session) -> tuple[float, float]:
    """(CPU s, wall s) of one reconstruction into ``out`` (replaced)."""
    settings = RunSettings(overwrite=True, hand_load_kg=0.0 if moments else None)
    c0, w0 = time.process_time(), time.perf_counter()
    reconstruct_file(trial, out, methods=[method], session=session, settings=settings)
    return time.process_time() - c0, time.perf_counter() - w0


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5, help="runs of each setting per method (median; default 5)")
    p.add_argument("--methods", default="ls,pf", help="comma-separated (default ls,pf)")
    p.add_argument("--duration", type=float, help="simulate a trial this long (s) instead of the shipped example")
    p.add_argument("--rate", type=float, default=100.0, help="its sampling rate (Hz; default 100)")
    args = p.parse_args(argv)
    session = load_session(body_mass_kg=BODY_MASS_KG)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.duration:
            trial = write_c3d(tmp / "trial.c3d", simulate_trial(load_model(), "abduction", duration_s=args.duration,
                                                                rate_hz=args.rate, noise_mm=1.0, seed=1).trajectories)
        else:
            trial = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
        for method in args.methods.split(","):
            one_run(trial, tmp / "warm", method, True, session)  # imports and caches warm
            cpu = {False: [], True: []}
            wall = {False: [], True: []}
            for _ in range(args.runs):
                for moments in (False, True):  # alternated: a slow spell of the machine hits both
                    c, w = one_run(trial, tmp / f"{method}_{moments}", method, moments, session)
                    cpu[moments].append(c)
                    wall[moments].append(w)
            n = json.loads((tmp / f"{method}_True" / f"{Path(trial).stem}.{method}.summary.json").read_text())["n_frames"]
            base, with_m = statistics.median(cpu[False]), statistics.median(cpu[True])
            results[method] = {"frames": n, "runs": args.runs, "cpu_s_without": round(base, 4),
                               "cpu_s_with_body_mass": round(with_m, 4), "added_share": round(with_m / base - 1, 4),
                               "added_ms_per_frame": round((with_m - base) / n * 1000, 4),
                               "wall_s_without": round(statistics.median(wall[False]), 4),
                               "wall_s_with_body_mass": round(statistics.median(wall[True]), 4)}
            print(json.dumps({"method": method, **results[method]}))
    for method, r in results.items():
        print(f"{method.upper()}: {r['frames']} frames, CPU median {r['cpu_s_without']:.3f} s without, "
              f"{r['cpu_s_with_body_mass']:.3f} s with --body-mass: +{100 * r['added_share']:.1f} % "
              f"({r['added_ms_per_frame']:.3f} ms/frame; aim: at most 20 %)", file=sys.stderr)
    return results


if __name__ == "__main__":
    main()
