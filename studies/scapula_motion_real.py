"""The functional scapula calibration cross-validated on the thoracoscapular TRC subject (issue 21):
calibrate on one trial, reconstruct the other (FLX01 -> ABD01 and ABD01 -> FLX01), never the trial
it reports; and the simulated subject whose ellipsoid differs from the generic one.

It prints the validation study's own section (exubio.validation.scapula, the numbers of the
report's "scapula calibration" page): per direction and calibration (own still frames; the other
trial's still frames; the other trial's still frames + its movement; both movements pooled, NOT
cross-validated) the contact points' RMS distance from the ellipsoid before -> after the motion
fit, aa/ts/ai RMSE (mm), the model-minus-data ST angles (deg, RMSE and max over HT 30-120) and PF's
deviation from Ludewig et al. 2009 in his frames at HT 30/60/90/120.

Usage:  python studies/scapula_motion_real.py      (real part needs ../shared/data/trc; ~1 minute)
"""
from __future__ import annotations

import logging
import sys

from exubio.validation.scapula import ST_KEYS, scapula_checks, scapula_cross_validation
from exubio.validation.results import ScapulaVariant
from exubio.validation.settings import ValidationSettings

LABEL = {"own_still": "own still frames", "cal_still": "other trial's still frames",
         "cal_still_motion": "other trial's still frames + motion",
         "pooled_not_cross_validated": "both motions pooled (NOT cross-validated)"}
ANGLES = ("internal rotation", "upward rotation", "tilt")


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    scv = scapula_cross_validation(ValidationSettings(), lambda msg: print(f"# {msg}", file=sys.stderr))
    sim = scv.simulated
    print("simulated subject:", sim.description)
    for k, v in sim.st_max_error_deg.items():
        print(f"  {k:<14} flexion ST max error (int.rot / upward / tilt): {' / '.join(f'{x:.2f}' for x in v)} deg; "
              f"true contact points up to {sim.flexion_contacts_max_off_ellipsoid_mm[k]:.2f} mm off the ellipsoid")
    if scv.real_skipped:
        print(f"real TRC subject: {scv.real_skipped}")
    for d in scv.real.values():
        print(f"\n=== calibrate on {d.calibration_trial}, reconstruct {d.reconstructed_trial} ===")
        for key, v in d.variants.items():
            if not isinstance(v, ScapulaVariant):
                print(f"-- {LABEL[key]}: {v.skipped}")
                continue
            fit = (f"contact points {v.contact_rms_before_mm:.1f} -> {v.contact_rms_after_mm:.1f} mm RMS off the "
                   f"ellipsoid, {v.determined_directions} of 6 directions determined" if v.motion_fit == "used"
                   else f"motion fit {v.motion_fit}" + (f": {v.reason}" if v.reason else ""))
            print(f"-- {LABEL[key]}: {fit}")
            for m in ("ls", "pf"):
                mk = v.marker_rmse_mm[m]
                print(f"   {m.upper()}: RMSE aa/ts/ai {mk['aa']:.1f} / {mk['ts']:.1f} / {mk['ai']:.1f} mm; model-minus-data ST "
                      f"RMSE {' / '.join(f'{x:.1f}' for x in v.st_model_minus_data_rmse_deg[m])} deg, max "
                      f"{' / '.join(f'{x:.1f}' for x in v.st_model_minus_data_max_deg[m])} deg (int.rot / upward / tilt)")
            for k in ST_KEYS:
                print(f"   PF - Ludewig {k:<17} at HT 30/60/90/120: "
                      f"{' / '.join(f'{x:+.1f}' for x in v.ludewig_deviation_deg[k])} deg; inside corridor "
                      f"{v.ludewig_share_inside_corridor[k]:.0%}")
    print("\naims (issue 21):")
    for c in scapula_checks(scv):
        print(f"  {'met' if c.passed else 'NOT met'}: {c.what}: {c.value:.2f} {c.unit} (aim <= {c.limit:g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
