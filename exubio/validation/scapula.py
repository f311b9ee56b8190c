"""The functional scapula calibration (exubio.calibration.scapula_motion) cross-validated: calibrated
on one trial, reconstructing another, never the trial it reports.

Real data (the thoracoscapular TRC subject, when ../shared/data is there): per direction
(FLX01 -> ABD01, ABD01 -> FLX01) the generic model calibrated

* ``own_still``: on the reconstructed trial's own still frames (the rest of the validation's
  calibration: the TRC trials come without a static trial), static ellipsoid;
* ``cal_still``: on the calibration trial's still frames, static ellipsoid;
* ``cal_still_motion``: the same plus the calibration trial's scapula postures (the cross-validated
  result);
* ``pooled_not_cross_validated``: both trials' postures pooled (the reconstructed trial is in the
  fit): the ceiling of what one thorax-aligned ellipsoid can carry, not a validation;

and per calibration, LS and PF on the reconstructed trial: aa/ts/ai RMSE (mm), the model-minus-data
ST angles (ISB Y-X'-Z'', deg; data = the registered scapula rigidly fitted to each frame's
aa/ts/ai) RMSE and maximum over the frames at HT 30-120 deg, and PF's deviation from Ludewig et al.
2009 in his frames (ST angles at HT 30/60/90/120 deg, share of HT 30-120 inside the corridor).

Simulated subject (always): the generic model with its ellipsoid moved 10 mm and its radii changed
8 % (not a common scale), 9-marker thoracoscapular set on the landmarks; calibrated on a static pose
and the abduction, the flexion's ST angles against the truth (max error per angle), at rest only
and with the movement.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from exubio.model.angles import anatomical_frames, euler_angles, humerothoracic_elevation, isb_angles, \
    segment_anatomical_rotations
from exubio.calibration import calibrate_model, calibrated_protocol
from exubio.calibration.ellipsoid import surface_distance
from exubio.calibration.cluster import cluster_poses
from exubio.calibration.scapula_motion import scapula_markers
from exubio.errors import ExubioError
from exubio.literature.invivo import compare_elevation
from exubio.io.trial import read_trial
from exubio.model.kinematics import Kinematics
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.io.resources import shipped_file
from exubio.synth.simulate import simulate_trial
from exubio.validation.paths import shared_data_dir
from exubio.validation.results import (Check, ScapulaCrossValidation, ScapulaDirection, ScapulaSimulated,
                                       ScapulaVariant, Skipped)
from exubio.validation.settings import ValidationSettings
from exubio.validation.trials import LUDEWIG_PLANE, REAL_PROTOCOL, REAL_TRIALS, Progress, why_no_real_trial

__all__ = ["AIM_MARKER_RMSE_MM", "AIM_ST_RMSE_DEG", "HT_BAND_DEG", "ST_KEYS", "data_clavicle_mm", "data_st_deg",
           "registered_scapula_poses", "scapula_checks",
           "scapula_cross_validation", "simulated_subject"]

ST_KEYS = ("ST_medRotation_X", "ST_protraction_Y", "ST_tilt_Z")
HT_BAND_DEG = (30.0, 120.0)
AIM_MARKER_RMSE_MM = 12.0  # issue 21: ts and ai RMSE, both directions
AIM_ST_RMSE_DEG = 5.0  # issue 21: model-minus-data ST angles over HT 30-120
SIM_SHIFT_M = (-0.006, 0.0, 0.008)  # 10 mm, partly lateral (the static fit moves the centre in x, y only)
SIM_RADII_FACTOR = (1.08, 0.92, 1.08)  # 8 %, not a common scale
_SIM_POINTS = ("IJ", "C7", "PX", "T8", "AA", "TS", "AI", "GH", "EL", "EJC")


def registered_scapula_poses(model, protocol, targets) -> tuple[np.ndarray, np.ndarray]:
    """The registered scapula (its markers' positions on it, protocol bound to ``model``) rigidly
    fitted to each frame's scapula markers: R (n, 3, 3), t (n, 3), scapula to thorax."""
    idx = scapula_markers(model, protocol, targets.positions_m[0])
    local = np.array([protocol.markers[j].local_position_m for j in idx])
    R, t, _ = cluster_poses(local, targets.positions_m[:, idx])
    return R, t


def data_st_deg(model, protocol, targets, poses=None) -> np.ndarray:
    """ST angles (n, 3) deg of the data: the registered scapula (``poses``, default
    registered_scapula_poses) in the model's ISB scapula frame."""
    R, _ = poses if poses is not None else registered_scapula_poses(model, protocol, targets)
    return np.degrees(euler_angles(R @ anatomical_frames(model)["scapula"], "YXZ"))


def data_clavicle_mm(model, protocol, targets, poses=None) -> tuple[np.ndarray, float]:
    """The clavicle the data imply: per frame, the distance (mm) from the model's SC (fixed on the
    thorax) to AC of the registered scapula (``poses``, default registered_scapula_poses), and the
    model's rigid SC-AC length (mm). The model's AC must stay on the sphere of that radius about SC;
    where the data's does not, no ellipsoid lets the model follow the data's scapula."""
    R, t = poses if poses is not None else registered_scapula_poses(model, protocol, targets)
    kin = Kinematics(model)
    sc = kin.points(np.zeros(kin.n_coordinates), kin.point_set([("clavicle", "SC")]))[0]
    clav = model.segment("clavicle").points
    ac = model.segment("scapula").points["AC"]
    return np.linalg.norm(R @ ac + t - sc, axis=1) * 1000.0, float(np.linalg.norm(clav["AC"] - clav["SC"]) * 1000.0)


def _variant(model, protocol, targets, plane: str, info: dict) -> ScapulaVariant:
    recs = {m: reconstruct(model, protocol, targets, method=m) for m in ("ls", "pf")}
    poses = registered_scapula_poses(model, protocol, targets)
    data = data_st_deg(model, protocol, targets, poses)
    clavicle, length = data_clavicle_mm(model, protocol, targets, poses)
    rmse, st_rmse, st_max = {}, {}, {}
    for m, rec in recs.items():
        names = list(rec.marker_names)
        res = rec.residuals_m * 1000.0
        rmse[m] = {k: float(np.sqrt(np.nanmean(res[:, names.index(k)] ** 2))) for k in ("aa", "ts", "ai") if k in names}
        st = np.degrees(euler_angles(segment_anatomical_rotations(model, rec.q_rad)["scapula"], "YXZ"))
        ht = np.degrees(humerothoracic_elevation(model, rec.q_rad))
        band = (ht >= HT_BAND_DEG[0]) & (ht <= HT_BAND_DEG[1])
        diff = (st - data)[band]
        st_rmse[m] = tuple(np.sqrt(np.mean(diff**2, axis=0)).tolist())
        st_max[m] = tuple(np.abs(diff).max(axis=0).tolist())
    res, _ = compare_elevation(model, {m: r.q_rad for m, r in recs.items()}, targets.time_s, plane)
    sc = (info or {}).get("scapula") or {}
    used = bool(sc.get("used"))
    return ScapulaVariant(
        motion_fit=("used" if used else ("refused" if sc else "none")), reason=sc.get("reason"),
        contact_rms_before_mm=sc["contact_distance_before_mm"]["movement"]["all"]["rms"] if used else None,
        contact_rms_after_mm=sc["contact_distance_after_mm"]["movement"]["all"]["rms"] if used else None,
        determined_directions=sc.get("determined_directions") if used else None,
        marker_rmse_mm=rmse, st_model_minus_data_rmse_deg=st_rmse, st_model_minus_data_max_deg=st_max,
        ludewig_deviation_deg={k: tuple(res["pf"][k]["deviation_deg"]) for k in ST_KEYS},
        ludewig_share_inside_corridor={k: float(res["pf"][k]["share_inside_corridor"]) for k in ST_KEYS},
        data_ac_from_model_sc_mm=(float(np.nanmin(clavicle)), float(np.nanmax(clavicle))), model_clavicle_mm=length)


def _trc_like(sim):
    P = sim.trajectories.positions_m
    ix = {n: i for i, n in enumerate(sim.trajectories.labels)}
    cols = {"ij": P[:, ix["IJ"]], "centijc7": (P[:, ix["IJ"]] + P[:, ix["C7"]]) / 2,
            "centpxt8": (P[:, ix["PX"]] + P[:, ix["T8"]]) / 2, "aa": P[:, ix["AA"]], "ts": P[:, ix["TS"]],
            "ai": P[:, ix["AI"]], "gu": P[:, ix["GH"]], "EpL": P[:, ix["EL"]], "centelbow": P[:, ix["EJC"]]}
    return dataclasses.replace(sim.trajectories, labels=tuple(cols), positions_m=np.stack(list(cols.values()), axis=1))


def simulated_subject(*, rate_hz: float = 50.0, duration_s: float = 5.0) -> ScapulaSimulated:
    """The simulated subject of the module docstring: the flexion's ST angles against the truth
    after a calibration at rest only and with the abduction's scapula postures."""
    generic, protocol = load_model_and_protocol(protocol_path=shipped_file("exubio.protocols", REAL_PROTOCOL,
                                                                           "protocols"))
    e = generic.ellipsoid
    subject = dataclasses.replace(generic, ellipsoid=dataclasses.replace(
        e, centre_m=np.asarray(e.centre_m) + np.array(SIM_SHIFT_M),
        radii_m=np.asarray(e.radii_m) * np.array(SIM_RADII_FACTOR)))
    sims = {m: simulate_trial(subject, m, duration_s=duration_s, rate_hz=rate_hz, marker_names=_SIM_POINTS,
                              lab_transform=False) for m in ("abduction", "flexion")}
    traj = {m: _trc_like(s) for m, s in sims.items()}
    n = 40
    static = dataclasses.replace(traj["abduction"], positions_m=np.repeat(traj["abduction"].positions_m[:1], n, axis=0),
                                 time_s=np.arange(n) / rate_hz)
    tg = {m: prepare_targets(t, protocol) for m, t in traj.items()}
    kin = Kinematics(subject)
    true_contacts = kin.points(sims["flexion"].q_true, kin.contacts)
    st_true = np.degrees(isb_angles(subject, sims["flexion"].q_true)["ST"])
    errs, off = {}, {}
    for label, kw in (("static", {}), ("static_motion", {"scapula_motion": tg["abduction"]})):
        model, _ = calibrate_model(generic, protocol, static, **kw)
        rec = reconstruct(model, calibrated_protocol(protocol, model), tg["flexion"], method="ls")
        d = np.degrees(isb_angles(model, rec.q_rad)["ST"]) - st_true
        errs[label] = tuple(np.abs(d).max(axis=0).tolist())
        off[label] = float(np.abs(surface_distance(model.ellipsoid, true_contacts)).max() * 1000.0)
    return ScapulaSimulated(
        description=(f"generic model with its ellipsoid centre moved {np.round(np.array(SIM_SHIFT_M) * 1000, 1).tolist()} "
                     f"mm and radii x {list(SIM_RADII_FACTOR)}; thoracoscapular_9 markers on the landmarks, noise-free, "
                     f"{duration_s:g} s at {rate_hz:g} Hz; calibrated on a static pose and the abduction, the flexion "
                     f"reconstructed (LS)"),
        st_max_error_deg=errs, flexion_contacts_max_off_ellipsoid_mm=off)


def scapula_cross_validation(s: ValidationSettings, progress: Progress) -> ScapulaCrossValidation:
    """The section (module docstring); the real part is Skipped, with the reason, without the data."""
    progress("scapula calibration: simulated subject")
    sim = simulated_subject()
    why = None if s.real_trials else "not used in this run (ValidationSettings.real_trials is False)"
    if why is None:
        why = next((w for w in (why_no_real_trial(n) for n in REAL_TRIALS) if w), None)
    if why is not None:
        return ScapulaCrossValidation(simulated=sim, real={}, real_skipped=why)
    generic, protocol = load_model_and_protocol(protocol_path=shipped_file("exubio.protocols", REAL_PROTOCOL,
                                                                           "protocols"))
    folder = shared_data_dir() / "trc"
    traj = {n: read_trial(folder / f) for n, f in REAL_TRIALS.items()}
    tg = {n: prepare_targets(t, protocol) for n, t in traj.items()}
    directions = {}
    for cal, rec in (("flexion", "abduction"), ("abduction", "flexion")):
        progress(f"scapula calibration: calibrate on {REAL_TRIALS[cal]}, reconstruct {REAL_TRIALS[rec]}")
        variants = {}
        for key, source, motion in (("own_still", rec, None), ("cal_still", cal, None),
                                    ("cal_still_motion", cal, tg[cal]),
                                    ("pooled_not_cross_validated", cal, (tg[cal], tg[rec]))):
            try:
                model, report = calibrate_model(generic, protocol, traj[source], targets=tg[source],
                                                scapula_motion=motion)
                variants[key] = _variant(model, calibrated_protocol(protocol, model), tg[rec], LUDEWIG_PLANE[rec],
                                         report.functional)
            except ExubioError as exc:
                variants[key] = Skipped(skipped=f"failed: {exc}")
        directions[f"{cal}_to_{rec}"] = ScapulaDirection(calibration_trial=REAL_TRIALS[cal],
                                                         reconstructed_trial=REAL_TRIALS[rec], variants=variants)
    return ScapulaCrossValidation(simulated=sim, real=directions)


def scapula_checks(scv: ScapulaCrossValidation) -> tuple[Check, ...]:
    """The simulated subject's 2 deg. The real TRC subject's aims of issue 21 (ts/ai within 12 mm, ST
    within 5 deg of the data) are withdrawn (issue 33): that subject's aa/ts/ai are one rigid
    registration of an acromion cluster, not bone, so missing them says nothing about the scapula;
    the cross-validation's figures stay on the report's scapula page, and the scapula is judged
    against bone in the bone-truth chapter (exubio.validation.bone)."""
    err = max(scv.simulated.st_max_error_deg.get("static_motion", (np.nan,)))
    return (Check(what="simulated subject (ellipsoid 10 mm, 8 % off): flexion ST max error after the scapula "
                       "calibration on the abduction", value=float(err), limit=2.0, unit="deg", kind="aim",
                  passed=bool(err <= 2.0) if np.isfinite(err) else None),)
