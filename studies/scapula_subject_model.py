"""What the TRC subject's own thoracoscapular model achieves on its own scapula markers (issue 21):
the subject-scaled OpenSim model of Seth et al. 2019 (../shared/data/models/rmr_TSM_subject_noWeight.osim:
its own thorax ellipsoid, rotated and fitted to this subject, its own scapulothoracic joint and its
rigid clavicle through the AC point constraint) fitted by marker inverse kinematics to all 9 TRC
markers in every FRAME_STEP-th frame of ABD01 and FLX01 (models/sources/tsm_geometry.py: unweighted,
the AC constraint weighted 100, warm-started from the previous frame; OpenSim is not needed).

Printed per trial, for the frames at humerothoracic elevation 30-120 deg (the band of the issue's
aims; HT = angle between the thorax's -Y and gu -> centelbow) and for all fitted frames: aa/ts/ai
RMSE (mm) and the model-minus-data ST angles (deg, RMSE and max; ISB scapula frame of the model's
aa/ts/ai markers against the same frame of the data's, both in the data's ISB thorax frame,
Y-X-Z: internal rotation / upward rotation / tilt), and the distance of the data's AC (the
model's scapula rigidly fitted to the data's aa/ts/ai) from the model's SC against the model's
rigid SC-AC length. These are the figures exubio's cross-validated calibration is held to
(studies/scapula_motion_real.py: ts/ai <= 12 mm, ST <= 5 deg); here the subject's own model is
fitted to the very trial it reports (not cross-validated: a best case for that model).

Usage:  python studies/scapula_subject_model.py [--step N]   (needs ../shared/data; ~2 min at N = 10)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from exubio.model.angles import euler_angles

from calibration_trc_vs_tsm import _tsm_module  # models/sources/tsm_geometry.py, loaded from the checkout

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
FRAME_STEP = 10
HT_BAND_DEG = (30.0, 120.0)


def st_deg(tg, thorax, aa, ts, ai) -> np.ndarray:
    """ISB ST angles (deg, Y-X-Z) of the scapula frame of aa/ts/ai in the thorax frame."""
    S = tg.isb_scapula_frame(aa, ts, ai)
    return np.degrees(euler_angles(thorax.R.T @ S.R, "YXZ"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=int, default=FRAME_STEP, help="fit every N-th frame (default %(default)s)")
    args = ap.parse_args()
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to run", file=sys.stderr)
        return 2
    tg = _tsm_module()
    tsm = tg.load_tsm(SHARED / "models" / "rmr_TSM_subject_noWeight.osim")
    sc_ac = None
    for name in ("ABD01", "FLX01"):
        labels, pos, units = tg.read_trc(SHARED / "trc" / f"tsm_rmr_{name}.trc")
        pos = pos / 1000.0  # mm -> m
        at = {n: i for i, n in enumerate(labels)}
        ij, c7m, pt8 = (pos[0, at[n]] for n in ("ij", "centijc7", "centpxt8"))  # constant in these files
        thorax = tg.isb_thorax_frame(ij, 2 * c7m - ij, pt8, pt8)
        frames = range(0, pos.shape[0], args.step)
        q = tg.assemble(tsm)
        err = {k: [] for k in ("aa", "ts", "ai")}
        st_model, st_data, ht, ac_dist = [], [], [], []
        scap_local = {k: tsm.markers[k].location for k in ("aa", "ts", "ai")}
        for f in frames:
            targets = {n: pos[f, i] for n, i in at.items() if n in tsm.markers}
            q, _ = tg.fit_markers(tsm, targets, q)
            pts = tg.posture_points(tsm, q)
            for k in err:
                err[k].append(np.linalg.norm(pts[k] - pos[f, at[k]]) * 1000.0)
            st_model.append(st_deg(tg, thorax, pts["aa"], pts["ts"], pts["ai"]))
            st_data.append(st_deg(tg, thorax, *(pos[f, at[k]] for k in ("aa", "ts", "ai"))))
            hum = pos[f, at["gu"]] - pos[f, at["centelbow"]]
            ht.append(np.degrees(np.arccos(np.clip(-hum @ thorax.R[:, 1] / np.linalg.norm(hum), -1, 1))))
            X = tg.body_transforms(tsm, q)
            sc = X["clavicle"].p  # the clavicle's origin: the SC joint centre
            ac_model = pts["AC_joint_scapula"]
            if sc_ac is None:
                sc_ac = float(np.linalg.norm(pts["AC_joint_clavicle"] - sc) * 1000.0)
            # the data's AC: the model's scapula moved rigidly onto the data's aa/ts/ai
            T, _ = tg.kabsch(np.array([X["scapula"].apply(scap_local[k]) for k in scap_local]),
                             np.array([pos[f, at[k]] for k in scap_local]))
            ac_dist.append(np.linalg.norm(T.apply(ac_model) - sc) * 1000.0)
        ht, diff = np.array(ht), np.array(st_model) - np.array(st_data)
        diff = (diff + 180.0) % 360.0 - 180.0
        band = (ht >= HT_BAND_DEG[0]) & (ht <= HT_BAND_DEG[1])
        ac_dist = np.array(ac_dist)
        print(f"{name}: {len(ht)} frames fitted (every {args.step}th), {band.sum()} at HT "
              f"{HT_BAND_DEG[0]:.0f}-{HT_BAND_DEG[1]:.0f} deg")
        for label, sel in ((f"HT {HT_BAND_DEG[0]:.0f}-{HT_BAND_DEG[1]:.0f}", band), ("all frames", slice(None))):
            rmse = {k: float(np.sqrt(np.mean(np.array(v)[sel] ** 2))) for k, v in err.items()}
            d = diff[sel]
            print(f"  {label:<11} RMSE aa/ts/ai {rmse['aa']:.1f} / {rmse['ts']:.1f} / {rmse['ai']:.1f} mm; model-minus-data ST "
                  f"RMSE {' / '.join(f'{x:.1f}' for x in np.sqrt(np.mean(d**2, axis=0)))} deg, max "
                  f"{' / '.join(f'{x:.1f}' for x in np.abs(d).max(axis=0))} deg (int.rot / upward / tilt)")
        print(f"  the data's AC from the model's SC: {ac_dist.min():.1f}-{ac_dist.max():.1f} mm (SD {ac_dist.std():.1f}) "
              f"against the model's rigid {sc_ac:.1f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
