"""Where the per-trial CPU of the checks and the target preparation goes: the stages a study worker
runs around the reconstruction, on one simulated study trial, with a profile of each.

The trial is one of ``bench_study.py``'s (25 s at 200 Hz, abduction, 1 mm noise, 10 mm soft-tissue
artefact, seed 0), simulated in memory (no file). Its PF reconstruction is made once, untimed; the
stages are then run ``--runs`` times each, one after the other, as ``exubio.run.pipeline`` runs
them:

  prepare_targets     exubio.prep.targets.prepare_targets (thorax frame, automatic cut-off, filter, splines)
  partial_swaps       exubio.trust.label_ranges.find_partial_swaps (labels exchanged in part of the trial)
  label_checks        exubio.trust.assess.trial_label_findings (pair distances, side relations, chain fits)
  assessment          exubio.trust.assess.assess_trial (determinacy, angle status and uncertainty, limits,
                      mismatch, verdict) of the PF reconstruction

For each stage: the median CPU time per run in us per frame, and (``--top N``) the N functions of
its cProfile with the most own time, in us per frame (over ``--runs`` more runs, profiled; cProfile
adds its own cost per call, so read them as shares rather than timings). The process pins itself to one core and sets BLAS
threads to 1. It uses only functions that older checkouts have too: run it with another checkout
on PYTHONPATH to compare (``PYTHONPATH=../base python benchmarks/profile_checks.py``).

    python benchmarks/profile_checks.py                 # 5 runs per stage, top 8 functions
    python benchmarks/profile_checks.py --runs 9 --top 0
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: before numpy is imported

import argparse  # noqa: E402
import cProfile  # noqa: E402
import logging  # noqa: E402
import pstats  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

from bench_reconstruction import pin_to_one_core  # noqa: E402  (this folder: the script's own)


def _name(func: tuple) -> str:
    path, line, name = func
    if path == "~":
        return name  # a builtin: "<built-in method ...>" / "<method 'reduce' ...>"
    parts = path.replace("\\", "/").split("/")
    short = "/".join(parts[parts.index("exubio"):]) if "exubio" in parts else parts[-1]
    return f"{short}:{name}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5, help="timed runs per stage (median), default 5")
    ap.add_argument("--top", type=int, default=8, help="functions of each stage's profile to print, default 8")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    cpu = pin_to_one_core()

    import exubio
    from exubio.prep.targets import prepare_targets
    from exubio.run.inputs import load_session
    from exubio.run.pipeline import reconstruct
    from exubio.synth.simulate import simulate_trial
    from exubio.trust.assess import TrialContext, assess_trial, known_before_trials, trial_label_findings
    from exubio.trust.label_ranges import find_partial_swaps

    session = load_session()
    binding, expect = session.binding, session.generic_binding
    known_before_trials(binding, expect=expect)  # as a study does once per session
    sim = simulate_trial(binding.model, "abduction", duration_s=25.0, rate_hz=200.0, noise_mm=1.0, sta_mm=10.0, seed=0)
    traj = sim.trajectories
    targets = prepare_targets(traj, binding.protocol)
    recon = reconstruct(binding.model, binding.protocol, targets, method="pf")
    n = targets.n_frames
    stages = {
        "prepare_targets": lambda: prepare_targets(traj, binding.protocol),
        "partial_swaps": lambda: find_partial_swaps(traj, binding.protocol, binding.model),
        "label_checks": lambda: trial_label_findings(expect, targets),
        "assessment": lambda: assess_trial(binding, targets, [recon], context=TrialContext()),
    }
    print(f"exubio from {os.path.dirname(exubio.__file__)}; {n} frames; CPU {cpu}; median of {args.runs} runs")
    total = 0.0
    for name, run in stages.items():
        run()  # warm: compiled kernels, caches
        times = []
        for _ in range(args.runs):
            c0 = time.process_time()
            run()
            times.append(time.process_time() - c0)
        us = statistics.median(times) / n * 1e6
        total += us
        print(f"{name:16s} {us:7.1f} us/frame  ({statistics.median(times) * 1e3:.0f} ms per trial)")
        if args.top:
            prof = cProfile.Profile()
            prof.enable()
            for _ in range(args.runs):
                run()
            prof.disable()
            st = pstats.Stats(prof).stats
            rows = sorted(((tt, nc, _name(f)) for f, (_, nc, tt, _, _) in st.items()), reverse=True)[: args.top]
            for tt, nc, fname in rows:
                print(f"    {tt / args.runs / n * 1e6:7.1f} us/frame  {nc // args.runs:6d} calls  {fname}")
    print(f"{'in all':16s} {total:7.1f} us/frame")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
