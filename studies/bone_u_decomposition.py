"""Where the error of a bone trial's angles comes from, against what the uncertainty assumes.

One bone trial reconstructed by LS twice as `exubio truth` sets it up: with the skin markers as
recorded, and with every marker carried rigidly by its bone from where it sits at rest (no soft
tissue). Per angle, over the frames measured in both (every ``--every``-th frame):

* ``total``: the error against the bone with skin; ``rigid``: without skin (the model's girdle and the
  still thorax); ``skin``: their difference, what the skin's artefact did to the angle;
* ``first order``: the artefact the file shows (each skin marker minus the same marker carried by its
  bone, in the thorax frame) carried through the least-squares step's first-order sensitivity at the
  reconstructed pose, D K dm: what the uncertainty's propagation says that artefact does; with the
  slope and correlation of ``skin`` on it;
* ``u artefact``: the RMS of the uncertainty's artefact part alone (noise, misfit and trunk left out:
  the amplitude model through the same D K), and the RMS ratio first order / u artefact: whether the
  amplitude model's statistics describe this trial's artefact.

    python studies/bone_u_decomposition.py ../shared/data/truth/sta_opendata/dataSample_S2M_eating.mat 300
"""
from __future__ import annotations

import argparse
import logging
import warnings

import numpy as np

from exubio.io.yaml import read_yaml
from exubio.model.angles import anatomical_table, distal_only_coordinates, segment_anatomical_rotations
from exubio.model.load import DEFAULT_MODEL
from exubio.run.pipeline import reconstruct
from exubio.trust import angle_uncertainty as AU
from exubio.trust.angle_uncertainty import _driver
from exubio.trust.observability import _angle_jacobian
from exubio.trust.sta_amplitude import shipped_amplitude
from exubio.truth import compare
from exubio.truth.lab_run import setup_lab_run
from exubio.truth.sta_format import read_sta_trial

BINS = ((0, 10), (10, 20), (20, 40), (40, 60), (60, 90), (90, 180))
SHOWN = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_X_elevation",
         "GH_phadke_X_elevation", "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation", "HT_X_elevation",
         "HT_Y_plane_of_elevation", "HT_Y_axial_rotation")


def _solve(run):
    model, inputs = compare.lab_inputs(run)
    rec = reconstruct(inputs.model, inputs.protocol, inputs.targets, method="ls")
    return model, inputs, rec


def rms(x):
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("rate", type=float)
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--angles", nargs="*", default=SHOWN)
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    generic = read_yaml(DEFAULT_MODEL)
    trial = read_sta_trial(args.file)
    skin, rigid = (setup_lab_run(trial, generic, rate_hz=args.rate, without_sta=w) for w in (False, True))
    model, inputs, rec = _solve(skin)
    _, inputs_r, rec_r = _solve(rigid)
    assert inputs.targets.marker_names == inputs_r.targets.marker_names
    names, table = anatomical_table(model, rec.q_rad)
    _, table_r = anatomical_table(model, rec_r.q_rad)
    truth = compare.truth_angles(skin)
    det = compare.angle_status(inputs, rec, still_thorax=False)
    det_r = compare.angle_status(inputs_r, rec_r, still_thorax=False)

    b = inputs.binding
    kin, points = b.kin, b.points
    n = rec.q_rad.shape[0]
    frames = np.arange(0, n, args.every)
    present = inputs.targets.present[frames] & inputs_r.targets.present[frames]
    q = rec.q_rad[frames]
    free = np.flatnonzero(~b.held & ~b.locked)
    K = AU.sensitivity(kin, points, q, present, b.protocol.weights, free)
    tab = lambda qq: anatomical_table(model, qq, kinematics=kin, unwrap=False)[1]
    D = _angle_jacobian(tab, q, distal_only_coordinates(model, kin))
    dm = np.nan_to_num(inputs.targets.positions_m[frames] - inputs_r.targets.positions_m[frames])
    dm = np.where(present[..., None], dm, 0.0).reshape(len(frames), -1)
    pred = np.einsum("bam,bmk,bk->ba", D, K, dm)
    frames_isb = segment_anatomical_rotations(model, q, kinematics=kin)
    anat = {s: frames_isb[s] for s in ("scapula", "humerus")}
    amp = shipped_amplitude()
    sig = AU.marker_covariance(kin, points, q, present, amp, noise_mm=0.0, anatomical=anat)
    u_art = np.sqrt(np.maximum(AU.quadratic_forms(D @ K, sig), 0.0))
    R, _ = kin.poses(q)
    theta = np.degrees(_driver([sg.name for sg in model.segments], R))
    print(f"{trial.path.name}: {len(frames)} frames (every {args.every}); deg, RMS over frames measured in both runs")
    print(f"{'angle':32s} {'total':>6s} {'rigid':>6s} {'skin':>6s} {'1st ord':>7s} {'slope':>6s} {'corr':>5s} "
          f"{'u art':>6s} {'cov lab':>7s}  skin / u art RMS by theta " + " ".join(f"{lo}-{hi}" for lo, hi in BINS))
    for a in args.angles:
        j, k = names.index(a), det.names.index(a)
        et = compare._wrap(table[frames, j] - truth[a][frames])
        er = compare._wrap(table_r[frames, j] - truth[a][frames])
        es = compare._wrap(table[frames, j] - table_r[frames, j])
        ok = (det.status[frames, k] == 0) & (det_r.status[frames, k] == 0) & np.isfinite(et) & np.isfinite(er)
        if ok.sum() < 5:
            print(f"{a:32s} not measured")
            continue
        p, s_, ua = pred[ok, k], es[ok], u_art[ok, k]
        slope = float(p @ s_ / max(p @ p, 1e-30))
        corr = float(np.corrcoef(p, s_)[0, 1])
        ul = det.uncertainty_rad[frames, k][ok]
        cov = float(np.mean(np.abs(et[ok]) <= 2 * ul))
        d = np.degrees
        print(f"{a:32s} {d(rms(et[ok])):6.2f} {d(rms(er[ok])):6.2f} {d(rms(s_)):6.2f} {d(rms(p)):7.2f} {slope:6.2f} "
              f"{corr:5.2f} {d(rms(ua)):6.2f} {cov:7.0%}  " + " ".join(
                  (f"{d(rms(s_[sel])):.1f}/{d(rms(ua[sel])):.1f}" if (sel := (theta[ok] >= lo) & (theta[ok] < hi)).sum() >= 3
                   else "-") for lo, hi in BINS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
