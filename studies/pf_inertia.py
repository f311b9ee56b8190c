"""PF's inertia (PFOptions.inertia_scale): the segments' masses and inertias the springs accelerate,
x 1.0 (the paper's physical segments) against 0.1 (the default) and 0.01, on simulated abduction,
flexion, scaption and SIER (100 Hz, the shipped protocol), noise-free and with 1.5 mm noise and
10 mm soft-tissue artefact. Prints per run: the worst coordinate's RMSE and its worst frame against
the truth (deg), q̈'s RMSE against the truth (rad/s²), the mean marker residual (mm) and the CPU
time per frame (ms, median of --runs).

    python studies/pf_inertia.py                 # 4 s trials
    python studies/pf_inertia.py --duration 25
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from exubio import load_model, load_protocol
from exubio.prep.targets import prepare_targets
from exubio.run.pipeline import reconstruct
from exubio.synth.simulate import Motion, simulate_trial

SCALES = (1.0, 0.1, 0.01)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args(argv)
    model = load_model()
    protocol = load_protocol()
    print(f"{'motion':10s} {'noise':6s} {'scale':>5s}  {'worst RMSE deg':>26s} {'worst frame deg':>16s} "
          f"{'qdd RMSE':>9s} {'residual mm':>11s} {'ms/frame':>8s}")
    for motion in Motion:
        for noise, sta in ((0.0, 0.0), (1.5, 10.0)):
            sim = simulate_trial(model, motion, duration_s=args.duration, rate_hz=100.0, noise_mm=noise, sta_mm=sta,
                                 seed=1)
            targets = prepare_targets(sim.trajectories, protocol)
            for scale in SCALES:
                times = []
                for _ in range(args.runs):
                    t0 = time.process_time()
                    rec = reconstruct(model, protocol, targets, method="pf", inertia_scale=scale)
                    times.append(time.process_time() - t0)
                err = np.degrees(rec.q_rad - sim.q_true)
                rmse = np.sqrt(np.mean(err ** 2, axis=0))
                j = int(np.argmax(rmse))
                qdd = float(np.sqrt(np.mean((rec.qdd_rad_s2 - sim.qdd_true) ** 2)))
                print(f"{motion.value:10s} {noise:<6.1f} {scale:5.2f}  {rmse[j]:7.3f} ({sim.coordinate_names[j]:17s})"
                      f" {np.abs(err).max():16.3f} {qdd:9.4f} {np.nanmean(rec.residuals_m) * 1000:11.3f} "
                      f"{1000 * np.median(times) / rec.n_frames:8.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
