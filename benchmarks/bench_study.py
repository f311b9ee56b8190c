"""A study at scale: N simulated trials (default 100 of 25 s at 200 Hz, 1 mm noise, 10 mm soft-tissue
artefact; abduction and flexion alternating; 10 subjects x 10 trials), PF with the per-trial
report on, run by ``exubio study`` with the local process pool (--jobs 2) and with Dask
(--scheduler local:2). Prints the wall time of each run, the per-trial time and the per-trial
overhead outside the solver (trial wall time minus the PF solve time of its summary), and the CPU
time of the run (all its processes) per trial, and the time after the last trial's DONE.json
(the study's long tables, its report and files). ``--no-trial-reports``: the same study with
``report: false`` (no per-trial report and no study report; the tables and files stay).

Usage:
    python benchmarks/bench_study.py [--trials 100] [--duration 25] [--rate 200] [--methods pf]
           [--runs jobs,dask] [--keep DIR] [--no-trial-reports] [--breakdown N]

With --keep DIR the simulated trials are written once into DIR/data and reused by later runs with
the same --trials, --duration and --rate (writing 100 trials takes about a minute); the results of
each run (DIR/out_jobs, DIR/out_dask) are replaced, never resumed. --breakdown N (no study run):
where one worker's time goes, N trials run one after the other in this process as a study worker
runs them (the first two warm it up), CPU time per stage (median over the others).
"""
from __future__ import annotations

import argparse
import json
import logging
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial, write_simulated_trial


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


def run(study: Path, out: Path, extra: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``exubio study`` run; CPU: user + system time of the command and
    every process it waited for (the pool's or the local cluster's workers), steadier than the wall
    time when other jobs share the machine."""
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "exubio.cli", "-q", "study", str(study), "--out", str(out), *extra],
                       capture_output=True, text=True, encoding="utf-8")
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode not in (0, 1):
        print(p.stdout, p.stderr, file=sys.stderr)
        raise SystemExit(f"study run failed with exit code {p.returncode}")
    return wall, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


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


_STAGES = (("exubio.run.job", "read_trial", "read the trial"),
           ("exubio.run.pipeline", "read_trial", "read the trial"),
           ("exubio.run.pipeline", "prepare_targets", "prepare targets (thorax frame, cut-off, filter, splines)"),
           ("exubio.prep.filtering", "residual_cutoffs", "  of which the automatic cut-off"),
           ("exubio.run.pipeline", "stream_reconstruct", "reconstruction (PF)"),
           ("exubio.trust.assess", "trial_label_findings", "label checks"),
           ("exubio.trust.assess", "assess_trial", "assessment (determinacy, limits, verdict)"),
           ("exubio.run.pipeline", "write_outcome", "write the result files (angles, u, moments)"),
           ("exubio.report.trial_report", "draw_trial_report", "report (PDF + PNG)"))


def breakdown(trials: list[Path], out: Path, methods: tuple[str, ...]) -> None:
    """CPU time per stage of ``exubio.run.study.run_trial_task`` on each trial (the functions the
    pipeline calls, wrapped with timers), median over the trials after the first two."""
    import importlib

    from exubio.run.inputs import load_session
    from exubio.run.job import TrialJob
    from exubio.run.study import TrialTask, run_trial_task

    session = load_session()  # as a study does: once per session, carried by every job

    spent: dict[str, float] = {}

    def timed(fn, label):
        def call(*a, **k):
            t0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                spent[label] = spent.get(label, 0.0) + time.process_time() - t0
        return call

    for module, name, label in _STAGES:
        mod = importlib.import_module(module)
        setattr(mod, name, timed(getattr(mod, name), label))
    rows = []
    for k, trial in enumerate(trials):
        spent.clear()
        t0 = time.process_time()
        job = TrialJob(trial, out / f"t{k}", methods=methods, session=session, report=True)
        done = run_trial_task(TrialTask(subject="S", session="s", trial=str(trial), final_dir=str(out / f"t{k}"), job=job))
        if done.status != "done":
            raise SystemExit(f"{trial}: {done.error}")
        spent["whole trial"] = time.process_time() - t0
        if k >= 2:
            rows.append(dict(spent))
    print(f"CPU s per trial, median of {len(rows)} trials after 2 warm-up trials:")
    for label in dict.fromkeys([label for _, _, label in _STAGES] + ["whole trial"]):
        print(f"  {label:58s} {statistics.median(r.get(label, 0.0) for r in rows):6.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--duration", type=float, default=25.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--methods", default="pf", help="comma-separated: pf, ls (default pf)")
    ap.add_argument("--runs", default="jobs,dask", help="which runs: jobs (process pool, --jobs 2), dask (local:2)")
    ap.add_argument("--keep", help="write the trials and results here instead of a temporary folder")
    ap.add_argument("--no-trial-reports", action="store_true",
                    help="the study with report: false (no per-trial reports and no study report; its tables and files stay)")
    ap.add_argument("--breakdown", type=int, metavar="N",
                    help="instead of the study runs: CPU time per stage of N trials run one after the other here")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep or tmp)
        data = root / "data"
        t0 = time.perf_counter()
        made = {"trials": args.trials, "duration": args.duration, "rate": args.rate}
        marker = data / "bench_trials.json"
        if marker.is_file() and json.loads(marker.read_text(encoding="utf-8")) == made:
            sessions = yaml.safe_load((data / "study.yaml").read_text(encoding="utf-8"))["sessions"]
            study, written = data / "study.yaml", "reused"
        else:
            shutil.rmtree(data, ignore_errors=True)
            study, sessions = make_trials(data, args.trials, args.duration, args.rate)
            written = f"written in {time.perf_counter() - t0:.0f} s"
        study.write_text(yaml.safe_dump({"schema_version": 1, "name": "bench", "report": not args.no_trial_reports,
                                         "methods": args.methods.split(","), "sessions": sessions}), encoding="utf-8")
        marker.write_text(json.dumps(made), encoding="utf-8")
        print(f"{args.trials} trials of {args.duration:g} s at {args.rate:g} Hz {written}; "
              f"methods {args.methods}, per-trial reports {'off' if args.no_trial_reports else 'on'}")
        if args.breakdown:
            trials = sorted(data.rglob("*.c3d"))[: max(args.breakdown, 3)]
            breakdown(trials, root / "out_breakdown", tuple(args.methods.split(",")))
            return 0
        for name in args.runs.split(","):
            extra = ["--jobs", "2"] if name == "jobs" else ["--scheduler", "local:2"]
            out = root / f"out_{name}"
            shutil.rmtree(out, ignore_errors=True)  # a kept earlier result would be resumed, not run
            wall, cpu = run(study, out, extra)
            walls, over = overheads(out)
            done = max(p.stat().st_mtime for p in out.rglob("DONE.json"))
            tail = max(p.stat().st_mtime for p in out.iterdir() if p.is_file()) - done
            print(f"{name:>5} ({' '.join(extra)}): study wall {wall:.1f} s; per trial {statistics.median(walls):.2f} s "
                  f"median (worker time), of which outside the PF solver {statistics.median(over):.2f} s median; "
                  f"throughput {args.trials / wall:.2f} trials/s; CPU {cpu:.0f} s in all, {cpu / args.trials:.2f} s "
                  f"per trial; after the last trial (the study's table, report and files) {tail:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
