"""The functional scapula calibration (``--scapula-trial``) on simulated trials with the bone-pin
artefact: the simulator's counterpart of ``studies/scapula_trial_bone.py``.

A subject is simulated with the shipped model (its ellipsoid as generic, or moved 10 mm and its radii
changed 8 %: a surface the static fit cannot make), the thoracoscapular_9 markers (the TRC set: aa,
ts, ai over the scapula landmarks), 1 mm noise and the bone-pin artefact (``--sta bone``: each
cluster's rigid motion regressed on the pins, plus its residual). Calibrated on a static (the
abduction's first frame held) alone, on the static and the abduction as scapula trial, or on the
static and a raised static (the abduction's highest frame held: ``--also-static``); the flexion
and the scaption are reconstructed with LS; per ST and GH angle the RMSE against the truth over every
frame and the share of measured frames within +-2u (the skin-fitted ellipsoid's term,
``angle_uncertainty.skin_ellipsoid_variance``, applies to the scapula-trial model as it records the
fit; ``--no-skin-term`` leaves it out).

    python studies/scapula_trial_sim.py            # ~5 min per seed on one core; markdown to stdout
    python studies/scapula_trial_sim.py --seeds 3
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import warnings

import numpy as np

RATE_HZ = 50.0
SIM_POINTS = ["IJ", "C7", "PX", "T8", "AA", "TS", "AI", "GH", "EL", "EJC"]
HT_ELEVATION = 16  # HT_X_elevation's column of the anatomical table
SHOWN = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_X_elevation",
         "GH_phadke_X_elevation", "GH_phadke_Y_internal_rotation")
SUBJECTS = {"generic ellipsoid": (np.zeros(3), np.ones(3)),
            "ellipsoid 10 mm off, radii 8 %": (np.array([-0.006, 0.0, 0.008]), np.array([1.08, 0.92, 1.08]))}


def _trc_like(traj):
    P = traj.positions_m
    ix = {n: i for i, n in enumerate(traj.labels)}
    cols = {"ij": P[:, ix["IJ"]], "centijc7": (P[:, ix["IJ"]] + P[:, ix["C7"]]) / 2,
            "centpxt8": (P[:, ix["PX"]] + P[:, ix["T8"]]) / 2, "aa": P[:, ix["AA"]], "ts": P[:, ix["TS"]],
            "ai": P[:, ix["AI"]], "gu": P[:, ix["GH"]], "EpL": P[:, ix["EL"]], "centelbow": P[:, ix["EJC"]]}
    return dataclasses.replace(traj, labels=tuple(cols), positions_m=np.stack(list(cols.values()), axis=1))


def main(argv=None) -> int:
    from exubio.calibration import calibrate_model, calibrated_protocol
    from exubio.io.resources import shipped_file
    from exubio.model.angles import anatomical_table
    from exubio.prep.targets import prepare_targets
    from exubio.protocol.bind import bind
    from exubio.run.inputs import load_model_and_protocol
    from exubio.run.pipeline import reconstruct
    from exubio.synth.simulate import simulate_trial
    from exubio.synth.sta_bone import load_sta_model
    from exubio.trust import angle_uncertainty as AU
    from exubio.trust.observability import angle_determinacy

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--no-skin-term", action="store_true")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    if args.no_skin_term:
        AU.ellipsoid_from_skin = lambda calibration: False
    generic, protocol = load_model_and_protocol(
        protocol_path=shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols"))
    sta = load_sta_model("bone")
    print("| subject | seed | calibration | trial | " + " | ".join(SHOWN) + " |")
    print("|---|---|---|---|" + "---|" * len(SHOWN))
    for label, (shift, factor) in SUBJECTS.items():
        e = generic.ellipsoid
        subject = dataclasses.replace(generic, ellipsoid=dataclasses.replace(
            e, centre_m=np.asarray(e.centre_m) + shift, radii_m=np.asarray(e.radii_m) * factor))
        for seed in range(1, args.seeds + 1):
            sims = {m: simulate_trial(subject, m, duration_s=5.0, rate_hz=RATE_HZ, marker_names=SIM_POINTS,
                                      lab_transform=False, noise_mm=1.0, sta_mm=10.0, seed=seed, sta_model=sta)
                    for m in ("abduction", "flexion", "scaption")}
            trc = {m: _trc_like(s.trajectories) for m, s in sims.items()}
            static = dataclasses.replace(trc["abduction"], positions_m=np.repeat(trc["abduction"].positions_m[:1], 40, 0),
                                         time_s=np.arange(40) / RATE_HZ)
            abd_targets = prepare_targets(trc["abduction"], protocol)
            top = int(np.argmax(np.abs(anatomical_table(subject, sims["abduction"].q_true)[1][:, HT_ELEVATION])))
            raised = dataclasses.replace(trc["abduction"], positions_m=np.repeat(trc["abduction"].positions_m[top:top + 1], 40, 0),
                                         time_s=np.arange(40) / RATE_HZ)  # the abduction's highest frame, held
            models = {"static": calibrate_model(generic, protocol, static)[0],
                      "static + scapula trial": calibrate_model(generic, protocol, static, scapula_motion=abd_targets)[0],
                      "static + raised static": calibrate_model(generic, protocol, static,
                                                                more_statics=[prepare_targets(raised, protocol)])[0]}
            for cal, model in models.items():
                prot = calibrated_protocol(protocol, model)
                b = bind(model, prot)
                for m in ("flexion", "scaption"):
                    targets = prepare_targets(trc[m], prot)
                    rec = reconstruct(model, prot, targets, method="ls")
                    det = angle_determinacy(b.kin, b.points, rec.q_rad, targets.present, prot.weights, held=b.held,
                                            locked=b.locked, every=3, residuals_m=rec.residuals_m,
                                            marker_positions_m=targets.positions_m)
                    names, est = anatomical_table(model, rec.q_rad)
                    _, true = anatomical_table(subject, sims[m].q_true)
                    cells = []
                    for a in SHOWN:
                        j = names.index(a)
                        d = np.angle(np.exp(1j * (est[:, j] - true[:, j])))
                        k = det.names.index(a)
                        meas = det.status[:, k] == 0
                        u = det.uncertainty_rad[:, k]
                        cov = f"{np.mean(np.abs(d[meas]) <= 2 * u[meas]):.0%}" if meas.any() else "-"
                        cells.append(f"{np.degrees(np.sqrt(np.mean(d ** 2))):.1f} / {cov} ({meas.mean():.0%})")
                    print(f"| {label} | {seed} | {cal} | {m} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
