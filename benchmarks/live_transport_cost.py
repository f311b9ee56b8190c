"""What LSL costs ``exubio live`` per frame, without the solver: the CPU of waiting for and pulling
one marker sample (``LSLSource.pull``, as the live loop's intake calls it) and of publishing one
output row (``LSLPublisher``), each in this process pinned to one core, the other end in a
subprocess; beside a bare sleep and wake at the same period (what any loop that waits for its frame
pays on this machine). Loopback only (exubio.run.live.transport's LOOPBACK_CONFIG).

    python benchmarks/live_transport_cost.py                 # 200 Hz, 10 s each
    python benchmarks/live_transport_cost.py --rate 1000 --duration 5
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

N_MARKERS = 21  # bench_live.py's marker set


def _names() -> list[str]:
    return [f"M{i}" for i in range(N_MARKERS)]


def send(name: str, rate: float, duration: float) -> None:
    from exubio.run.live.transport import ReplayOutlet

    out = ReplayOutlet(_names(), rate, name=name, units="mm")
    out.wait_for_consumer(30)
    out.send(np.random.default_rng(0).random((int(duration * rate), N_MARKERS, 3)), speed=1.0)
    time.sleep(1.0)


def consume(name: str, duration: float) -> None:
    from exubio.run.live.transport import load_pylsl

    lsl = load_pylsl()
    found = lsl.resolve_byprop("name", name, minimum=1, timeout=30)
    inlet = lsl.StreamInlet(found[0])
    inlet.open_stream(timeout=10)
    end = time.time() + duration + 5
    while time.time() < end:
        inlet.pull_chunk(timeout=0.2)


def _child(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, __file__, *args], env=dict(os.environ))


def receive_cost(rate: float, duration: float) -> float:
    """CPU (us) per sample of the intake's pull pattern: pull(0.02) until a sample comes."""
    from exubio.run.live.transport import LSLSource

    name = f"transport_cost_{os.getpid()}"
    child = _child("--send", name, "--rate", str(rate), "--duration", str(duration))
    src = LSLSource(name=name)
    src.open(30)
    got, c0, last = 0, None, time.perf_counter()
    while True:
        s = src.pull(0.02)
        now = time.perf_counter()
        if s:
            if c0 is None:
                c0, first = time.process_time(), got
            got += len(s)
            last = now
        elif c0 is not None and now - last > 0.5:
            break
    cpu = time.process_time() - c0
    src.close()
    child.wait(30)
    return 1e6 * cpu / max(got - first, 1)


def publish_cost(rate: float, duration: float) -> tuple[float, float]:
    """CPU (us) per frame of a sleep to the next frame alone, and of the sleep plus one published row."""
    from exubio.run.live.outputs import OUTPUT_CHANNELS
    from exubio.run.live.transport import LSLPublisher, load_pylsl

    lsl = load_pylsl()
    name = f"transport_cost_out_{os.getpid()}"
    pub = LSLPublisher(name, OUTPUT_CHANNELS(_names()), rate)
    child = _child("--consume", name, "--duration", str(duration))
    pub.outlet.wait_for_consumers(30)
    n, period = int(duration * rate), 1.0 / rate
    row = np.random.default_rng(1).random(len(OUTPUT_CHANNELS(_names())))
    c0 = time.process_time()
    for _ in range(n):
        time.sleep(period)
    bare = time.process_time() - c0
    c0 = time.process_time()
    for _ in range(n):
        time.sleep(period)
        pub(row, lsl.local_clock())
    both = time.process_time() - c0
    child.wait(duration + 30)
    return 1e6 * bare / n, 1e6 * both / n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--core", type=int, default=1, help="the core this process is pinned to (-1: not pinned)")
    ap.add_argument("--send", help=argparse.SUPPRESS)
    ap.add_argument("--consume", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    from exubio.run.live.transport import use_config

    use_config("loopback")
    if args.send:
        send(args.send, args.rate, args.duration)
        return 0
    if args.consume:
        consume(args.consume, args.duration)
        return 0
    if args.core >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.core})
    load = os.getloadavg()[0]
    rx = receive_cost(args.rate, args.duration)
    bare, both = publish_cost(args.rate, args.duration)
    print(f"{args.rate:g} Hz, {args.duration:g} s each, {N_MARKERS} markers, load average {load:.1f} -> "
          f"{os.getloadavg()[0]:.1f}: waiting for and pulling a sample {rx:.1f} us of CPU; a sleep to the next "
          f"frame {bare:.1f} us, with one output row published {both:.1f} us (publishing {both - bare:.1f} us)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
