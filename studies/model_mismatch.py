"""Model mismatch: what a perturbed generating model costs on the measured angles, and what the
residuals show of it.

For a grid of perturbations (exubio.synth.perturb.ModelPerturbation: ellipsoid centre and radii, segment
lengths, joint centres, marker offsets, each at 2-3 sizes) x motions (abduction, flexion, scaption)
x artefact (none; noise + soft-tissue artefact), a trial is simulated with the perturbed model and
reconstructed with the generic one (LS; ``--methods ls,pf`` adds PF). Printed per run: the RMSE and
max error (deg) of every anatomical angle over the frames where it is measured (the truth: the
perturbed model's angles; the anatomical frames are the same in both models for these
perturbations), and per segment the residual features of exubio.trust.mismatch.segment_evidence, and the
detector's verdict (exubio.trust.mismatch.mismatch_findings). ``--seeds N`` repeats the no-mismatch runs
with N noise/STA realisations (the false-alarm rate on simulations).

Usage:
    python studies/model_mismatch.py                      # the grid, LS, 5 s at 50 Hz (~10 min on 1 core)
    python studies/model_mismatch.py --only ellipsoid --json out.jsonl
    python studies/model_mismatch.py --seeds 5 --only none
    python studies/model_mismatch.py --artefacts clean,noise1_sta10,noise1_sta20 --seeds 3 --json grid.jsonl
    python studies/model_mismatch.py --summary grid.jsonl   # rates per perturbation
    python studies/model_mismatch.py --real-refit   # the real trials: evidence before/after refitting the ellipsoid

``--real-refit``: every real trial of ../shared/data (calibrated as studies/trust_real_trials.py
does, relabelled where its session needs it) is reconstructed (LS), then again with the thorax
ellipsoid refitted (exubio.calibration.ellipsoid.fit_ellipsoid_poses) through the contact points TS
and AI of the scapula's own rigid fit to its markers in every frame: if the scapula evidence was
a wrong ellipsoid, it drops, and the ST angles move by what the first reconstruction had wrong.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time

import numpy as np

from exubio.io.records import to_json
from exubio.protocol.bind import bind
from exubio.trust.assess import assess_trial
from exubio.model.kinematics import Kinematics
from exubio.protocol.bind import tracked_points
from exubio.trust.mismatch import segment_evidence
from exubio.synth.perturb import ModelPerturbation
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.synth.simulate import simulate_trial
from exubio.validation.mismatch import measured_angle_errors

P = ModelPerturbation
PERTURBATIONS: dict[str, ModelPerturbation] = {
    "none": P(),
    "ellipsoid_post5_4pc": P(ellipsoid_centre_mm=(-5, 0, 0), ellipsoid_radii_scale=(1.04,) * 3),
    "ellipsoid_post10_8pc": P(ellipsoid_centre_mm=(-10, 0, 0), ellipsoid_radii_scale=(1.08,) * 3),
    "ellipsoid_post10": P(ellipsoid_centre_mm=(-10, 0, 0)),
    "ellipsoid_8pc": P(ellipsoid_radii_scale=(1.08,) * 3),
    "ellipsoid_ant10_minus8pc": P(ellipsoid_centre_mm=(10, 0, 0), ellipsoid_radii_scale=(0.92,) * 3),
    "ellipsoid_y_radius_1.15": P(ellipsoid_radii_scale=(1.0, 1.15, 1.0)),
    "ellipsoid_x_radius_1.15": P(ellipsoid_radii_scale=(1.15, 1.0, 1.0)),
    "ellipsoid_sup15": P(ellipsoid_centre_mm=(0, 15, 0)),
    "length_clavicle_1.10": P(segment_length_scale={"clavicle": 1.10}),
    "length_clavicle_0.90": P(segment_length_scale={"clavicle": 0.90}),
    "length_scapula_1.10": P(segment_length_scale={"scapula": 1.10}),
    "length_humerus_1.10": P(segment_length_scale={"humerus": 1.10}),
    "length_humerus_0.90": P(segment_length_scale={"humerus": 0.90}),
    "joint_gh_lat10": P(joint_centre_mm={"humerus": (0, 0, 10)}),
    "joint_gh_sup15_post10": P(joint_centre_mm={"humerus": (-10, 15, 0)}),
    "joint_ac_10": P(joint_centre_mm={"scapula": (0, 10, 0)}),
    "joint_sc_10": P(joint_centre_mm={"clavicle": (0, 10, 0)}),
    "marker_scap_ia_20": P(marker_offset_mm={"SCAP_IA": (0, -20, 0)}),
    "marker_scap_ia_10": P(marker_offset_mm={"SCAP_IA": (0, 0, 10)}),
    "marker_epi_lat_15": P(marker_offset_mm={"EPI_lat": (0, 15, 0)}),
    "marker_arm_delt_15": P(marker_offset_mm={"ARM": (10, 0, 10), "DELT": (10, 0, 10)}),
}
MOTIONS = ("abduction", "flexion", "scaption")
ARTEFACTS = {"clean": (0.0, 0.0), "noise1_sta10": (1.0, 10.0), "noise1_sta20": (1.0, 20.0)}


def run(name: str, pert: ModelPerturbation, motion: str, artefact: str, *, methods, duration, rate, seed,
        calibrate: bool = False) -> dict:
    model, protocol = load_model_and_protocol()
    noise, sta = ARTEFACTS[artefact]
    sim = simulate_trial(model, motion, duration_s=duration, rate_hz=rate, noise_mm=noise, sta_mm=sta, seed=seed,
                         perturbation=pert)
    targets = prepare_targets(sim.trajectories, protocol)
    if calibrate:  # as a lab would: the generic model calibrated on the trial's first, still, frames
        from exubio.calibration import calibrate_model, calibrated_protocol

        model, _ = calibrate_model(model, protocol, sim.trajectories, frames=slice(0, max(2, int(0.1 * rate))),
                                   targets=targets)
        protocol = calibrated_protocol(protocol, model)
    recons = [reconstruct(model, protocol, targets, method=m) for m in methods]
    assessment = assess_trial(bind(model, protocol), targets, recons)
    kin = Kinematics(model)
    points = tracked_points(kin, protocol)
    rec = {"perturbation": name, "words": list(pert.words()), "motion": motion, "artefact": artefact, "seed": seed,
           "calibrated": calibrate, "methods": {}}
    for r in recons:
        ang = assessment.angles[r.method]
        errs = {k: {"rmse": v[0], "max": v[1]}
                for k, v in measured_angle_errors(model, sim.model, r.q_rad, sim.q_true, ang.status).items()}
        worst = max(errs, key=lambda k: errs[k]["rmse"])
        ev = segment_evidence(kin, points, r.q_rad, targets.positions_m)
        q = assessment.quality[r.method]
        rec["methods"][r.method] = {
            "angle_errors_deg": {k: {kk: round(vv, 2) for kk, vv in v.items()} for k, v in errs.items()},
            "worst_angle": worst, "worst_rmse_deg": round(errs[worst]["rmse"], 2),
            "worst_max_deg": round(max(v["max"] for v in errs.values()), 2),
            "mean_residual_mm": round(float(np.nanmean(r.residuals_m)) * 1e3, 2),
            "evidence": {k: to_json(v) for k, v in ev.items()},
            "verdict": q.verdict, "reasons": [f"{x.level}: {x.message}" for x in q.reasons if x.level != "note"],
            "mismatch_reasons": [x.message for x in q.reasons if x.code == "model_mismatch"],
        }
    return rec


def real_refit() -> None:
    """See the module docstring (--real-refit)."""
    import tempfile
    from pathlib import Path

    import dataclasses

    from exubio.model.angles import anatomical_table
    from exubio.calibration.ellipsoid import fit_ellipsoid_poses
    from exubio.io.trial import read_trial
    from exubio.trust.mismatch import rigid_fit
    from exubio.model.load import load_model
    from exubio.run.inputs import load_session, protocol_for_model
    from exubio.run.session import calibrate_session
    from exubio.validation.trials import real_trial

    root = Path(__file__).resolve().parents[1]
    shared = root.parent / "shared" / "data"
    session = root / "protocols" / "examples" / "kinova_martin_session.yaml"
    c3d = shared / "c3d"
    specs = [(c3d / f"bioptim_exo_kinova_martin_{n}_f3_1.c3d", c3d / "bioptim_exo_kinova_martin_statique.c3d", session)
             for n in ("aisselle", "dent", "manger", "tete")]
    specs.append((c3d / "bioptim_exo_martin_dynamique.c3d", c3d / "bioptim_exo_martin_statique.c3d", None))
    with tempfile.TemporaryDirectory() as tmp:
        runs = []
        for trial, static, prot in specs:
            mf = calibrate_session(static, load_session(protocol_path=prot), Path(tmp) / trial.stem, "static").model_file
            model = load_model(mf)
            protocol = protocol_for_model(model, prot)
            runs.append((trial.name, model, protocol, prepare_targets(read_trial(trial), protocol)))
        for name in ("abduction", "flexion"):
            got = real_trial(name)
            if got is not None:
                runs.append((f"TRC {name}", got[0], got[1], got[2]))
        for label, model, protocol, targets in runs:
            kin = Kinematics(model)
            points = tracked_points(kin, protocol)
            r1 = reconstruct(model, protocol, targets, method="ls")
            ev1 = segment_evidence(kin, points, r1.q_rad, targets.positions_m)["scapula"]
            si = model.segment_index("scapula")
            cols = np.flatnonzero(points.segment_index == si)
            ok = np.isfinite(targets.positions_m[:, cols]).all(axis=(1, 2))
            Rf, tf = rigid_fit(points.local_m[cols], targets.positions_m[ok][:, cols])
            contacts = [np.einsum("nij,j->ni", Rf, np.asarray(model.segment(s).points[p])) + tf
                        for s, p in model.ellipsoid.contact_points]
            ell, k = fit_ellipsoid_poses(model.ellipsoid, np.concatenate(contacts))
            model2 = dataclasses.replace(model, ellipsoid=ell)
            kin2 = Kinematics(model2)
            r2 = reconstruct(model2, protocol, targets, method="ls")
            ev2 = segment_evidence(kin2, tracked_points(kin2, protocol), r2.q_rad, targets.positions_m)["scapula"]
            names, a1 = anatomical_table(model, r1.q_rad)
            _, a2 = anatomical_table(model2, r2.q_rad)
            d = np.degrees(np.angle(np.exp(1j * (a2 - a1))))  # wrapped to +-180
            st = {n: float(np.sqrt(np.mean(d[:, j] ** 2))) for j, n in enumerate(names) if n.startswith(("ST_", "GH_"))}
            moved = np.asarray(ell.centre_m) - np.asarray(model.ellipsoid.centre_m)
            print(f"{label:40s} scapula gap {ev1.pose_gap_deg:.1f} -> {ev2.pose_gap_deg:.1f} deg, bias {ev1.bias_mm:.1f} -> "
                  f"{ev2.bias_mm:.1f} mm, normal {ev1.normal_mm:+.1f} -> {ev2.normal_mm:+.1f} mm, residual "
                  f"{ev1.residual_rms_mm:.1f} -> {ev2.residual_rms_mm:.1f} mm; ellipsoid moved "
                  f"{np.round(moved * 1e3, 1).tolist()} mm, radii x{k:.3f}; angle change RMS (deg): "
                  + ", ".join(f"{n} {v:.1f}" for n, v in st.items() if v > 1.0), flush=True)


def summarise(path: str) -> None:
    """Per perturbation: what it costs (clean runs), how often the check names it, which segment."""
    import collections

    rows = [json.loads(line) for line in open(path)]
    by = collections.defaultdict(list)
    for r in rows:
        by[r["perturbation"]].append(r)
    cost = {(r["perturbation"], r["motion"], m): v["worst_rmse_deg"] for r in rows if r["artefact"] == "clean"
            for m, v in r["methods"].items()}
    print(f"{'perturbation':26s} {'cost clean (deg)':17s} {'worst with artefact':20s} {'flagged':9s} "
          f"{'costly & flagged':17s} segments named")
    for name, rs in by.items():
        runs = [(r, m, v) for r in rs for m, v in r["methods"].items()]
        cc = [v["worst_rmse_deg"] for r, m, v in runs if r["artefact"] == "clean"]
        allw = [v["worst_rmse_deg"] for r, m, v in runs]
        flagged = [(r, m, v) for r, m, v in runs if v["mismatch_reasons"]]
        costly = [(r, m, v) for r, m, v in runs if cost.get((r["perturbation"], r["motion"], m), 0) > 5.0]
        caught = [x for x in costly if x[2]["mismatch_reasons"]]
        segs = sorted({reason.split(":")[0].replace("model mismatch on the ", "") for _, _, v in flagged
                       for reason in v["mismatch_reasons"]})
        print(f"{name:26s} {min(cc):5.1f}-{max(cc):5.1f}       {min(allw):5.1f}-{max(allw):5.1f}          "
              f"{len(flagged):3d}/{len(runs):<3d}  {len(caught):3d}/{len(costly):<3d}          {', '.join(segs)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default="", help="perturbations whose name contains this (comma-separated)")
    ap.add_argument("--motions", default=",".join(MOTIONS))
    ap.add_argument("--artefacts", default="clean,noise1_sta20")
    ap.add_argument("--methods", default="ls")
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--calibrate", action="store_true",
                    help="reconstruct with the generic model calibrated on the trial's first 0.1 s (its static pose)")
    ap.add_argument("--seeds", type=int, default=1, help="noise/STA realisations of each run with artefact")
    ap.add_argument("--json", default="", help="append one JSON line per run to this file")
    ap.add_argument("--real-refit", action="store_true", help="the real trials, before/after refitting the ellipsoid")
    ap.add_argument("--summary", default="", help="summarise a --json file (rates per perturbation) and exit")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    if args.summary:
        summarise(args.summary)
        return 0
    if args.real_refit:
        real_refit()
        return 0
    only = [s for s in args.only.split(",") if s]
    methods = tuple(args.methods.split(","))
    sink = open(args.json, "a") if args.json else None
    for name, pert in PERTURBATIONS.items():
        if only and not any(o in name for o in only):
            continue
        for motion in args.motions.split(","):
            for artefact in args.artefacts.split(","):
                for seed in range(args.seeds if artefact != "clean" else 1):
                    t0 = time.perf_counter()
                    rec = run(name, pert, motion, artefact, methods=methods, duration=args.duration, rate=args.rate,
                              seed=seed, calibrate=args.calibrate)
                    if sink:
                        sink.write(json.dumps(rec) + "\n")
                        sink.flush()
                    for m, v in rec["methods"].items():
                        ev = v["evidence"]
                        feats = "; ".join(
                            f"{s}: bias {e['bias_mm']:.1f} res {e['residual_rms_mm']:.1f}"
                            + (f" gap {e['pose_gap_deg']:.1f}" if e["pose_gap_deg"] is not None else "")
                            + (f" n {e['normal_mm']:.1f}" if e["normal_mm"] is not None else "") for s, e in ev.items())
                        print(f"{name:26s} {motion:9s} {artefact:12s} s{seed} [{m}] worst {v['worst_angle']} "
                              f"{v['worst_rmse_deg']:.1f} (max {v['worst_max_deg']:.1f}) deg; res {v['mean_residual_mm']:.1f} mm; "
                              f"{v['verdict']} {'MISMATCH ' + ' | '.join(v['mismatch_reasons']) if v['mismatch_reasons'] else ''}"
                              f"\n      {feats}  ({time.perf_counter() - t0:.1f} s)", flush=True)
    if sink:
        sink.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
