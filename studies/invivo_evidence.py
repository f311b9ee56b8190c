"""Why the real TRC trials deviate from Ludewig et al. 2009 (issue "In vivo validation like for
like"): per trial and band of humerothoracic (HT) elevation during raising, the plane of
elevation actually used, the residual of each scapula and humerus marker (how far the skin
marker is from where the rigid, ellipsoid-bound scapula can put it), and the ST/GH deviations
from Ludewig in his own frames split into the offset at HT 30 deg and the change after it.

Usage:  python studies/invivo_evidence.py      (needs ../shared/data/trc; about 1 minute)
"""
from __future__ import annotations

import logging
import sys

import numpy as np

from exubio.model.angles import humerothoracic_elevation, isb_angles
from exubio.literature.invivo import compare_elevation, raising
from exubio.run.pipeline import reconstruct
from exubio.validation.trials import LUDEWIG_PLANE, why_no_real_trial
from exubio.validation.trials import real_trial as _real_trial

BANDS = ((30, 60), (60, 90), (90, 120), (120, 150))


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    for name in ("abduction", "flexion"):
        why = why_no_real_trial(name)
        if why:
            print(f"{name}: {why}", file=sys.stderr)
            return 2
        model, protocol, targets, _ = _real_trial(name)
        rec = {m: reconstruct(model, protocol, targets, method=m) for m in ("ls", "pf")}
        q = rec["ls"].q_rad
        ht = np.degrees(humerothoracic_elevation(model, q))
        plane = np.degrees(isb_angles(model, q)["HT"][:, 0])
        rise = raising(ht, targets.time_s)
        resid = rec["ls"].residuals_m * 1000.0
        print(f"\n{name} ({targets.n_frames} frames), LS; medians over raising frames per HT band")
        print(f"{'HT band':>9} {'plane deg':>9} " + " ".join(f"{n + ' mm':>9}" for n in rec["ls"].marker_names))
        for lo, hi in BANDS:
            s = rise & (ht >= lo) & (ht < hi)
            if s.sum() < 3:
                continue
            print(f"{lo:>4}-{hi:<4} {np.median(plane[s]):>9.1f} "
                  + " ".join(f"{np.median(resid[s, j]):>9.1f}" for j in range(resid.shape[1])))
        res, _ = compare_elevation(model, {m: r.q_rad for m, r in rec.items()}, targets.time_s, LUDEWIG_PLANE[name])
        print(f"{'angle (Ludewig frames)':<22} {'PF dev 30/60/90/120':>26} {'offset@30':>9} {'change after 30':>20}")
        for key in ("ST_medRotation_X", "ST_protraction_Y", "ST_tilt_Z", "GH_abduction_X", "GH_flexion_Z",
                    "GH_rotation_Y"):
            e = res["pf"][key]
            print(f"{key:<22} {' / '.join(f'{v:+.1f}' for v in e['deviation_deg']):>26} {e['deviation_deg'][0]:>+9.1f} "
                  f"{' / '.join(f'{v:+.1f}' for v in e['trend_deviation_deg'][1:]):>20}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
