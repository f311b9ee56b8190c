"""``exubio sta-fit``: fit a bone soft-tissue-artefact model (exubio.synth.sta_bone) on a lab's own
bone-referenced trials (.mat files of the ISB data-sharing format) and write it as JSON, for
``exubio simulate --sta MODEL.json``; prints the model's leave-one-trial-out fit where there are
several trials."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from exubio.errors import InputError

__all__ = ["add_parser", "cmd_sta_fit"]


def add_parser(sub, common: argparse.ArgumentParser) -> None:
    p = sub.add_parser(
        "sta-fit", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
        help="fit a soft-tissue-artefact model on bone-referenced trials (.mat), for 'exubio simulate --sta'",
        description="Fit the skin markers' motion over the bone (per segment: the cluster's rigid rotation and "
                    "translation as a regression on the joint angles, and the non-rigid rest) on trials of the ISB "
                    "soft-tissue-artefact data-sharing format (Cereatti et al. 2017, J Biomech 62:5-13), with the "
                    "scapula and the humerus tracked by bone pins or fluoroscopy. The files hold no thorax: it is "
                    "assumed upright and fixed in the lab.",
        epilog="example:\n  exubio sta-fit dataSample_S2M_armAbd.mat dataSample_S2M_eating.mat --rate 300 --out model.json\n"
               "  exubio simulate --motion abduction --sta model.json --out abd.c3d\n\n"
               "exit codes: 0 written; 2 bad input (the file or key is named), nothing written.")
    p.add_argument("trials", nargs="+", metavar="FILE.mat", help="bone-referenced trials (all at --rate)")
    p.add_argument("--rate", type=float, required=True, help="the trials' sampling rate, Hz (the files do not hold it)")
    p.add_argument("--name", default="", help="the model's name (default: the labs and tasks)")
    p.add_argument("--citation", default="", help="the data's citation, written into the model")
    p.add_argument("--out", required=True, help="MODEL.json")
    p.set_defaults(func=cmd_sta_fit)


def cmd_sta_fit(args: argparse.Namespace) -> int:
    from exubio.synth.sta_bone import fit_sta_model
    from exubio.synth.sta_validate import leave_one_task_out

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise InputError(f"--out {out}: expected a path ending in .json")
    model = fit_sta_model(args.trials, rate_hz=args.rate, name=args.name, citation=args.citation)
    out.parent.mkdir(parents=True, exist_ok=True)
    model.write(out)
    for s, m in model.segments.items():
        print(f"{s}: {m.fit['frames']} frames; rigid rotation {m.fit['rms_rotation_deg']:.1f} deg RMS, translation "
              f"{m.fit['rms_translation_mm']:.1f} mm RMS; non-rigid rest {1e3 * m.nonrigid_sd_m:.1f} mm RMS")
        if m.residual is not None:
            sd = m.residual.sd_per_rad
            print(f"  held-out residual per rad of humerus rotation: rotation {np.degrees(np.linalg.norm(sd[:3])):.1f} deg, "
                  f"translation {1e3 * np.linalg.norm(sd[3:]):.1f} mm; correlation time "
                  f"{m.residual.correlation_time_s:.2f} s")
    if len(args.trials) > 1:
        print("leave one trial out (RMS data / RMS residual, R^2):")
        for h in leave_one_task_out(args.trials, rate_hz=args.rate):
            print(f"  {h.segment:8s} {h.task:12s} " + "  ".join(
                f"{k} {a:.1f}/{b:.1f} R2 {c:.2f}" for k, (a, b, c) in h.stats.items()))
    print(f"wrote {out}")
    return 0
