"""The functional scapula calibration cross-validated on the thoracoscapular TRC subject (issue 21):
calibrate on one trial, reconstruct the other (FLX01 -> ABD01 and ABD01 -> FLX01), never the
trial it reports.

Per direction, three calibrations of the generic model, each then used to reconstruct the other
trial with LS and PF:

* ``own still``: today's validation: calibrated on the reconstructed trial's own still frames
  (the TRC trials come without a static trial), static ellipsoid;
* ``cal still``: calibrated on the calibration trial's still frames, static ellipsoid;
* ``cal still+motion``: the same plus ``scapula_motion=`` the calibration trial
  (exubio.calibration.scapula_motion): the ellipsoid through its scapula postures;
* ``NOT cross-validated: both movements``: the postures of both trials pooled (the reconstructed
  trial is in the fit): what a session whose movement trial covers both planes could reach, the
  ceiling of the cross-validated figures, not a validation.

Printed per calibration: the fit (what moved, residuals, coverage), ts/ai RMSE (mm) of the
reconstructed trial, the model-minus-data ST angles (ISB Y-X'-Z'', deg RMSE over the frames at HT
30-120 deg; data = the registered scapula rigidly fitted to each frame's aa/ts/ai) and the PF
deviation from Ludewig et al. 2009 in his frames at HT 30/60/90/120 deg (ST internal rotation,
upward rotation, tilt) with the share of HT 30-120 inside the corridor.

Usage:  python benchmarks/scapula_motion_real.py      (needs ../shared/data/trc; about 2 minutes)
"""
from __future__ import annotations

import logging
import sys

import numpy as np

from exubio.angles import euler_angles, humerothoracic_elevation, segment_anatomical_rotations
from exubio.calibration import calibrate_model, calibrated_protocol
from exubio.calibration.scapula_motion import contact_points_over_motion, scapula_markers
from exubio.calibration.functional import cluster_poses
from exubio.invivo import compare_elevation
from exubio.io.trial import read_trial
from exubio.pipeline import load_model_and_protocol, reconstruct
from exubio.preprocess import prepare_targets
from exubio.resources import shipped_file
from exubio.validation.paths import shared_data_dir
from exubio.validation.trials import LUDEWIG_PLANE, REAL_PROTOCOL, REAL_TRIALS

ST_KEYS = ("ST_medRotation_X", "ST_protraction_Y", "ST_tilt_Z")
HT_BAND = (30.0, 120.0)


def data_st_deg(model, protocol, targets) -> np.ndarray:
    """ST angles (n, 3) deg of the data: the registered scapula rigidly fitted to each frame."""
    import exubio.angles as angles

    idx = scapula_markers(model, protocol, targets.positions_m[0])
    local = np.array([protocol.markers[j].local_position_m for j in idx])
    R, _, _ = cluster_poses(local, targets.positions_m[:, idx])
    A = angles.anatomical_frames(model)["scapula"]
    return np.degrees(euler_angles(R @ A, "YXZ"))


def evaluate(name: str, model, protocol, targets, plane: str) -> dict:
    """LS and PF on ``targets`` with the calibrated model: ts/ai RMSE, model-minus-data ST, Ludewig."""
    out = {}
    recs = {m: reconstruct(model, protocol, targets, method=m) for m in ("ls", "pf")}
    data = data_st_deg(model, protocol, targets)
    for m, rec in recs.items():
        names = list(rec.marker_names)
        res = rec.residuals_m * 1000.0
        rmse = {k: float(np.sqrt(np.nanmean(res[:, names.index(k)] ** 2))) for k in ("aa", "ts", "ai")}
        st = np.degrees(euler_angles(segment_anatomical_rotations(model, rec.q_rad)["scapula"], "YXZ"))
        ht = np.degrees(humerothoracic_elevation(model, rec.q_rad))
        band = (ht >= HT_BAND[0]) & (ht <= HT_BAND[1])
        diff = (st - data)[band]
        out[m] = {"rmse": rmse, "st_rmse": np.sqrt(np.mean(diff**2, axis=0)), "st_max": np.abs(diff).max(axis=0),
                  "band_frames": int(band.sum())}
    res, _ = compare_elevation(model, {m: r.q_rad for m, r in recs.items()}, targets.time_s, plane)
    out["ludewig"] = {k: (res["pf"][k]["deviation_deg"], res["pf"][k]["share_inside_corridor"]) for k in ST_KEYS}
    return out


def fmt_fit(info: dict) -> str:
    sc = info.get("scapula")
    if not sc:
        return "static ellipsoid"
    if not sc.get("used"):
        return f"scapula trial refused: {sc['reason']}"
    b, a = sc["contact_distance_before_mm"]["movement"]["all"], sc["contact_distance_after_mm"]["movement"]["all"]
    return (f"{sc['frames_used']} postures of {sc['trial']}; contact points off the ellipsoid {b['rms']:.1f} -> "
            f"{a['rms']:.1f} mm RMS (max {b['max']:.0f} -> {a['max']:.0f}); centre moved {sc['centre_shift_mm']} mm, "
            f"radii x {sc['radius_scale']}; determined {sc['determined']} ({sc['determined_directions']} of 6 "
            f"directions); scapula rotation range {sc['scapula_rotation_range_deg']} deg; rigid fit "
            f"{sc['rigid_fit_frame_rms_mm']['median']} mm median")


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    data = shared_data_dir() / "trc"
    if not all((data / f).exists() for f in REAL_TRIALS.values()):
        print(f"needs {data}/{list(REAL_TRIALS.values())}", file=sys.stderr)
        return 2
    generic, protocol = load_model_and_protocol(protocol_path=shipped_file("exubio.protocols", REAL_PROTOCOL,
                                                                           "protocols"))
    traj = {n: read_trial(data / f) for n, f in REAL_TRIALS.items()}
    tg = {n: prepare_targets(t, protocol) for n, t in traj.items()}
    for cal, rec in (("flexion", "abduction"), ("abduction", "flexion")):
        print(f"\n=== calibrate on {REAL_TRIALS[cal]}, reconstruct {REAL_TRIALS[rec]} ===")
        variants = {
            "own still": dict(trajectories=traj[rec], targets=tg[rec]),
            "cal still": dict(trajectories=traj[cal], targets=tg[cal]),
            "cal still+motion": dict(trajectories=traj[cal], targets=tg[cal], scapula_motion=tg[cal]),
            "NOT cross-validated: both movements": dict(trajectories=traj[cal], targets=tg[cal],
                                                        scapula_motion=(tg[cal], tg[rec])),
        }
        for label, kw in variants.items():
            model, report = calibrate_model(generic, protocol, kw.pop("trajectories"), **kw)
            bound = calibrated_protocol(protocol, model)
            print(f"-- {label}: {fmt_fit(report.functional)}")
            ev = evaluate(rec, model, bound, tg[rec], LUDEWIG_PLANE[rec])
            for m in ("ls", "pf"):
                e = ev[m]
                print(f"   {m.upper()}: RMSE aa/ts/ai {e['rmse']['aa']:.1f} / {e['rmse']['ts']:.1f} / {e['rmse']['ai']:.1f} mm;"
                      f" model-minus-data ST (int.rot / upward / tilt) RMSE "
                      f"{' / '.join(f'{v:.1f}' for v in e['st_rmse'])} deg, max "
                      f"{' / '.join(f'{v:.1f}' for v in e['st_max'])} deg over {e['band_frames']} frames at HT 30-120")
            for k, (dev, share) in ev["ludewig"].items():
                print(f"   PF - Ludewig {k:<17} at HT 30/60/90/120: "
                      f"{' / '.join(f'{v:+.1f}' for v in dev)} deg; inside corridor {share:.0%}")
    _ = contact_points_over_motion  # the same pose fit the calibration uses
    return 0


if __name__ == "__main__":
    sys.exit(main())
