"""Static and task trials of the same and of the other session (../shared/data): the per-segment
shift and z of exubio.trust.session_check, and whether each pair is flagged; plus simulated trials with
10-30 mm of soft-tissue artefact checked against their own first 0.5 s (the same session by
construction). Prints one line per pair.

Usage: python studies/session_consistency.py
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

from exubio.io.trial import read_trial
from exubio.trust.labels import pair_distances
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.trust.session_check import SHIFT_MM, SHIFT_Z, placed_anew, static_consistency
from exubio.synth.simulate import simulate_trial

C3D = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d"
SESSIONS = {"bioptim_exo_kinova_martin_statique.c3d": [f"bioptim_exo_kinova_martin_{n}_f3_1.c3d"
                                                       for n in ("aisselle", "dent", "manger", "tete")],
            "bioptim_exo_martin_statique.c3d": ["bioptim_exo_martin_dynamique.c3d"]}


def _line(tag: str, trial: str, static: str, shifts) -> str:
    flagged = placed_anew(shifts)
    txt = "  ".join(f"{s.segment} {s.shift_mm:.1f} mm z {s.z:.2f}" for s in shifts)
    return f"{tag:5s} {trial:42s} static {static:40s} {txt}  -> {'FLAGGED' if flagged else 'ok'}"


def main() -> int:
    warnings.simplefilter("ignore")
    model, protocol = load_model_and_protocol()
    print(f"thresholds: shift > {SHIFT_MM} mm and z > {SHIFT_Z}")
    if C3D.is_dir():
        pd = {}
        for path in [*SESSIONS, *(t for ts in SESSIONS.values() for t in ts)]:
            targets = prepare_targets(read_trial(C3D / path), protocol)
            pd[path] = pair_distances(targets.positions_m, targets.marker_names, source=path)
        for static in SESSIONS:
            for own, trials in SESSIONS.items():
                for trial in trials:
                    tag = "SAME" if own == static else "CROSS"
                    print(_line(tag, trial, static, static_consistency(pd[static], pd[trial], protocol)))
    else:
        print(f"{C3D} is absent: real sessions skipped", file=sys.stderr)
    for motion in ("abduction", "flexion", "scaption", "sier"):
        for sta in (10, 20, 30):
            sim = simulate_trial(model, motion, duration_s=10, rate_hz=100, noise_mm=1, sta_mm=sta, seed=3)
            targets = prepare_targets(sim.trajectories, protocol)
            static = pair_distances(targets.positions_m[:50], targets.marker_names)
            trial = pair_distances(targets.positions_m, targets.marker_names)
            print(_line("SIM", f"{motion} STA {sta} mm", "its first 0.5 s", static_consistency(static, trial, protocol)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
