"""A soft-tissue-artefact model from bone pins: how well it reproduces held-out tasks, and what it
costs exubio's angles on simulated trials beside the per-marker model.

Table 1 (leave one task out): exubio.synth.sta_validate on the four S2M pin trials of
../shared/data/truth/sta_opendata (Cereatti et al. 2017, J Biomech 62:5-13, doi
10.1016/j.jbiomech.2017.02.004; S2M, one subject, left arm, 300 Hz): per held-out task and segment,
the RMS of the data, the RMS of the residual after the model and R^2 (about zero) of the cluster's
rigid rotation (deg), of its centroid's translation (mm) and of every skin marker's displacement over
the bone (mm; the model's rigid part against the whole artefact); the non-rigid rest's RMS (mm per
coordinate). Then the model fitted on all four S2M tasks scored on the ARTANIM fluoroscopy trial
(another subject, right arm, 27 frames; start posture = its first frame).

Table 2: exubio's angle errors (RMSE over the frames where the angle is measured, deg; mean over the
seeds) on simulated abduction, flexion, scaption and SIER with noise and the per-marker STA
(``--sta-mm``) beside the same with the bone model on the scapula and humerus markers (``--sta
bone``; the other segments keep ``--sta-mm``), both methods.

Usage:
    python studies/sta_bone_model.py                 # 3 seeds, 5 s at 50 Hz (~1-2 min)
    python studies/sta_bone_model.py --seeds 5 --duration 10
    python studies/sta_bone_model.py --loto-only
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "truth" / "sta_opendata"
MOTIONS = ("abduction", "flexion", "scaption", "sier")
ANGLES = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt",
          "GH_Y_plane_of_elevation", "GH_X_elevation", "GH_Y_axial_rotation",
          "GH_phadke_X_elevation", "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation",
          "HT_Y_plane_of_elevation", "HT_X_elevation", "HT_Y_axial_rotation")


def loto_table() -> list[str]:
    from exubio.synth.sta_bone import fit_sta_model
    from exubio.synth.sta_validate import leave_one_task_out, score_other
    from exubio.truth.sta_format import read_sta_trial

    s2m = sorted(DATA.glob("dataSample_S2M_*.mat"))
    if not s2m:
        return [f"(no S2M trials in {DATA})"]
    rows = ["| held out | segment | rotation deg: data / residual, R² | translation mm: data / residual, R² | "
            "marker displacement mm: data / residual, R² | non-rigid rest mm |", "|---|---|---|---|---|---|"]

    def row(h, label):
        cells = [f"{a:.1f} / {b:.1f}, {c:.2f}" for a, b, c in (h.stats[k] for k in
                                                             ("rotation_deg", "translation_mm", "displacement_mm"))]
        return f"| {label} | {h.segment} | " + " | ".join(cells) + f" | {h.nonrigid_mm:.1f} |"

    for h in sorted(leave_one_task_out(s2m, rate_hz=300.0), key=lambda h: (h.segment != "scapula", h.task)):
        rows.append(row(h, f"S2M {h.task}"))
    art = DATA / "dataSample_ARTANIM_armAbd.mat"
    if art.is_file():
        model = fit_sta_model(s2m, rate_hz=300.0)
        for h in score_other(model.segments, read_sta_trial(art), rate_hz=30.0, n_reference=1):
            rows.append(row(h, "ARTANIM armAbd (other subject; all 4 S2M tasks fitted)"))
    return rows


def angle_table(*, seeds: int, duration: float, rate: float, noise_mm: float, sta_mm: float) -> list[str]:
    from exubio.prep.targets import prepare_targets
    from exubio.run.inputs import load_model_and_protocol
    from exubio.run.pipeline import reconstruct
    from exubio.synth.simulate import simulate_trial
    from exubio.protocol.bind import bind
    from exubio.trust.assess import assess_trial
    from exubio.validation.mismatch import measured_angle_errors

    model, protocol = load_model_and_protocol()
    cols = [(m, s) for m in ("pf", "ls") for s in ("per-marker", "bone")]
    res: dict = {}
    for motion in MOTIONS:
        for seed in range(1, seeds + 1):
            for sta in ("per-marker", "bone"):
                sim = simulate_trial(model, motion, duration_s=duration, rate_hz=rate, noise_mm=noise_mm, sta_mm=sta_mm,
                                     seed=seed, sta_model=sta)
                targets = prepare_targets(sim.trajectories, protocol)
                for method in ("pf", "ls"):
                    rec = reconstruct(model, protocol, targets, method=method)
                    a = assess_trial(bind(model, protocol), targets, [rec])
                    errs = measured_angle_errors(model, sim.model, rec.q_rad, sim.q_true, a.angles[method].status)
                    for ang in ANGLES:
                        res.setdefault((motion, ang, method, sta), []).append(errs.get(ang, (np.nan,))[0])
            print(f"  {motion} seed {seed} done", file=sys.stderr)
    rows = ["| motion | angle | " + " | ".join(f"{m.upper()} {s}" for m, s in cols) + " |",
            "|---|---|" + "---|" * len(cols)]
    for motion in MOTIONS:
        for ang in ANGLES:
            vals = [np.nanmean(res[(motion, ang, m, s)]) if np.isfinite(res[(motion, ang, m, s)]).any() else np.nan
                    for m, s in cols]
            rows.append(f"| {motion} | {ang} | " + " | ".join("not measured" if not np.isfinite(v) else f"{v:.1f}"
                                                           for v in vals) + " |")
    return rows


def artefact_table(*, duration: float, rate: float, sta_mm: float) -> list[str]:
    """The simulated artefact's size (seed 1): per segment, the RMS over frames and markers and the
    largest |displacement| (mm), per-marker model beside the bone model."""
    from exubio.model.load import load_model
    from exubio.synth.simulate import simulate_trial

    model = load_model()
    rows = ["| motion | segment | per-marker: RMS / max mm | bone: RMS / max mm |", "|---|---|---|---|"]
    for motion in MOTIONS:
        sims = [simulate_trial(model, motion, duration_s=duration, rate_hz=rate, sta_mm=sta_mm, seed=1, sta_model=s)
                for s in ("per-marker", "bone")]
        segs = sims[0].marker_segments
        for seg in ("clavicle", "scapula", "humerus"):
            idx = [i for i, s in enumerate(segs) if s == seg]
            cells = []
            for sim in sims:
                d = 1e3 * np.linalg.norm(sim.sta_m[:, idx], axis=2)
                cells.append(f"{np.sqrt(np.mean(d * d)):.1f} / {d.max():.1f}")
            rows.append(f"| {motion} | {seg} | " + " | ".join(cells) + " |")
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--duration", type=float, default=5.0)
    p.add_argument("--rate", type=float, default=50.0)
    p.add_argument("--noise-mm", type=float, default=1.0)
    p.add_argument("--sta-mm", type=float, default=10.0)
    p.add_argument("--loto-only", action="store_true")
    args = p.parse_args(argv)
    print("Leave one task out (S2M bone pins), and the S2M model on ARTANIM:\n")
    print("\n".join(loto_table()))
    if not args.loto_only:
        print(f"\nSimulated artefact ({args.duration:g} s at {args.rate:g} Hz, seed 1, per-marker STA {args.sta_mm:g} mm):\n")
        print("\n".join(artefact_table(duration=args.duration, rate=args.rate, sta_mm=args.sta_mm)))
        print(f"\nAngle RMSE (deg, measured frames, mean of seeds 1-{args.seeds}; {args.duration:g} s at {args.rate:g} Hz, "
              f"noise {args.noise_mm:g} mm, per-marker STA {args.sta_mm:g} mm; 'bone': the bone model on the scapula "
              "and humerus markers, the per-marker STA on the others):\n")
        print("\n".join(angle_table(seeds=args.seeds, duration=args.duration, rate=args.rate, noise_mm=args.noise_mm,
                                    sta_mm=args.sta_mm)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
