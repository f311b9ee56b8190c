"""A study at scale: N simulated trials (default 100 of 25 s at 200 Hz, 1 mm noise, 10 mm soft-tissue
artefact; abduction and flexion alternating; 10 subjects x 10 trials), PF with the per-trial
report on, run by ``exubio study`` with the local process pool (--jobs 2) and with Dask
(--scheduler local:2). Prints the wall time of each run, the per-trial time and the per-trial
overhead outside the solver (trial wall time minus the PF solve time of its summary).

Usage:
    python benchmarks/bench_study.py [--trials 100] [--duration 25] [--rate 200] [--methods pf]
           [--runs jobs,dask] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import logging
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from exubio.model import load_model
from exubio.simulate import simulate_trial, write_simulated_trial


def make_trials(folder: Path, n: int, duration: float, rate: float) -> Path:
    model = load_model()
    sessions = []
    per_subject = 10
    for k in range(n):
        subject = f"S{k // per_subject + 1:02d}"
        path = folder / subject / f"trial{k % per_subject:02d}.c3d"
        path.parent.mkdir(parents=True, exist_ok=True)
        sim = simulate_trial(model, "abduction" if k % 2 == 0 else "flexion", duration_s=duration, rate_hz=rate,
                             noise_mm=1.0, sta_mm=10.0, seed=k)
        write_simulated_trial(sim, path)
    for subject in sorted({p.name for p in folder.iterdir() if p.is_dir()}):
        sessions.append({"subject": subject, "trials": [f"{subject}/*.c3d"]})
    return folder / "study.yaml", sessions


def run(study: Path, out: Path, extra: list[str]) -> float:
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "exubio.cli", "-q", "study", str(study), "--out", str(out), *extra],
                       capture_output=True, text=True, encoding="utf-8")
    wall = time.perf_counter() - t0
    if p.returncode not in (0, 1):
        print(p.stdout, p.stderr, file=sys.stderr)
        raise SystemExit(f"study run failed with exit code {p.returncode}")
    return wall


def overheads(out: Path) -> tuple[list[float], list[float]]:
    walls, over = [], []
    for done in out.rglob("DONE.json"):
        row = json.loads(done.read_text(encoding="utf-8"))["outcome"]
        summ = next(done.parent.glob("*.pf.summary.json"), None)
        if summ is None or row.get("wall_s") is None:
            continue
        solve = json.loads(summ.read_text(encoding="utf-8")).get("wall_time_s", 0.0)
        walls.append(row["wall_s"])
        over.append(row["wall_s"] - solve)
    return walls, over


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--duration", type=float, default=25.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--methods", default="pf", help="comma-separated: pf, ls (default pf)")
    ap.add_argument("--runs", default="jobs,dask", help="which runs: jobs (process pool, --jobs 2), dask (local:2)")
    ap.add_argument("--keep", help="write the trials and results here instead of a temporary folder")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep or tmp)
        data = root / "data"
        t0 = time.perf_counter()
        study, sessions = make_trials(data, args.trials, args.duration, args.rate)
        study.write_text(yaml.safe_dump({"schema_version": 1, "name": "bench", "report": True,
                                         "methods": args.methods.split(","), "sessions": sessions}), encoding="utf-8")
        print(f"{args.trials} trials of {args.duration:g} s at {args.rate:g} Hz written in {time.perf_counter() - t0:.0f} s; "
              f"methods {args.methods}, reports on")
        for name in args.runs.split(","):
            extra = ["--jobs", "2"] if name == "jobs" else ["--scheduler", "local:2"]
            out = root / f"out_{name}"
            wall = run(study, out, extra)
            walls, over = overheads(out)
            print(f"{name:>5} ({' '.join(extra)}): study wall {wall:.1f} s; per trial {statistics.median(walls):.2f} s "
                  f"median (worker time), of which outside the PF solver {statistics.median(over):.2f} s median; "
                  f"throughput {args.trials / wall:.2f} trials/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
