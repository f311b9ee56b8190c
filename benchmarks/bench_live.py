"""End-to-end latency of ``exubio live``: a marker sample's push to the arrival of its angles.

A simulated 21-marker abduction trial (the 21-marker C3D set: ELB left out) is sent on LSL from
this process (a sender thread pushing each frame at its time and noting the LSL clock of the push);
``exubio live`` runs as a separate process pinned to one core (``taskset -c CORE``); a receiver
thread here pulls its output stream and notes the LSL clock at each sample's arrival. Latency =
arrival - push, per frame (the same clock: one machine). Everything stays on 127.0.0.1 (the
loopback lsl_api.cfg of exubio.run.live.transport, used by both processes).

Figures: p50 / p99 / max latency over the run, frames that never arrived, and the live process's
own summary (frames skipped when it fell behind, its CPU time per frame). A rate "keeps up" when no
frame was skipped and the median latency after the first 2 s stays below KEEPS_UP_MS (10 ms). The machine is shared: the load
average during a run is printed with it (the figures of a loaded machine are its, not exubio's).

    python benchmarks/bench_live.py                      # 60 s at 200 Hz, then 1000 Hz
    python benchmarks/bench_live.py --rates 200 400 600 --duration 20 --runs 3
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np


KEEPS_UP_MS = 10.0
"""A rate is kept up with when no frame is skipped and, after the first 2 s, the median latency stays
below this: the solver is not queueing frames (a backlog shows as a median of tens to hundreds of ms)."""


def simulated_trial(rate_hz: float, duration_s: float):
    from exubio.model.load import load_model
    from exubio.synth.simulate import Motion, simulate_trial
    from exubio.types import Trajectories

    trial = simulate_trial(load_model(), Motion.parse("abduction"), duration_s=duration_s, rate_hz=rate_hz,
                           noise_mm=0.5, sta_mm=0.0, seed=1)
    t = trial.trajectories
    keep = [i for i, lab in enumerate(t.labels) if lab != "ELB"]
    return Trajectories(labels=tuple(t.labels[i] for i in keep), positions_m=t.positions_m[:, keep], rate_hz=t.rate_hz,
                        time_s=t.time_s, source="bench")


def run_once(trial, *, core: int | None, out: Path, tag: str) -> dict:
    from exubio.run.live.transport import ReplayOutlet, load_pylsl

    lsl = load_pylsl("loopback")
    name = f"bench_markers_{tag}"
    pub = f"bench_angles_{tag}"
    n = trial.n_frames
    push = np.full(n, np.nan)
    arrive = np.full(n, np.nan)
    cmd = [sys.executable, "-m", "exubio.cli", "live", "--stream", name, "--publish", pub, "--out", str(out),
           "--name", tag, "--no-report", "--end-after", "3", "--timeout", "60", "-q"]  # (a loaded machine resolves slowly)
    if core is not None and shutil.which("taskset"):
        cmd = ["taskset", "-c", str(core)] + cmd
    env = dict(os.environ, LSLAPICFG=os.environ["LSLAPICFG"])
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    outlet = ReplayOutlet(trial.labels, trial.rate_hz, name=name, units="mm", source_id=name)
    stop = threading.Event()
    connected = threading.Event()

    def receive():
        # the output stream appears with the first frame; resolve it while frames go
        inlet = None
        deadline = time.time() + 60
        while inlet is None and time.time() < deadline and not stop.is_set():
            res = lsl.resolve_byprop("name", pub, minimum=1, timeout=0.5)
            if res:
                inlet = lsl.StreamInlet(res[0], max_buflen=30)
                inlet.open_stream(timeout=5)
        labels = []
        ch = inlet.info(timeout=5).desc().child("channels").child("channel")
        while not ch.empty():
            labels.append(ch.child_value("label"))
            ch = ch.next_sibling("channel")
        col = labels.index("frame")
        connected.set()
        while not stop.is_set():
            s, _ = inlet.pull_sample(timeout=0.2)
            if s is None:
                continue
            t = lsl.local_clock()
            i = int(s[col])
            if 0 <= i < n:
                arrive[i] = t

    rx = threading.Thread(target=receive, daemon=True)
    rx.start()  # the output stream appears before live takes its first sample: connect to it first
    if not connected.wait(60) or not outlet.wait_for_consumer(60):
        proc.kill()
        out_, err_ = proc.communicate()
        raise RuntimeError(f"exubio live did not connect: {err_[-2000:]}")

    def noted(i, clock):
        push[i] = clock

    outlet.send(trial.positions_m, speed=1.0, on_sample=noted)
    time.sleep(1.0)
    stop.set()
    rx.join(5)
    try:
        stdout, stderr = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        stdout, stderr = proc.communicate()
    outlet.close()
    lat = (arrive - push) * 1e3
    got = np.isfinite(lat)
    live = json.loads((out / tag / f"{tag}.live.json").read_text()) if (out / tag / f"{tag}.live.json").is_file() else {}
    fig = live.get("figures", {})
    first_after = int(round(2.0 * trial.rate_hz))  # the start-up backlog (2 s of catch-up) is left out too
    steady = got.copy()
    steady[:first_after] = False
    return {
        "rate_hz": trial.rate_hz, "frames": n, "markers": len(trial.labels), "arrived": int(got.sum()),
        "first_arrived": int(np.argmax(got)) if got.any() else None,
        "last_arrived": int(n - 1 - np.argmax(got[::-1])) if got.any() else None,
        "p50_ms": float(np.percentile(lat[got], 50)) if got.any() else None,
        "p99_ms": float(np.percentile(lat[got], 99)) if got.any() else None,
        "max_ms": float(lat[got].max()) if got.any() else None,
        "steady_p99_ms": float(np.percentile(lat[steady], 99)) if steady.any() else None,
        "skipped": fig.get("skipped"), "dropped": fig.get("dropped"), "runs": fig.get("runs"),
        "cpu_ms_per_frame": fig.get("cpu_ms_per_frame"),
        "keeps_up": bool(fig.get("skipped") == 0 and steady.any() and np.percentile(lat[steady], 50) < KEEPS_UP_MS),
        "exit": proc.returncode, "stderr_tail": stderr.strip().splitlines()[-3:] if proc.returncode else [],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", type=float, nargs="+", default=[200.0, 1000.0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--core", type=int, default=1, help="the core exubio live is pinned to (-1: not pinned)")
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)
    from exubio.run.live.transport import use_config

    use_config("loopback")
    rows = []
    with tempfile.TemporaryDirectory(prefix="exubio-bench-live-") as tmp:
        for rate in args.rates:
            trial = simulated_trial(rate, args.duration)
            for r in range(args.runs):
                load = os.getloadavg()[0]
                row = run_once(trial, core=None if args.core < 0 else args.core, out=Path(tmp),
                               tag=f"r{int(rate)}_{r}_{os.getpid()}")
                row["load_before"] = load
                row["load_after"] = os.getloadavg()[0]
                rows.append(row)
                print(f"{rate:6.0f} Hz run {r + 1} (load average {load:.1f} -> {row['load_after']:.1f}): {row['markers']} markers, {row['arrived']}/{row['frames']} frames "
                      f"arrived; latency p50 {row['p50_ms']:.2f} ms, p99 {row['p99_ms']:.2f} ms, max {row['max_ms']:.1f} ms "
                      f"(after the first 2 s: p99 {row['steady_p99_ms']:.2f} ms); skipped {row['skipped']}, "
                      f"PF runs {row['runs']}; live CPU {row['cpu_ms_per_frame'] or float('nan'):.2f} ms/frame: "
                      f"{'keeps up' if row['keeps_up'] else 'does NOT keep up'}", flush=True)
    for rate in args.rates:
        rs = [r for r in rows if r["rate_hz"] == rate]
        med = {k: float(np.median([r[k] for r in rs if r[k] is not None] or [np.nan]))
               for k in ("p50_ms", "p99_ms", "max_ms", "steady_p99_ms", "cpu_ms_per_frame")}
        print(f"median of {len(rs)} run(s) at {rate:g} Hz: p50 {med['p50_ms']:.2f} ms, p99 {med['p99_ms']:.2f} ms, "
              f"max {med['max_ms']:.1f} ms, steady p99 {med['steady_p99_ms']:.2f} ms; live CPU {med['cpu_ms_per_frame']:.2f} "
              f"ms/frame (a dedicated core keeps up to ~{1000 / med['cpu_ms_per_frame']:.0f} Hz); keeps up in "
              f"{sum(r['keeps_up'] for r in rs)}/{len(rs)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
