"""The live loop's outputs across a change: the offline causal run (exubio.run.live.offline, the live
loop on an in-process replay) of a fixed set of streams, written to one .npz per stream, and two
such sets compared exactly.

    python benchmarks/same_live.py --write DIR                  # this checkout
    PYTHONPATH=<other checkout> python benchmarks/same_live.py --write DIR2
    python benchmarks/same_live.py --compare DIR DIR2

The streams: the shipped example (100 Hz, 4 s) clean and with each fault the live loop handles
(dropped frames, a marker gap, late samples, a stall, a restarted sender, a label swap), and a
simulated 21-marker abduction at 200 Hz (10 s) and at 1000 Hz (3 s), the profile's. Every array of
the recording is kept, with its events (kind, frame, message, markers) and the running verdict
(verdict, reasons) at the end; the timing fields (the loop's clock: received_s, published_s, the
latencies and the CPU figures) are not. ``--compare`` prints, per stream, the arrays that differ
and by how much (max |a - b|), and exits 1 if any does.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1]))  # after PYTHONPATH: another checkout may be named there

TIMING = {"received_s", "published_s"}


def streams():
    """(name, trial, faults) of every stream."""
    from exubio.io.resources import shipped_file
    from exubio.io.trial import read_trial
    from exubio.run.live.sources import Faults
    from exubio.types import Trajectories

    t = read_trial(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"))
    short = Trajectories(labels=t.labels, positions_m=t.positions_m[:400], rate_hz=t.rate_hz, time_s=t.time_s[:400],
                         source="example_short")
    faults = {"clean": Faults(), "dropped": Faults(drop=(100, 101, 102)), "gap": Faults(gaps=(("EPI_lat", 100, 250),)),
              "late": Faults(late=(120, 121)), "stall": Faults(stall=(150, 0.5)), "restart": Faults(restart=200),
              "swap": Faults(swap=("EPI_lat", "EPI_med", 200))}
    out = [(f"example_{k}", short, f) for k, f in faults.items()]
    for rate, duration in ((200.0, 10.0), (1000.0, 3.0)):
        out.append((f"abduction_{rate:g}hz", _abduction(duration, rate), Faults()))
    return out


def _abduction(duration_s: float, rate_hz: float):
    """profile_frames.py's live stream: a simulated abduction, 0.5 mm noise, the 21-marker set."""
    from exubio.run.inputs import load_model_and_protocol
    from exubio.synth.simulate import Motion, simulate_trial
    from exubio.types import Trajectories

    model, _ = load_model_and_protocol()
    t = simulate_trial(model, Motion.parse("abduction"), duration_s=duration_s, rate_hz=rate_hz, noise_mm=0.5,
                       sta_mm=0.0, seed=1).trajectories
    keep = [i for i, lab in enumerate(t.labels) if lab != "ELB"]
    return Trajectories(labels=tuple(t.labels[i] for i in keep), positions_m=t.positions_m[:, keep],
                        rate_hz=t.rate_hz, time_s=t.time_s, source="abduction")


def write(folder: Path) -> None:
    from exubio.run.inputs import load_model_and_protocol
    from exubio.run.live.offline import reconstruct_causal

    folder.mkdir(parents=True, exist_ok=True)
    model, protocol = load_model_and_protocol()
    for name, trial, faults in streams():
        rec = reconstruct_causal(trial, model, protocol, faults=faults)
        arrays = {f: getattr(rec, f) for f in ("raw_m", "timestamps_s", "positions_m", "velocities_m_s",
                                               "accelerations_m_s2", "active", "q_rad", "qd_rad_s", "qdd_rad_s2",
                                               "model_points_m", "residuals_m", "constraint", "constraint_velocity",
                                               "status", "run", "isb_rad", "isb_rate_rad_s", "measured", "verdict")}
        q = rec.live_quality
        text = {"events": [[e.kind, e.frame, e.message, list(e.markers)] for e in rec.events],
                "verdict": q.verdict, "reasons": [[r.code, r.message] for r in q.reasons],
                "stats": {k: v for k, v in rec.stats.items() if k in ("frames", "dropped", "late", "skipped", "failed",
                                                                      "no_pf_state", "runs")}}
        np.savez(folder / f"{name}.npz", text=np.array(json.dumps(text)), **arrays)
        print(f"{name}: {rec.n_frames} frames, verdict {q.verdict}, {len(rec.events)} events")


def compare(a: Path, b: Path) -> int:
    differ = 0
    names = sorted(p.name for p in a.glob("*.npz"))
    if names != sorted(p.name for p in b.glob("*.npz")):
        print("the two folders hold different streams")
        return 1
    for name in names:
        with np.load(a / name) as za, np.load(b / name) as zb:
            bad = []
            for key in za.files:
                x, y = za[key], zb[key]
                if key == "text":
                    if str(x) != str(y):
                        bad.append("events/verdict/stats")
                elif x.shape != y.shape or not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
                    gap = (float(np.nanmax(np.abs(x.astype(float) - y.astype(float))))
                           if x.shape == y.shape and x.size else float("nan"))
                    bad.append(f"{key} (max |a - b| {gap:.3g})")
        print(f"{name[:-4]}: " + ("identical" if not bad else "differ: " + ", ".join(bad)))
        differ += bool(bad)
    print(f"{len(names) - differ} of {len(names)} streams identical")
    return 1 if differ else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path)
    ap.add_argument("--compare", nargs=2, type=Path)
    args = ap.parse_args(argv)
    if args.write:
        write(args.write)
    if args.compare:
        return compare(*args.compare)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
