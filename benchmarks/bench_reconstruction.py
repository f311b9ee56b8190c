"""Benchmark of the reconstruction methods on a simulated abduction trial.

Simulates 25 s of arm abduction at 200 Hz (5000 frames; Ludewig rhythm, exubio.synth.simulate) with
1.5 mm Gaussian marker noise, runs the real pipeline (prepare_targets: thorax frame, 2 Hz
low-pass, spline derivatives; then pipeline.reconstruct) with every method and prints one JSON
line per method to stdout and a small table to stderr.

Timing: the reconstruction call alone (PF: static equilibrium, building the Exudyn system,
integration, angle recovery, constraint projection, residuals; LS: the same outputs), median of
``--runs`` runs, on one core (the process is pinned to one CPU and BLAS/OpenMP threads are set
to 1 before numpy loads). Simulation and target preparation are not timed.

JSON fields (all methods): method, n_frames, duration_s, rate_hz, noise_mm, seed,
ms_per_frame (median wall time), ms_per_frame_runs, cpu_ms_per_frame (median CPU time of the
process: robust against other load on a shared machine), joint_rmse_deg {coordinate: RMSE against the truth},
max_joint_rmse_deg, mean_residual_mm, max_abs_g, max_abs_G_qd (1/s), consistency (q̇ against
the central difference of q and q̈ against that of q̇ over the interior frames after the first
0.1 s start-up: max and 99th percentile of the largest coordinate error per frame, absolute and
relative to max |q̇| / |q̈|). PF only: pf_ls_rmse_deg {coordinate: RMSE PF vs LS},
time_breakdown (Exudyn's CPU timers as fractions of its solve; ``wall`` holds the
reconstruction's own phases as fractions of its total), exudyn_max_abs_g / exudyn_max_abs_G_qd
(Exudyn's constraint residuals before the final projection), step_s, newton_iterations_per_step,
jacobian_updates_per_step.

The shipped protocol holds the clavicle's axial rotation (its two markers barely see it); the
simulated clavicle rotates by Ludewig's rhythm, so the held coordinate and the AC angles that absorb
it are reported apart (``max_joint_rmse_deg_measured`` leaves them out; ``--no-hold`` solves every
coordinate, the methods' own accuracy). ``checks_ms_per_frame``: what the trust checks cost on top
(label checks, determinacy, range limits, verdict: exubio.trust.assess), median of the runs.

Usage:
    python benchmarks/bench_reconstruction.py            # 25 s, 200 Hz, 1.5 mm noise, 3 runs
    python benchmarks/bench_reconstruction.py --no-hold  # every coordinate solved
    python benchmarks/bench_reconstruction.py --quick    # 5 s, 1 run
    python benchmarks/bench_reconstruction.py --noise-mm 0 --methods pf
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: before numpy is imported

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from exubio.run.pipeline import reconstruct  # noqa: E402
from exubio.run.inputs import load_model_and_protocol  # noqa: E402
from exubio.prep.targets import prepare_targets  # noqa: E402
from exubio.synth.simulate import Motion, simulate_trial  # noqa: E402

START_UP_S = 0.1  # the stiff spring-damper mode of the PF start settles within ~0.05 s


def pin_to_one_core() -> int | None:
    """Pin this process to one CPU (Linux); returns its number or None where unsupported."""
    try:
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return cpu
    except (AttributeError, OSError):
        return None


def rmse_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.sqrt(np.nanmean((a - b) ** 2, axis=0)))


def consistency(time_s: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, /, *,
                start_up_s: float = START_UP_S) -> dict[str, float]:
    """q̇ against the central difference of q, q̈ against that of q̇ (interior frames after the
    start-up): per frame the largest coordinate error; max and 99th percentile, absolute (rad/s,
    rad/s^2) and relative to max |q̇| resp. max |q̈|."""
    dt = float(np.median(np.diff(time_s)))
    k0 = max(1, int(round(start_up_s / dt)))
    out: dict[str, float] = {}
    for name, x, dx in (("qd", q, qd), ("qdd", qd, qdd)):
        fd = (x[2:] - x[:-2]) / (2 * dt)
        err = np.abs(dx[1:-1] - fd)[k0 - 1:].max(axis=1)
        scale = float(np.abs(dx).max())
        out[f"{name}_max"] = float(err.max())
        out[f"{name}_p99"] = float(np.quantile(err, 0.99))
        out[f"{name}_max_rel"] = float(err.max() / scale) if scale > 0 else float("nan")
        out[f"{name}_p99_rel"] = float(np.quantile(err, 0.99) / scale) if scale > 0 else float("nan")
    return out


def run_method(method: str, model, protocol, targets, runs: int):
    """The last reconstruction, and the wall and CPU times of every run (s)."""
    wall, cpu, recon = [], [], None
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        recon = reconstruct(model, protocol, targets, method=method)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return recon, wall, cpu


def pf_breakdown(recon) -> dict[str, Any]:
    cpu = dict(recon.info.get("exudyn_cpu_times_s", {}))
    total = cpu.pop("total", 0.0) or sum(cpu.values())
    fractions = {k: round(v / total, 4) for k, v in cpu.items() if total > 0 and v > 0}
    wall = dict(recon.timings_s)
    wall_total = wall.pop("total", 0.0) or sum(wall.values())
    fractions["wall"] = {k: round(v / wall_total, 4) for k, v in wall.items() if wall_total > 0}
    return fractions


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="5 s trial, 1 run")
    ap.add_argument("--duration", type=float, default=25.0, help="trial length (s), default 25")
    ap.add_argument("--rate", type=float, default=200.0, help="sampling rate (Hz), default 200")
    ap.add_argument("--noise-mm", type=float, default=1.5, help="marker noise SD (mm), default 1.5")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--runs", type=int, default=3, help="timed runs per method (median), default 3")
    ap.add_argument("--methods", default="pf,ls", help="comma-separated, default pf,ls")
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    ap.add_argument("--no-hold", action="store_true", help="solve every coordinate (ignore the protocol's hold)")
    args = ap.parse_args(argv)
    if args.quick:
        args.duration, args.runs = 5.0, 1
    logging.basicConfig(level=logging.WARNING)
    cpu = None if args.no_pin else pin_to_one_core()

    model, protocol = load_model_and_protocol()
    if args.no_hold:
        protocol = dataclasses.replace(protocol, held_coordinates=())
    held = set(protocol.held_coordinates)
    held_segments = {seg.name for seg in model.segments if seg.joint and held & set(seg.joint.coordinates)}
    not_measured = held | {c for seg in model.segments if seg.parent in held_segments and seg.joint
                           for c in seg.joint.coordinates}
    trial = simulate_trial(model, Motion.ABDUCTION, duration_s=args.duration, rate_hz=args.rate,
                           noise_mm=args.noise_mm, seed=args.seed)
    t0 = time.perf_counter()
    targets = prepare_targets(trial.trajectories, protocol)
    prep_s = time.perf_counter() - t0
    n = targets.n_frames
    names = model.coordinate_names
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]

    results: dict[str, Any] = {}
    rows = []
    for method in methods:
        recon, times, cpu_times = run_method(method, model, protocol, targets, args.runs)
        results[method] = recon
        rm = rmse_deg(recon.q_rad, trial.q_true)
        with np.errstate(all="ignore"):
            mean_res = float(np.nanmean(recon.residuals_m)) * 1e3
        rec: dict[str, Any] = {
            "method": method,
            "n_frames": int(n),
            "duration_s": args.duration,
            "rate_hz": args.rate,
            "noise_mm": args.noise_mm,
            "seed": args.seed,
            "cpu": cpu,
            "ms_per_frame": statistics.median(times) / n * 1e3,
            "ms_per_frame_runs": [t / n * 1e3 for t in times],
            "cpu_ms_per_frame": statistics.median(cpu_times) / n * 1e3,
            "prepare_targets_ms_per_frame": prep_s / n * 1e3,
            "joint_rmse_deg": {c: round(float(v), 5) for c, v in zip(names, rm)},
            "max_joint_rmse_deg": float(rm.max()),
            "max_joint_rmse_deg_measured": float(max(v for c, v in zip(names, rm) if c not in not_measured)),
            "not_measured": sorted(not_measured),
            "mean_residual_mm": mean_res,
            "max_abs_g": float(np.abs(recon.constraint).max()),
            "max_abs_G_qd": float(np.abs(recon.constraint_velocity).max()),
            "consistency": consistency(recon.time_s, recon.q_rad, recon.qd_rad_s, recon.qdd_rad_s2),
        }
        if method == "pf":
            info = recon.info
            rec["pf_ls_rmse_deg"] = None
            rec["time_breakdown"] = pf_breakdown(recon)
            for key in ("step_s", "newton_iterations_per_step", "jacobian_updates_per_step",
                        "exudyn_max_abs_g", "exudyn_max_abs_G_qd"):
                rec[key] = info.get(key)
        rows.append(rec)

    if "pf" in results:
        ls = results.get("ls")
        if ls is None:
            ls = run_method("ls", model, protocol, targets, 1)[0]
        pf_ls = rmse_deg(results["pf"].q_rad, ls.q_rad)
        for rec in rows:
            if rec["method"] == "pf":
                rec["pf_ls_rmse_deg"] = {c: round(float(v), 5) for c, v in zip(names, pf_ls)}

    if len(results) == len(methods) and results:
        from exubio.protocol.bind import bind
        from exubio.trust.assess import TrialContext, assess_trial, trial_label_findings

        check_times = []
        binding = bind(model, protocol)  # a session's: what it holds is computed in the first run, kept after
        for _ in range(args.runs):
            t0 = time.perf_counter()
            findings = trial_label_findings(binding, targets)
            assessment = assess_trial(binding, targets, list(results.values()),
                                      context=TrialContext(label_findings=tuple(findings)))
            check_times.append(time.perf_counter() - t0)
        for rec in rows:
            rec["checks_ms_per_frame"] = statistics.median(check_times) / n * 1e3
            rec["verdict"] = assessment.quality[rec["method"]].verdict

    for rec in rows:
        print(json.dumps(rec), flush=True)

    err = sys.stderr
    print(f"\n{args.duration:g} s abduction at {args.rate:g} Hz ({n} frames), noise {args.noise_mm:g} mm, "
          f"seed {args.seed}, median of {args.runs} run(s){'' if cpu is None else f', CPU {cpu}'}", file=err)
    print(f"{'method':6s} {'ms/frame':>9s} {'cpu ms/f':>9s} {'max RMSE':>9s} {'measured':>9s} {'residual':>9s} {'max|g|':>9s} {'max|Gqd|':>9s} "
          f"{'qd cons.':>9s} {'qdd cons.':>9s}", file=err)
    print(f"{'':6s} {'':>9s} {'':>9s} {'(deg)':>9s} {'(deg)':>9s} {'(mm)':>9s} {'':>9s} {'(1/s)':>9s} {'(p99 rel)':>9s} {'(p99 rel)':>9s}", file=err)
    for rec in rows:
        c = rec["consistency"]
        print(f"{rec['method']:6s} {rec['ms_per_frame']:9.3f} {rec['cpu_ms_per_frame']:9.3f} {rec['max_joint_rmse_deg']:9.3f} "
              f"{rec['max_joint_rmse_deg_measured']:9.3f} "
              f"{rec['mean_residual_mm']:9.3f} {rec['max_abs_g']:9.1e} {rec['max_abs_G_qd']:9.1e} "
              f"{c['qd_p99_rel']:9.1e} {c['qdd_p99_rel']:9.1e}", file=err)
    if rows and "checks_ms_per_frame" in rows[0]:
        print(f"trust checks: {rows[0]['checks_ms_per_frame']:.3f} ms/frame; verdicts "
              + ", ".join(f"{r['method']} {r['verdict']}" for r in rows)
              + (f"; not measured: {', '.join(rows[0]['not_measured'])}" if rows[0]["not_measured"] else ""), file=err)
    for rec in rows:
        if rec["method"] == "pf" and rec.get("pf_ls_rmse_deg"):
            worst = max(rec["pf_ls_rmse_deg"].items(), key=lambda kv: kv[1])
            tb = {k: v for k, v in rec["time_breakdown"].items() if k != "wall" and v >= 0.05}
            print(f"PF vs LS: max RMSE {worst[1]:.3f} deg ({worst[0]}); Exudyn time: "
                  + ", ".join(f"{k} {v:.0%}" for k, v in sorted(tb.items(), key=lambda kv: -kv[1])), file=err)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
