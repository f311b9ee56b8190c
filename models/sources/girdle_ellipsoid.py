"""The generic model's thorax ellipsoid, fitted through the scapula contact points (TS, AI) of the
model's shoulder girdle driven through Ludewig et al.'s (2009) mean rhythm in the coronal,
scapular and sagittal planes (HT elevation 0-120 deg every 5 deg; exubio.synth.simulate.rhythm_poses:
Ludewig's SC and ST changes applied to the reference posture, no constraint), as the paper fitted
its ellipsoid from several static elevations.

1. Least squares of the radial distance of the 150 points from an ellipsoid aligned with the
   thorax axes, centred on the mid-sagittal plane (a symmetric thorax)
   (exubio.calibration.ellipsoid.fit_ellipsoid_to_points).
2. The least change of that ellipsoid (centre in the sagittal plane, common radius factor;
   exubio.calibration.fit_ellipsoid) that puts TS and AI of the reference posture exactly on it,
   so that the model's zero posture satisfies its constraints.

Prints the fit's residuals and the model file's ``ellipsoid`` block.

Usage: python models/sources/girdle_ellipsoid.py [models/upper_extremity.yaml]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from exubio.calibration import fit_ellipsoid
from exubio.calibration.ellipsoid import fit_ellipsoid_to_points, surface_distance
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.synth.simulate import rhythm_poses

PLANES = ("frontal", "scapular", "sagittal")
HT_DEG = np.arange(0.0, 120.0 + 1e-9, 5.0)


def main(argv: list[str]) -> int:
    path = Path(argv[0]) if argv else Path(__file__).resolve().parents[1] / "upper_extremity.yaml"
    model = load_model(path)
    kin = Kinematics(model)
    pts = np.concatenate([kin.points(rhythm_poses(model, plane, HT_DEG), kin.contacts) for plane in PLANES])
    fitted, r = fit_ellipsoid_to_points(pts.reshape(-1, 3), centre_z_m=0.0)
    print(f"least squares through {pts.shape[0] * 2} contact points: radial residual RMS {np.sqrt(np.mean(r ** 2)) * 1e3:.2f} mm, "
          f"max {np.abs(r).max() * 1e3:.2f} mm")
    rest = kin.points(np.zeros(model.n_coordinates), kin.contacts)
    final, k = fit_ellipsoid(type(fitted)(fitted.centre_m, fitted.radii_m, model.ellipsoid.contact_points), rest)
    rr = surface_distance(final, pts.reshape(-1, 3))
    print(f"through the reference posture's TS and AI (radii x {k:.4f}): residual over the rhythm RMS "
          f"{np.sqrt(np.mean(rr ** 2)) * 1e3:.2f} mm, max {np.abs(rr).max() * 1e3:.2f} mm")
    for plane_i, plane in enumerate(PLANES):
        seg = rr.reshape(len(PLANES), -1)[plane_i]
        print(f"  {plane:<9} RMS {np.sqrt(np.mean(seg ** 2)) * 1e3:.2f} mm, max {np.abs(seg).max() * 1e3:.2f} mm")
    c, rad = final.centre_m * 1e3, final.radii_m * 1e3
    print("\nellipsoid:")
    print(f"  centre_mm: [{c[0]:.6f}, {c[1]:.6f}, {c[2]:.6f}]")
    print(f"  radii_mm: [{rad[0]:.6f}, {rad[1]:.6f}, {rad[2]:.6f}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
