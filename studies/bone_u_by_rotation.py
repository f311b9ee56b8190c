"""Where the u a lab's run gives falls short on the pins (benchmarks/README.md, "The uncertainty a lab's
run gives, on the pins"): one bone trial reconstructed by LS as `exubio truth` sets it up, each angle's
error against the bone over its measured frames and the u a lab's run gives (no still-thorax term),
binned by the STA amplitude model's driver, the humerus's rotation from rest (theta, deg): per bin the
RMS error, the median u and the coverage of +-2u; overall the coverage and the RMS of error / u.

    python studies/bone_u_by_rotation.py ../shared/data/truth/sta_opendata/dataSample_S2M_eating.mat 300 \\
        ST_X_upward_rotation HT_Y_plane_of_elevation ST_Y_internal_rotation
"""
from __future__ import annotations

import argparse
import logging
import warnings

import numpy as np

from exubio.io.yaml import read_yaml
from exubio.model.angles import anatomical_table
from exubio.model.load import DEFAULT_MODEL
from exubio.run.pipeline import reconstruct
from exubio.trust.angle_uncertainty import _driver
from exubio.truth import compare
from exubio.truth.lab_run import setup_lab_run
from exubio.truth.sta_format import read_sta_trial

BINS_DEG = ((0, 20), (20, 40), (40, 60), (60, 90), (90, 180))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("rate", type=float)
    ap.add_argument("angles", nargs="+")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    run = setup_lab_run(read_sta_trial(args.file), read_yaml(DEFAULT_MODEL), rate_hz=args.rate)
    model, inputs = compare.lab_inputs(run)
    rec = reconstruct(inputs.model, inputs.protocol, inputs.targets, method="ls")
    det = compare.angle_status(inputs, rec, still_thorax=False)  # the u and status a lab's run gives
    names, table = anatomical_table(model, rec.q_rad)
    truth = compare.truth_angles(run)
    R, _ = inputs.binding.kin.poses(rec.q_rad)
    theta = np.degrees(_driver([s.name for s in model.segments], R))
    for a in args.angles:
        j, k = names.index(a), det.names.index(a)
        err = np.degrees(np.abs(compare._wrap(table[:, j] - truth[a])))
        u = np.degrees(det.uncertainty_rad[:, k])
        ok = (det.status[:, k] == 0) & np.isfinite(err)
        print(f"{a}: coverage {np.mean(err[ok] <= 2 * u[ok]):.0%}, RMS of error / u {np.sqrt(np.mean((err[ok] / u[ok]) ** 2)):.2f}")
        for lo, hi in BINS_DEG:
            sel = ok & (theta >= lo) & (theta < hi)
            if sel.sum() > 10:
                print(f"  theta {lo:3d}-{hi:3d} deg: {sel.sum():5d} frames, RMS error {np.sqrt(np.mean(err[sel] ** 2)):5.1f} deg, "
                      f"median u {np.median(u[sel]):5.1f} deg, coverage {np.mean(err[sel] <= 2 * u[sel]):.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
