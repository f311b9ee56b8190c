"""What one ellipsoid can carry of the TRC subject's scapula paths (issue 21): the ts/ai contact
points of the registered scapula (its rigid fit to aa/ts/ai in every third frame) against
ellipsoids fitted to one trial (cross-validated on the other) or to both (pooled, the ceiling):

* thorax-aligned (centre 3 + radii 3, exubio's model) and rotated (3 more parameters);
* aligned with the two contact points free on the scapula as well (6 more parameters, prior SD
  10 / 20 mm): how far the points would have to move from TS/AI;
* the clavicle the data imply: the distance from the model's SC (fixed on the thorax) to AC of the
  registered scapula in each frame, against the model's rigid clavicle length (no ellipsoid can
  make up for an AC that does not stay on that sphere); and the sphere the data's AC path does lie
  on (a functional SC, fitted on one trial, tried on the other).

Printed: RMS distance (mm) of the fitted and of the other trial's contact points from the surface.
The calibration itself is exubio.calibration.scapula_motion (aligned, contact points at TS/AI).

Usage:  python studies/scapula_surface_limits.py     (needs ../shared/data/trc; ~20 s)
"""
from __future__ import annotations

import logging
import sys

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from exubio.calibration import calibrate_model, calibrated_protocol
from exubio.calibration.cluster import cluster_poses
from exubio.calibration.scapula_motion import scapula_markers
from exubio.io.trial import read_trial
from exubio.model.kinematics import Kinematics
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.io.resources import shipped_file
from exubio.validation.paths import shared_data_dir
from exubio.validation.scapula import data_clavicle_mm, registered_scapula_poses


def radial(p, x, rotated):
    c, r = p[:3], np.exp(p[3:6])
    R = Rotation.from_rotvec(p[6:9]).as_matrix() if rotated else np.eye(3)
    y = (x - c) @ R
    f = np.sqrt(((y / r) ** 2).sum(axis=-1))
    return np.linalg.norm(y, axis=-1) * (1.0 - 1.0 / f)


def rms_mm(d):
    return float(np.sqrt(np.mean(d**2)) * 1000.0)


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    folder = shared_data_dir() / "trc"
    names = {"ABD01": "tsm_rmr_ABD01.trc", "FLX01": "tsm_rmr_FLX01.trc"}
    if not all((folder / f).exists() for f in names.values()):
        print(f"needs {folder}", file=sys.stderr)
        return 2
    generic, protocol = load_model_and_protocol(protocol_path=shipped_file("exubio.protocols", "thoracoscapular_9.yaml",
                                                                           "protocols"))
    traj = {n: read_trial(folder / f) for n, f in names.items()}
    tg = {n: prepare_targets(t, protocol) for n, t in traj.items()}
    model, _ = calibrate_model(generic, protocol, traj["FLX01"], targets=tg["FLX01"])
    bound = calibrated_protocol(protocol, model)
    idx = scapula_markers(model, bound, tg["FLX01"].positions_m[0])
    local = np.array([bound.markers[j].local_position_m for j in idx])
    poses = {n: cluster_poses(local, t.positions_m[::3, idx])[:2] for n, t in tg.items()}
    pts = model.segment("scapula").points
    c0 = np.array([pts["TS"], pts["AI"]])

    def contacts(n, shift=None):
        R, t = poses[n]
        c = c0 if shift is None else c0 + shift.reshape(2, 3)
        return (np.einsum("nab,kb->nka", R, c) + t[:, None]).reshape(-1, 3)

    e = model.ellipsoid
    p0 = np.r_[e.centre_m, np.log(e.radii_m), 0.0, 0.0, 0.0]
    print("ellipsoid through the contact points: RMS distance (mm) of the fitted / the other trial's")
    for label, train, test in (("pooled (not cross-validated)", ("ABD01", "FLX01"), ("ABD01", "FLX01")),
                               ("FLX01 -> ABD01", ("FLX01",), ("ABD01",)), ("ABD01 -> FLX01", ("ABD01",), ("FLX01",))):
        X = np.concatenate([contacts(n) for n in train])
        Y = np.concatenate([contacts(n) for n in test])
        for rotated in (False, True):
            sol = least_squares(lambda p, X=X, rotated=rotated: np.r_[radial(p, X, rotated), 1e-3 * (p - p0)], p0)
            print(f"  {label:<30} {'rotated' if rotated else 'aligned':<8} {rms_mm(radial(sol.x, X, rotated)):5.1f} / "
                  f"{rms_mm(radial(sol.x, Y, rotated)):5.1f}" + (f"  (rotated {np.degrees(np.linalg.norm(sol.x[6:])):.0f} deg)"
                                                                  if rotated else ""))
    print("aligned, contact points free on the scapula too (prior SD on their shift):")
    for cal, other in (("FLX01", "ABD01"), ("ABD01", "FLX01")):
        for sd in (0.01, 0.02):
            def resid(p, cal=cal, sd=sd):
                return np.r_[radial(p[:9], contacts(cal, p[9:]), False) / 0.005, (p[:3] - p0[:3]) / 0.02,
                             (p[3:6] - p0[3:6]) / 0.15, p[9:] / sd]
            sol = least_squares(resid, np.r_[p0, np.zeros(6)], loss="soft_l1")
            p = sol.x
            shift = np.linalg.norm(p[9:].reshape(2, 3), axis=1) * 1000
            print(f"  {cal} -> {other} SD {sd * 1000:.0f} mm: {rms_mm(radial(p[:9], contacts(cal, p[9:]), False)):4.1f} / "
                  f"{rms_mm(radial(p[:9], contacts(other, p[9:]), False)):4.1f} mm; TS, AI moved "
                  f"{shift[0]:.0f}, {shift[1]:.0f} mm")
    poses_all = {n: registered_scapula_poses(model, bound, t) for n, t in tg.items()}  # every frame
    clavicle = {n: data_clavicle_mm(model, bound, tg[n], poses_all[n]) for n in names}  # the validation's figure
    length = clavicle["FLX01"][1]
    print(f"the clavicle the data imply: |AC - SC| of the registered scapula in every frame (model: rigid, {length:.1f} mm):")
    for n in names:
        d = clavicle[n][0]
        print(f"  {n}: {d.min():.1f}-{d.max():.1f} mm (SD {d.std():.1f}); AC up to {np.abs(d - length).max():.1f} mm "
              f"off the model's sphere about SC")
    # the sphere the data's AC path does lie on: a functional SC (as SCoRE finds GH), fitted on one
    # trial and tried on the other, with a prior holding its centre near the model's SC
    kin = Kinematics(model)
    sc = kin.points(np.zeros(kin.n_coordinates), kin.point_set([("clavicle", "SC")]))[0]
    ac = model.segment("scapula").points["AC"]
    paths = {n: R @ ac + t for n, (R, t) in poses_all.items()}
    print("the sphere the data's AC paths lie on (centre prior SD about the model's SC; residual RMS / max, mm):")
    for sd in (0.005, 0.02):
        for cal, other in (("FLX01", "ABD01"), ("ABD01", "FLX01")):
            sol = least_squares(lambda p, cal=cal, sd=sd: np.r_[(np.linalg.norm(paths[cal] - p[:3], axis=1) - p[3]) / 0.002,
                                                               (p[:3] - sc) / sd], np.r_[sc, length / 1000.0])
            c, r = sol.x[:3], sol.x[3]
            res = {n: (np.linalg.norm(paths[n] - c, axis=1) - r) * 1000.0 for n in (cal, other)}
            print(f"  SD {sd * 1000:.0f} mm, fitted on {cal}: centre {np.linalg.norm(c - sc) * 1000:.0f} mm from the model's SC "
                  f"({', '.join(f'{v:+.0f}' for v in (c - sc) * 1000)} mm, thorax x/y/z), radius {r * 1000:.0f} mm; "
                  + "; ".join(f"{n} {np.sqrt(np.mean(v**2)):.1f} / {np.abs(v).max():.1f}" for n, v in res.items()))
    # or the clavicle's attachment re-registered on the scapula: the point of the scapula that stays
    # at one distance from the model's SC (a functional AC), fitted on one trial, tried on the other
    print("a functional AC: the scapula's point at one distance from the model's SC (prior SD about AC; "
          "residual RMS / max, mm):")
    for sd in (0.01, 0.02):
        for cal, other in (("FLX01", "ABD01"), ("ABD01", "FLX01")):
            R, t = poses_all[cal]
            sol = least_squares(lambda p, R=R, t=t, sd=sd: np.r_[(np.linalg.norm(R @ p[:3] + t - sc, axis=1) - p[3]) / 0.002,
                                                                 (p[:3] - ac) / sd], np.r_[ac, length / 1000.0])
            q, r = sol.x[:3], sol.x[3]
            res = {n: (np.linalg.norm(poses_all[n][0] @ q + poses_all[n][1] - sc, axis=1) - r) * 1000.0
                   for n in (cal, other)}
            print(f"  SD {sd * 1000:.0f} mm, fitted on {cal}: AC moved {np.linalg.norm(q - ac) * 1000:.0f} mm, clavicle "
                  f"{r * 1000:.0f} mm; " + "; ".join(f"{n} {np.sqrt(np.mean(v**2)):.1f} / {np.abs(v).max():.1f}"
                                                    for n, v in res.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
