"""What the thorax's own motion does to the joint moments (issue 36 item 2): a simulated slow raise
(coronal abduction, 10-120 deg in 5 s cycles, 10 s at 100 Hz, 70 kg, 2 kg in the hand) whose trunk
leans 20 deg in step with each raise (exubio.synth.thorax_lean: about a point 0.45 m below IJ;
lateral, towards the arm, and forward).

Per joint moment, as a share of its peak (%), the RMSE and the worst error against the exact
moments (the simulation's exact q, q', q'' with the thorax's exact motion):

1. ``still``: the exact arm motion, the thorax assumed still (upright, gravity -Y of the thorax):
   how wrong a thorax-fixed inverse dynamics is;
2. ``markers``: the exact arm motion, the thorax's motion measured from its four skin markers
   (exubio.prep.thorax_motion: the protocol's filter and splines) with 1 mm noise, and with a
   thorax-marker skin artefact of 5 and 10 mm driven by the lean (the simulator gives the thorax
   markers none by default): what a thorax tracked by skin markers costs alone;
3. ``LS``: the whole chain a lab runs, LS on markers with 1 mm noise and the simulator's 20 mm
   per-marker STA (thorax markers: noise only), moments with the measured thorax motion, and with
   the thorax assumed still.

Seeds 0-2, averaged.

    python studies/moments_thorax.py        # about a minute on 2 cores
"""
from __future__ import annotations

import logging

import numpy as np

MASS, LOAD = 70.0, 2.0
SHOWN = ("GH_X_moment_Nm", "GH_Y_moment_Nm", "GH_Z_moment_Nm", "elbow_flexion_moment_Nm",
         "forearm_pronation_moment_Nm", "wrist_flexion_moment_Nm")
SEEDS = (0, 1, 2)


def shares(got, truth) -> dict[str, tuple[float, float]]:
    out = {}
    for c in SHOWN:
        t, e = truth.column(c), got.column(c) - truth.column(c)
        peak = np.abs(t).max()
        out[c] = (100 * float(np.sqrt(np.nanmean(e ** 2))) / peak, 100 * float(np.nanmax(np.abs(e))) / peak)
    return out


def run(axis: str) -> dict[str, list[dict]]:
    import exubio
    from exubio.dynamics.moments import joint_moments
    from exubio.model.load import load_model
    from exubio.prep.thorax_motion import measure_thorax_motion
    from exubio.synth.simulate import simulate_trial
    from exubio.synth.thorax_lean import ThoraxLean

    model = load_model(body_mass_kg=MASS)
    protocol = exubio.load_protocol(model=model)
    rows: dict[str, list[dict]] = {}

    def add(key, got, truth):
        rows.setdefault(key, []).append(shares(got, truth))

    for seed in SEEDS:
        exact = simulate_trial(model, "abduction", duration_s=10.0, rate_hz=100, thorax_lean=ThoraxLean(20.0, axis))
        q, qd, qdd = exact.q_true, exact.qd_true, exact.qdd_true
        truth = joint_moments(model, q, qd, qdd, hand_load_kg=LOAD, thorax=exact.thorax_motion)
        if seed == SEEDS[0]:
            add("still (exact arm motion)", joint_moments(model, q, qd, qdd, hand_load_kg=LOAD), truth)
        for sta in (0.0, 5.0, 10.0):
            noisy = simulate_trial(model, "abduction", duration_s=10.0, rate_hz=100, noise_mm=1.0, seed=seed,
                                   thorax_lean=ThoraxLean(20.0, axis, thorax_sta_mm=sta))
            measured = measure_thorax_motion(noisy.trajectories, protocol)
            add(f"markers: 1 mm noise, thorax STA {sta:g} mm (exact arm motion)",
                joint_moments(model, q, qd, qdd, hand_load_kg=LOAD, thorax=measured), truth)
        lab = simulate_trial(model, "abduction", duration_s=10.0, rate_hz=100, noise_mm=1.0, sta_mm=20.0, seed=seed,
                             thorax_lean=ThoraxLean(20.0, axis))
        rec = exubio.reconstruct(lab.trajectories, model, protocol, method="ls")
        measured = measure_thorax_motion(lab.trajectories, protocol)
        args = (rec.q_rad, rec.qd_rad_s, rec.qdd_rad_s2)
        add("LS, 1 mm noise + 20 mm STA, thorax measured", joint_moments(model, *args, hand_load_kg=LOAD, thorax=measured),
            truth)
        add("LS, 1 mm noise + 20 mm STA, thorax assumed still", joint_moments(model, *args, hand_load_kg=LOAD), truth)
    return rows


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    short = {"GH_X_moment_Nm": "GH X", "GH_Y_moment_Nm": "GH Y", "GH_Z_moment_Nm": "GH Z",
             "elbow_flexion_moment_Nm": "elbow", "forearm_pronation_moment_Nm": "pron", "wrist_flexion_moment_Nm": "wrist"}
    for axis in ("lateral", "forward"):
        print(f"\n20 deg {axis} lean: RMSE / worst error, % of the moment's peak (mean over seeds {list(SEEDS)})")
        print(f"{'case':62s} " + " ".join(f"{short[c]:>13s}" for c in SHOWN))
        for key, runs in run(axis).items():
            cells = []
            for c in SHOWN:
                rmse = np.mean([r[c][0] for r in runs])
                worst = np.mean([r[c][1] for r in runs])
                cells.append(f"{rmse:5.1f} / {worst:5.1f}")
            print(f"{key:62s} " + " ".join(f"{x:>13s}" for x in cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
