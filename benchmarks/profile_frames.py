"""Where the time of a frame goes: per-stage timers around the functions a batch PF, a batch LS and a
live frame call.

Each stage is a set of functions wrapped (for this process only) by a timer that counts its own
CPU time (the thread's), the time of the stages it calls excluded; "other" is what no stage holds
(the loop's own Python). The timers cost about 1 us per call: the table gives each stage's share
of the timed run, applied to the CPU time per frame of untimed runs of the same work (median). The live frame is the live loop run on an in-process replay (``reconstruct_causal``,
exubio.run.live.offline: no LSL); what LSL adds is the live process's CPU per frame in
``bench_live.py`` minus this loop's. For the live loop it also prints the wall time between two
published frames of the untimed runs (p50, p99, max): the lumps a frame can be held by (a garbage
collection, the deferred checks), without LSL or another process.

    python benchmarks/profile_frames.py                  # PF, LS and live on 25 s / 10 s at 200 Hz
    python benchmarks/profile_frames.py --modes live --rate 1000 --duration 5
    python benchmarks/profile_frames.py --json out.json
    python benchmarks/profile_frames.py --modes pf live --solver-timers   # + Exudyn's own timers per frame

``--solver-timers``: one more run of PF and of the live loop with Exudyn's timers on (its
``computationTime``): per frame, the steps, the Newton iterations and Jacobian updates per step, the
native time (the solver's total less its Python step functions) and the time in the step functions
(the pre- and post-step: in the live loop that is the whole frame's Python but the intake's wait).

The process pins itself to one core and sets BLAS threads to 1 (as bench_reconstruction.py).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: before numpy is imported

import argparse  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SETUP = "set-up before the first sample (binding, check tables)"  # live: once a session, not a frame's
# (module, attribute path, stage) per mode; a stage's time excludes the stages it calls
STAGES = {
    "pf": [
        ("exubio.methods.pf", "pf_setup", "start: LS pose, build the Exudyn system"),
        ("exubio.backend.exudyn_integrate", "Integration.solve", "Exudyn's steps (native)"),
        ("exubio.backend.exudyn_integrate", "_TrialRun.pre_step", "prestep (spring targets, limits)"),
        ("exubio.backend.exudyn_integrate", "_TrialRun.post_step", "post-step (state record)"),
        ("exubio.backend.exudyn_integrate", "frames_from_steps", "frames from the steps (quintic)"),
        ("exubio.backend.exudyn_system", "PFSystem._decode", "decode the segment motion"),
        ("exubio.methods.pf", "_Frames.coordinates", "inverse map to q"),
        ("exubio.methods.pf", "_Frames.rates", "rates and the projection"),
        ("exubio.model.kinematics", "Kinematics.coordinate_rates", "rates and the projection"),
        ("exubio.methods.pf", "_Frames._project", "rates and the projection"),
        ("exubio.methods.pf", "_Frames.finish", "model points, residuals, g, checks"),
    ],
    "ls": [
        ("exubio.methods.poses", "_linearise", "LS: residuals and Jacobians"),
        ("exubio.methods.lsq", "damped_step", "LS: the damped step (solve)"),
        ("exubio.methods.poses", "project_on_constraints", "projection on the constraints"),
        ("exubio.methods.ls", "solve_rates", "rates (q̇, q̈)"),
        ("exubio.methods.ls", "assemble", "model points, residuals, g"),
    ],
    "live": [
        ("exubio.run.live.loop", "LiveSession._bind", SETUP),
        ("exubio.run.live.intake", "SampleIntake.next_raw", "sample intake (replay source)"),
        ("exubio.run.live.causal", "CausalTargets.push", "causal targets (thorax frame, rates)"),
        ("exubio.backend.exudyn_integrate", "Integration.solve", "Exudyn's step (native)"),
        ("exubio.backend.exudyn_live", "_LiveRun.pre_step", "prestep (spring targets, limits)"),
        ("exubio.backend.exudyn_live", "_LiveRun.fetch", "prestep (spring targets, limits)"),
        ("exubio.backend.exudyn_live", "_LiveRun.post_step", "post-step (state, interpolation)"),
        ("exubio.backend.exudyn_system", "PFSystem._decode", "decode the segment motion"),
        ("exubio.backend.exudyn_system", "PFSystem._decode_frame", "decode the segment motion"),
        ("exubio.methods.pf", "_Frames.coordinates", "inverse map to q"),
        ("exubio.run.live.frame", "LiveFrame.coordinates", "inverse map to q"),
        ("exubio.run.live.frame", "LiveFrame.outputs", "angles, model points, residuals (compiled)"),
        ("exubio.run.live.loop", "LiveSession._publish", "outputs (model points, residuals, row)"),
        ("exubio.run.live.monitor", "LiveMonitor.diverged", "checks (per frame)"),
        ("exubio.run.live.monitor", "LiveMonitor.label_check", "checks (per frame)"),
        ("exubio.run.live.monitor", "LiveMonitor.track_gaps", "checks (per frame)"),
        ("exubio.run.live.monitor", "LiveMonitor.determinacy", "checks (deferred: determinacy, running)"),
        ("exubio.run.live.monitor", "LiveMonitor.running", "checks (deferred: determinacy, running)"),
        ("exubio.run.live.monitor", "LiveMonitor.verdict", "checks (deferred: determinacy, running)"),
        ("exubio.run.live.loop", "LiveSession._flush", "deferred: rates, g, model points (a batch of frames)"),
        ("exubio.run.live.loop", "LiveSession._record_outputs", "record"),
        ("exubio.run.live.loop", "LiveSession._frames_done", "record"),
        ("exubio.run.live.loop", "LiveSession._record_input", "record"),
    ],
}


class Timers:
    def __init__(self):
        self.own = defaultdict(float)
        self.calls = defaultdict(int)
        self.stack: list[list] = []  # [stage, start, time of the stages called]

    def wrap(self, fn, stage: str):
        clock = time.thread_time  # CPU time of this thread: a shared machine's other jobs do not count

        def timed(*args, **kwargs):
            entry = [stage, clock(), 0.0]
            self.stack.append(entry)
            try:
                return fn(*args, **kwargs)
            finally:
                self.stack.pop()
                total = clock() - entry[1]
                self.own[stage] += total - entry[2]
                self.calls[stage] += 1
                if self.stack:
                    self.stack[-1][2] += total

        timed.__wrapped__ = fn
        return timed


def install(mode: str, timers: Timers) -> list:
    undo = []
    for module, path, stage in STAGES[mode]:
        mod = importlib.import_module(module)
        *owners, name = path.split(".")
        obj = mod
        for o in owners:
            obj = getattr(obj, o)
        fn = obj.__dict__[name] if isinstance(obj, type) else getattr(obj, name)
        setattr(obj, name, timers.wrap(fn, stage))
        undo.append((obj, name, fn))
    return undo


def uninstall(undo: list) -> None:
    for obj, name, fn in reversed(undo):
        setattr(obj, name, fn)


def batch_inputs(duration_s: float, rate_hz: float, noise_mm: float):
    from exubio.prep.targets import prepare_targets
    from exubio.run.inputs import load_model_and_protocol
    from exubio.synth.simulate import Motion, simulate_trial

    model, protocol = load_model_and_protocol()
    trial = simulate_trial(model, Motion.parse("abduction"), duration_s=duration_s, rate_hz=rate_hz,
                           noise_mm=noise_mm, sta_mm=0.0, seed=1)
    return model, protocol, prepare_targets(trial.trajectories, protocol)


def live_inputs(duration_s: float, rate_hz: float):
    from exubio.run.inputs import load_model_and_protocol
    from exubio.synth.simulate import Motion, simulate_trial
    from exubio.types import Trajectories

    model, protocol = load_model_and_protocol()
    trial = simulate_trial(model, Motion.parse("abduction"), duration_s=duration_s, rate_hz=rate_hz, noise_mm=0.5,
                           sta_mm=0.0, seed=1)
    t = trial.trajectories
    keep = [i for i, lab in enumerate(t.labels) if lab != "ELB"]  # the 21-marker set of bench_live.py
    return model, protocol, Trajectories(labels=tuple(t.labels[i] for i in keep), positions_m=t.positions_m[:, keep],
                                         rate_hz=t.rate_hz, time_s=t.time_s, source="profile")


def profile(mode: str, args) -> dict:
    import numpy as np

    gaps: list = []
    loop_cpu: list = []  # live: the loop's own CPU of each run (the session's set-up excluded), s
    if mode == "live":
        from exubio.run.live.offline import reconstruct_causal

        model, protocol, trial = live_inputs(args.live_duration, args.rate)
        n = trial.n_frames

        def work():
            rec = reconstruct_causal(trial, model, protocol)
            loop_cpu.append(rec.stats["cpu_ms_per_frame"] * 1e-3 * n)  # the loop's CPU per frame stepped, from the first sample on
            pub = rec.published_s[np.isfinite(rec.published_s)]
            gaps.append(np.diff(pub) * 1e3)  # the loop's wall time from one published frame to the next, ms
    else:
        from exubio.run.pipeline import reconstruct

        model, protocol, targets = batch_inputs(args.duration, args.rate, args.noise_mm)
        n = targets.n_frames

        def work():
            reconstruct(model, protocol, targets, method=mode)
    work()  # warm: caches, imports
    cpu = []
    for _ in range(args.runs):
        c0 = time.process_time()
        work()
        cpu.append(time.process_time() - c0)
    whole = list(cpu)
    if loop_cpu:  # live: per frame from the first sample on, as the loop records it (bench_live's figure)
        cpu = loop_cpu[1:1 + args.runs]
    timers = Timers()
    undo = install(mode, timers)
    try:
        t0 = time.thread_time()
        work()
        timed = time.thread_time() - t0
    finally:
        uninstall(undo)
    cpu_ms = 1e3 * statistics.median(cpu) / n
    setup = timers.own.pop(SETUP, 0.0)  # live: the session's set-up, reported apart
    timers.calls.pop(SETUP, None)
    timed -= setup
    held = sum(timers.own.values())
    rows = {stage: timers.own[stage] / timed for stage in timers.own}
    rows["other (the loop's own Python)"] = max(timed - held, 0.0) / timed
    lumps = None
    if gaps:  # the untimed runs (the first, warming, left out): how long the longest frames hold the loop
        d = np.concatenate(gaps[1:1 + args.runs])
        lumps = {"p50_ms": float(np.percentile(d, 50)), "p99_ms": float(np.percentile(d, 99)),
                 "p999_ms": float(np.percentile(d, 99.9)), "max_ms": float(d.max()), "over_2_ms": int((d > 2).sum())}
    return {"mode": mode, "frames": n, "lumps": lumps, "cpu_ms_per_frame": cpu_ms, "cpu_ms_per_frame_runs": [1e3 * c / n for c in cpu],
            "whole_run_ms_per_frame": 1e3 * statistics.median(whole) / n, "setup_s": setup,
            "timed_ms_per_frame": 1e3 * timed / n,
            "stages": {s: {"share": f, "us_per_frame": 1e3 * f * cpu_ms, "calls_per_frame": timers.calls.get(s, 0) / n}
                       for s, f in sorted(rows.items(), key=lambda kv: -kv[1])}}


def solver_timers(mode: str, args) -> dict:
    """One run of ``mode`` (pf or live) with Exudyn's timers on: per frame (us) its native solver time
    and its step functions' (Exudyn's 'python' timer), and the steps, Newton iterations and Jacobian
    updates."""
    import numpy as np

    from exubio.backend import exudyn_integrate as integrate
    from exubio.backend import exudyn_live as live

    solvers = []
    settings_of, solve = integrate.solver_settings, integrate.Integration.solve

    def timed_settings(*a, **k):
        s = settings_of(*a, **k)
        s.show.computationTime = True
        return s

    def capturing_solve(self, settings, step_s):
        out = solve(self, settings, step_s)
        solvers.append(out[0])
        return out

    integrate.solver_settings = live.solver_settings = timed_settings
    integrate.Integration.solve = capturing_solve
    try:
        if mode == "live":
            from exubio.run.live.offline import reconstruct_causal

            model, protocol, trial = live_inputs(args.live_duration, args.rate)
            n = trial.n_frames
            reconstruct_causal(trial, model, protocol)
        else:
            from exubio.run.pipeline import reconstruct

            model, protocol, targets = batch_inputs(args.duration, args.rate, args.noise_mm)
            n = targets.n_frames
            reconstruct(model, protocol, targets, method="pf")
    finally:
        integrate.solver_settings = live.solver_settings = settings_of
        integrate.Integration.solve = solve
    total = sum(float(s.timer.total) for s in solvers)
    python = sum(float(s.timer.python) for s in solvers)
    steps = sum(int(s.it.currentStepIndex) for s in solvers)
    newton = sum(int(s.it.newtonStepsCount) for s in solvers)
    jac = sum(int(s.it.newtonJacobiCount) for s in solvers)
    return {"steps_per_frame": steps / n, "newton_per_step": newton / max(steps, 1), "jacobians_per_step": jac / max(steps, 1),
            "native_us_per_frame": 1e6 * (total - python) / n, "step_functions_us_per_frame": 1e6 * python / n,
            "native_us_per_step": 1e6 * (total - python) / max(steps, 1), "frames": int(n), "load": float(np.round(os.getloadavg()[0], 2))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--modes", nargs="+", default=["pf", "ls", "live"], choices=["pf", "ls", "live"])
    ap.add_argument("--duration", type=float, default=25.0, help="batch trial length (s), default 25")
    ap.add_argument("--live-duration", type=float, default=10.0, help="live trial length (s), default 10")
    ap.add_argument("--rate", type=float, default=200.0, help="frame rate (Hz), default 200")
    ap.add_argument("--noise-mm", type=float, default=1.5)
    ap.add_argument("--runs", type=int, default=3, help="untimed runs for the CPU per frame (median)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--solver-timers", action="store_true", help="also a run of pf and live with Exudyn's timers on")
    args = ap.parse_args(argv)
    try:
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
    except (AttributeError, OSError):
        cpu = None
    out = []
    for mode in args.modes:
        res = profile(mode, args)
        res["load_average"] = os.getloadavg()
        out.append(res)
        print(f"\n{mode}: {res['frames']} frames at {args.rate:g} Hz, CPU {res['cpu_ms_per_frame'] * 1e3:.1f} us/frame "
              f"(median of {args.runs}; runs {', '.join(f'{x * 1e3:.1f}' for x in res['cpu_ms_per_frame_runs'])}), "
              f"timed run {res['timed_ms_per_frame'] * 1e3:.1f} us/frame; core {cpu}; "
              f"load {' '.join(f'{x:.2f}' for x in res['load_average'])}")
        if mode == "live":
            print(f"  the session's set-up before the first sample: {res['setup_s'] * 1e3:.0f} ms of CPU (timed run), "
                  f"excluded above; the whole run with it {res['whole_run_ms_per_frame'] * 1e3:.1f} us/frame")
        if res["lumps"]:
            lu = res["lumps"]
            print(f"  wall time between published frames (untimed runs, ms): p50 {lu['p50_ms']:.3f}, p99 {lu['p99_ms']:.3f}, "
                  f"p99.9 {lu['p999_ms']:.3f}, max {lu['max_ms']:.1f}; {lu['over_2_ms']} over 2 ms")
        print(f"  {'stage':<52} {'us/frame':>9} {'share':>7} {'calls/frame':>12}")
        for stage, row in res["stages"].items():
            print(f"  {stage:<52} {row['us_per_frame']:9.1f} {100 * row['share']:6.1f}% {row['calls_per_frame']:12.2f}")
        if args.solver_timers and mode in ("pf", "live"):
            t = res["solver_timers"] = solver_timers(mode, args)
            print(f"  Exudyn's timers (one more run, load {t['load']:.2f}): {t['steps_per_frame']:.2f} steps per frame, "
                  f"{t['newton_per_step']:.2f} Newton iterations and {t['jacobians_per_step']:.2f} Jacobian updates per step; "
                  f"native {t['native_us_per_frame']:.1f} us/frame ({t['native_us_per_step']:.1f} per step), "
                  f"in the step functions {t['step_functions_us_per_frame']:.1f} us/frame")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
