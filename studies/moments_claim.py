"""Is the paper right that PF's dynamically consistent accelerations serve inverse dynamics? Joint
moments of simulated raises (70 kg, 2 kg in the hand) with 1 mm noise and soft-tissue artefact,
reconstructed by PF (inertia x0.1, the default, and x1), LS (its q'' from the smoothed markers'
derivatives, the shipped protocol's 'auto' filter) and LS with a typical lab pipeline (LS angles,
a 6 Hz 2nd-order zero-lag Butterworth on q, then central differences), against the exact moments
(exubio.dynamics on the simulation's exact q, q', q''). Per joint the RMSE (N m) over the frames
after the first 0.5 s (PF starts at rest), mean over seeds; GH is the RMSE of the 3D moment vector.

    python studies/moments_claim.py --seeds 3                 # per-marker STA 20 mm
    python studies/moments_claim.py --seeds 3 --sta bone      # the bone-pin STA model

slow: 5 s cycles (HT 10-120-10 deg), 10 s at 100 Hz; fast: 0.6 s cycles, 3 s at 200 Hz (peak
angular accelerations ~6000 deg/s^2). Gravity off in PF (the default).
"""
from __future__ import annotations

import argparse
import logging
import time
import warnings

import numpy as np

JOINTS = {"GH": ("GH_X_moment_Nm", "GH_Y_moment_Nm", "GH_Z_moment_Nm"), "elbow": ("elbow_flexion_moment_Nm",),
          "pronation": ("forearm_pronation_moment_Nm",), "wrist": ("wrist_flexion_moment_Nm",)}
SPEEDS = {"slow": (5.0, 10.0, 100.0), "fast": (0.6, 3.0, 200.0)}
METHODS = ("PF x0.1", "PF x1", "LS", "LS + 6 Hz on q")
MASS, LOAD = 70.0, 2.0


def lab_filter(q: np.ndarray, rate: float, cutoff: float = 6.0):
    """The common lab pipeline: low-pass the angles, then finite differences."""
    from scipy.signal import butter, filtfilt

    b, a = butter(2, cutoff / (0.5 * rate))
    qf = filtfilt(b, a, q, axis=0, padtype="odd", padlen=min(len(q) - 1, int(3 * rate / cutoff)))
    qd = np.gradient(qf, 1.0 / rate, axis=0)
    return qf, qd, np.gradient(qd, 1.0 / rate, axis=0)


def one(speed: str, seed: int, sta: str, sta_mm: float, noise_mm: float):
    import exubio
    from exubio.dynamics.moments import joint_moments
    from exubio.synth.simulate import simulate_trial

    cycle, duration, rate = SPEEDS[speed]
    model = exubio.load_model(body_mass_kg=MASS)
    trial = simulate_trial(model, "abduction", duration_s=duration, rate_hz=rate, cycle_s=cycle, noise_mm=noise_mm,
                           sta_mm=sta_mm, seed=seed, sta_model=None if sta == "per-marker" else sta)
    truth = joint_moments(model, trial.q_true, trial.qd_true, trial.qdd_true, hand_load_kg=LOAD)
    keep = trial.time_s >= 0.5
    out, secs = {}, {}
    for label in METHODS:
        t0 = time.perf_counter()
        if label.startswith("PF"):
            rec = exubio.reconstruct(trial.trajectories, model, method="pf", inertia_scale=float(label.split("x")[1]))
            states = rec.q_rad, rec.qd_rad_s, rec.qdd_rad_s2
        else:
            rec = exubio.reconstruct(trial.trajectories, model, method="ls")
            states = (rec.q_rad, rec.qd_rad_s, rec.qdd_rad_s2) if label == "LS" else lab_filter(rec.q_rad, rate)
        m = joint_moments(model, *states, hand_load_kg=LOAD)
        secs[label] = time.perf_counter() - t0
        out[label] = {}
        for joint, cols in JOINTS.items():
            err = np.stack([m.column(c) - truth.column(c) for c in cols], axis=-1)[keep]
            out[label][joint] = float(np.sqrt(np.mean(np.sum(err ** 2, axis=-1))))
    peaks = {j: float(np.max(np.linalg.norm(np.stack([truth.column(c) for c in cols], axis=-1), axis=-1)))
             for j, cols in JOINTS.items()}
    return out, peaks, secs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--sta", default="per-marker", help="per-marker (default) or bone")
    ap.add_argument("--sta-mm", type=float, default=20.0)
    ap.add_argument("--noise-mm", type=float, default=1.0)
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    print(f"STA {args.sta} {args.sta_mm:g} mm, noise {args.noise_mm:g} mm, seeds 0-{args.seeds - 1}; "
          f"RMSE of the moment (N m) after 0.5 s, mean over seeds (peak of the truth in brackets)\n")
    print("| motion | method | " + " | ".join(JOINTS) + " |")
    print("|---|---|" + "---:|" * len(JOINTS))
    for speed in SPEEDS:
        runs = [one(speed, s, args.sta, args.sta_mm, args.noise_mm) for s in range(args.seeds)]
        peaks = runs[0][1]
        for label in METHODS:
            cells = [f"{np.mean([r[0][label][j] for r in runs]):.2f}" for j in JOINTS]
            print(f"| {speed} | {label} | " + " | ".join(cells) + " |")
        print(f"| {speed} | (peak of the truth) | " + " | ".join(f"({peaks[j]:.1f})" for j in JOINTS) + " |")


if __name__ == "__main__":
    main()
