"""Does fitting the thorax ellipsoid to the reconstruction's own marker residuals over the
calibration trial do better than the functional scapula calibration's contact-point fit (issue 21)?

Per direction of the TRC subject (calibrate on FLX01, reconstruct ABD01; and the reverse): the
functional calibration (exubio.calibration.scapula_motion: the ellipsoid through the registered
scapula's contact points), then its ellipsoid refined (centre 3 + radii 3, the same weak prior) to
minimise the LS marker residuals of every tenth frame of the calibration trial: the model with both
of its constraints (the rigid clavicle and the ellipsoid) fitted as it will be used. Printed for the
other trial, LS and PF: aa/ts/ai RMSE (mm) and the model-minus-data ST angles (RMSE over HT 30-120,
internal rotation / upward rotation / tilt; data = the registered scapula rigidly fitted to each
frame's aa/ts/ai, exubio.validation.scapula.data_st_deg).

Usage:  python studies/scapula_residual_refit.py [STEP]     (needs ../shared/data/trc; ~2 min)
"""
from __future__ import annotations

import dataclasses
import logging
import sys

import numpy as np
from scipy.optimize import least_squares

from exubio.calibration import calibrate_model, calibrated_protocol
from exubio.io.resources import shipped_file
from exubio.io.trial import read_trial
from exubio.methods.ls import reconstruct_ls
from exubio.model.angles import euler_angles, humerothoracic_elevation, segment_anatomical_rotations
from exubio.prep.targets import prepare_targets
from exubio.run.inputs import load_model_and_protocol
from exubio.run.pipeline import reconstruct
from exubio.validation.paths import shared_data_dir
from exubio.validation.scapula import HT_BAND_DEG, data_st_deg
from exubio.validation.trials import REAL_PROTOCOL, REAL_TRIALS

PRIOR_SD = np.r_[[0.02] * 3, [0.15] * 3]  # as exubio.calibration.scapula_motion: centre 20 mm, radii 15 %


def every(t, step):
    return dataclasses.replace(t, time_s=t.time_s[::step], positions_m=t.positions_m[::step],
                               velocities_m_s=t.velocities_m_s[::step],
                               accelerations_m_s2=t.accelerations_m_s2[::step], gaps=())


def with_ellipsoid(model, p):
    e = model.ellipsoid
    return dataclasses.replace(model, ellipsoid=dataclasses.replace(e, centre_m=p[:3], radii_m=np.exp(p[3:6])))


def scores(model, protocol, targets):
    data = data_st_deg(model, protocol, targets)
    out = {}
    for m in ("ls", "pf"):
        rec = reconstruct(model, protocol, targets, method=m)
        names = list(rec.marker_names)
        rmse = [float(np.sqrt(np.nanmean((rec.residuals_m[:, names.index(k)] * 1000.0) ** 2))) for k in ("aa", "ts", "ai")]
        st = np.degrees(euler_angles(segment_anatomical_rotations(model, rec.q_rad)["scapula"], "YXZ"))
        ht = np.degrees(humerothoracic_elevation(model, rec.q_rad))
        band = (ht >= HT_BAND_DEG[0]) & (ht <= HT_BAND_DEG[1])
        out[m] = rmse, np.sqrt(np.mean((st - data)[band] ** 2, axis=0))
    return out


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    step = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    folder = shared_data_dir() / "trc"
    if not all((folder / f).exists() for f in REAL_TRIALS.values()):
        print(f"needs {folder}", file=sys.stderr)
        return 2
    generic, protocol = load_model_and_protocol(protocol_path=shipped_file("exubio.protocols", REAL_PROTOCOL, "protocols"))
    traj = {n: read_trial(folder / f) for n, f in REAL_TRIALS.items()}
    tg = {n: prepare_targets(t, protocol) for n, t in traj.items()}
    for cal, rec in (("flexion", "abduction"), ("abduction", "flexion")):
        model, _ = calibrate_model(generic, protocol, traj[cal], targets=tg[cal], scapula_motion=tg[cal])
        bound = calibrated_protocol(protocol, model)
        sub = every(tg[cal], step)
        p1 = np.r_[model.ellipsoid.centre_m, np.log(model.ellipsoid.radii_m)]

        def residuals(p, bound=bound, sub=sub, model=model, p1=p1):
            res = np.nan_to_num(reconstruct_ls(with_ellipsoid(model, p), bound, sub).residuals_m).ravel()
            return np.r_[res / np.sqrt(res.size), 0.01 * (p - p1) / PRIOR_SD]

        sol = least_squares(residuals, p1, diff_step=1e-4, x_scale=PRIOR_SD, max_nfev=60)
        print(f"calibrate on {REAL_TRIALS[cal]}, reconstruct {REAL_TRIALS[rec]}: refit moved the centre "
              f"{np.round((sol.x[:3] - p1[:3]) * 1000, 1).tolist()} mm, radii x {np.round(np.exp(sol.x[3:] - p1[3:]), 3).tolist()}")
        for label, mdl in (("contact-point fit", model), ("residual refit", with_ellipsoid(model, sol.x))):
            for m, (rmse, st) in scores(mdl, bound, tg[rec]).items():
                print(f"  {label:<18} {m.upper()}: aa/ts/ai {' / '.join(f'{x:.1f}' for x in rmse)} mm; model-minus-data ST "
                      f"RMSE {' / '.join(f'{x:.1f}' for x in st)} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
