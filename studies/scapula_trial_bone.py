"""The functional scapula calibration (``--scapula-trial``) against bone: does fitting the thorax
ellipsoid through the scapula's skin markers over a movement bring exubio's angles closer to the
bone-pin truth than the static calibration alone?

Every S2M trial of ../shared/data/truth/sta_opendata (Cereatti et al. 2017, J Biomech 62:5-13;
intracortical pins in the scapula and humerus of one subject) is set up as ``exubio truth`` sets it
up (``exubio.truth.lab_run``: the thorax still, a static calibration at the trial's rest frames,
the ellipsoid moved least so that TS and AI lie on it at rest) and reconstructed with LS, with the
thorax ellipsoid

* ``static``: as ``exubio truth`` has it (the static calibration's);
* ``own movement``: fitted by ``exubio.calibration.scapula_motion.fit_scapula_motion`` through the
  scapula postures of the reconstructed trial itself (its skin markers; the calibration's most
  favourable case: the very motion it is judged on);
* ``<task>``: fitted through another task of the same subject (what a lab does: a scapula trial of
  the session); the ellipsoid is taken as fitted, in the thorax frame, which each trial places at
  the same rest landmarks (``exubio.truth.lab_run``);
* ``own, skin fixed``: fitted through the trial's own motion with each skin marker carried rigidly
  by its bone (``setup_lab_run(without_sta=True)``): the same fit with skin that does not slide,
  which separates what the skin does to the fit from what the ellipsoid model can hold.

Per angle: RMSE / max error against the bone (deg), the share of measured frames within +-2u, and
the share of frames measured. The punching trial is left out: its subject moves 0.4 m in the lab,
which the still thorax cannot hold (``python studies/bone_truth.py``: both methods fail there).

    python studies/scapula_trial_bone.py            # ~3 min on one core; markdown to stdout
    python studies/scapula_trial_bone.py --data DIR # the trials of another folder (same format)
    python studies/scapula_trial_bone.py --no-skin-term   # u as before the skin-fitted ellipsoid's term
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import logging
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "truth" / "sta_opendata"
RATE_HZ = 300.0
SHOWN = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_X_elevation",
         "GH_phadke_X_elevation", "GH_phadke_Y_internal_rotation", "HT_X_elevation")
LEFT_OUT = ("punching",)


def _setup(path: Path, *, without_sta: bool = False):
    from exubio.errors import ModelError
    from exubio.io.yaml import read_yaml
    from exubio.model.load import DEFAULT_MODEL
    from exubio.truth.lab_run import setup_lab_run
    from exubio.truth.sta_format import read_sta_trial

    return setup_lab_run(read_sta_trial(path), read_yaml(DEFAULT_MODEL, error=ModelError), rate_hz=RATE_HZ,
                         without_sta=without_sta)


def fitted_ellipsoid(lab):
    """The ellipsoid ``fit_scapula_motion`` fits through ``lab``'s scapula postures and its rest pose,
    on the subject model ``exubio truth`` builds; and the fit's contact RMS before/after (mm)."""
    from exubio.calibration.scapula_motion import fit_scapula_motion
    from exubio.model.load import model_from_mapping
    from exubio.run.inputs import Session
    from exubio.run.pipeline import load_inputs
    from exubio.truth.compare import _protocol

    model = model_from_mapping(dict(lab.model_mapping), f"{lab.trial.path} (subject model)",
                               name=str(lab.model_mapping["name"]))
    protocol = _protocol(lab, model)
    inputs = load_inputs(lab.trajectories, Session(model, protocol, model, protocol))
    static = np.nanmean(inputs.targets.positions_m[lab.rest_frames], axis=0)
    fit = fit_scapula_motion(inputs.model, inputs.protocol, static, inputs.targets)
    return fit


def with_ellipsoid(lab, ellipsoid, *, skin: bool = True):
    mapping = copy.deepcopy(dict(lab.model_mapping))
    mapping["ellipsoid"]["centre_mm"] = [round(float(c) * 1e3, 4) for c in ellipsoid.centre_m]
    mapping["ellipsoid"]["radii_mm"] = [round(float(c) * 1e3, 4) for c in ellipsoid.radii_m]
    if skin:  # what a calibration with a scapula trial records (exubio.trust.angle_uncertainty.ellipsoid_from_skin)
        mapping["calibration"] = {"functional": {"scapula": {"used": True}}}
    return dataclasses.replace(lab, model_mapping=mapping)


def all_frames_rmse(lab, rec) -> dict[str, float]:
    """Each shown angle's RMSE against the bone over every frame the reconstruction solved (deg)."""
    from exubio.model.angles import anatomical_table
    from exubio.model.load import model_from_mapping
    from exubio.truth.compare import truth_angles

    model = model_from_mapping(dict(lab.model_mapping), "subject model", name=str(lab.model_mapping["name"]))
    names, table = anatomical_table(model, rec.q_rad)
    truth = truth_angles(lab)
    out = {}
    for a in SHOWN:
        d = np.angle(np.exp(1j * (table[:, names.index(a)] - truth[a])))
        out[a] = float(np.degrees(np.sqrt(np.nanmean(d ** 2))))
    return out


def _cell(e) -> str:
    if e is None or not np.isfinite(e.rmse_deg):
        return "not measured"
    cov = "-" if e.coverage is None else f"{e.coverage:.0%}"
    return f"{e.rmse_deg:.1f} / {e.max_deg:.1f} / {cov} ({e.measured_fraction:.0%})"


def main(argv=None) -> int:
    from exubio.truth.compare import compare_bone_trial

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder of data-sharing .mat files (S2M)")
    ap.add_argument("--no-skin-term", action="store_true",
                    help="u without the skin-fitted ellipsoid's term (angle_uncertainty.skin_ellipsoid_variance), as before it")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    files = sorted(p for p in args.data.glob("dataSample_S2M_*.mat") if not any(t in p.name for t in LEFT_OUT))
    if not files:
        print(f"{args.data}: no S2M trial; nothing to do", file=sys.stderr)
        return 2
    task = {p: p.stem.split("_")[-1] for p in files}
    skin = not args.no_skin_term
    labs = {p: _setup(p) for p in files}
    fits = {p: fitted_ellipsoid(labs[p]) for p in files}
    fixed = {p: fitted_ellipsoid(_setup(p, without_sta=True)) for p in files}
    print("The ellipsoids fitted (centre shift from the static calibration's, mm; radii scale; the contact points "
          "TS and AI off the surface over the movement, RMS mm, before -> after the fit; the scapula markers' rigid "
          "fit, median frame RMS mm):\n")
    print("| trial | fitted through | centre shift (mm) | radii scale | contact RMS before -> after (mm) | rigid fit RMS (mm) |")
    print("|---|---|---|---|---|---|")
    for p in files:
        for name, f in (("own movement (skin)", fits[p]), ("own movement, skin fixed", fixed[p])):
            d = f.to_dict()
            before = d["contact_distance_before_mm"]["movement"]["all"]["rms"]
            after = d["contact_distance_after_mm"]["movement"]["all"]["rms"]
            print(f"| {task[p]} | {name} | {[round(v) for v in d['centre_shift_mm']]} | {d['radius_scale']} | "
                  f"{before} -> {after} | {d['rigid_fit_frame_rms_mm']['median']} |")
    print()
    for p in files:
        rows = [("static", labs[p]), ("own movement", with_ellipsoid(labs[p], fits[p].ellipsoid, skin=skin))]
        rows += [(task[o], with_ellipsoid(labs[p], fits[o].ellipsoid, skin=skin)) for o in files if o != p]
        rows.append(("own, skin fixed", with_ellipsoid(labs[p], fixed[p].ellipsoid, skin=skin)))
        print(f"### {task[p]} (LS; RMSE / max (deg) / within +-2u (measured))\n")
        print("| ellipsoid | verdict | " + " | ".join(SHOWN) + " |")
        print("|---|---|" + "---|" * len(SHOWN))
        every = []
        for name, lab in rows:
            comp, recs = compare_bone_trial(lab, methods=("ls",))
            print(f"| {name} | {comp.verdicts['ls']} | " + " | ".join(_cell(comp.angles[a]["ls"]) for a in SHOWN) + " |",
                  flush=True)
            every.append((name, all_frames_rmse(lab, recs["ls"])))
        print(f"\n{task[p]}: RMSE over every frame (deg), measured or not (the same frames in every row):\n")
        print("| ellipsoid | " + " | ".join(SHOWN) + " |")
        print("|---|" + "---|" * len(SHOWN))
        for name, r in every:
            print(f"| {name} | " + " | ".join(f"{r[a]:.1f}" for a in SHOWN) + " |")
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
