"""``exubio uncertainty-fit``: a lab's own uncertainty model (exubio.truth.uncertainty_fit) from its
bone-referenced trials, written as JSON for a protocol's ``uncertainty_model:`` key."""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["add_parser", "cmd_uncertainty_fit"]

HELP = """\
The trials: ISB soft-tissue-artefact data-sharing .mat files (Cereatti et al. 2017, J Biomech 62:5-13)
with the scapula and the humerus tracked by bone pins or fluoroscopy, all at --rate. Each is also
reconstructed by LS twice (its skin markers, and the same markers carried by the bones), about a
second per thousand frames. Then name the file in your protocol:

  exubio uncertainty-fit abd.mat flex.mat eating.mat --rate 300 --out lab_u.json
  # in my_protocol.yaml:   uncertainty_model: lab_u.json   (relative to the protocol file)
  exubio reconstruct trial.c3d --protocol my_protocol.yaml --out results

Every angle's <angle>_u_deg then comes from this model, and the outputs name it.

exit codes: 0 written; 2 bad input (the file or key is named), nothing written.
"""


def add_parser(sub, common) -> None:
    p = sub.add_parser("uncertainty-fit", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=HELP, help="fit the uncertainty's soft-tissue-artefact model on a lab's bone-referenced "
                                         "trials (.mat), for a protocol's uncertainty_model")
    p.add_argument("trials", nargs="+", metavar="FILE.mat", help="bone-referenced trials (all at --rate)")
    p.add_argument("--rate", type=float, required=True, help="the trials' sampling rate, Hz (the files do not hold it)")
    p.add_argument("--citation", default="", help="the data's citation, written into the model")
    p.add_argument("--out", required=True, help="MODEL.json")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.add_argument("--no-judge", action="store_true",
                   help="skip judging each trial with the model of the others (one trial out; about as long again)")
    p.set_defaults(func=cmd_uncertainty_fit)


def cmd_uncertainty_fit(args: argparse.Namespace) -> int:
    from ..io.result_set import atomic_write
    from .uncertainty_fit import fit_uncertainty_model

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise InputError(f"--out {out}: expected a path ending in .json")
    if out.exists() and not args.overwrite:
        raise InputError(f"{out}: exists; give --overwrite to replace it")
    if not getattr(args, "verbose", False):  # the LS runs of bone trials say which frames took long: details
        logging.getLogger("exubio.methods").setLevel(logging.ERROR)
    fit = fit_uncertainty_model(args.trials, rate_hz=args.rate, judge=not args.no_judge)
    amp = fit.amplitude
    for bone, rot in amp.rotation.items():
        print(f"{bone}: skin cluster rotation {', '.join(f'{a} {x:.1f}' for a, x in zip('XYZ', np.degrees(rot)))} deg, "
              f"translation {', '.join(f'{a} {x:.1f}' for a, x in zip('XYZ', 1e3 * amp.translation[bone]))} mm, "
              "per rad of the humerus's rotation from rest (SD)")
    d = np.diag(amp.girdle)
    print(f"girdle (sign x sqrt of C's diagonal, deg per rad of theta + {np.degrees(amp.girdle_offset_rad):.0f} deg): " + ", ".join(
        f"{n} {x:+.1f}" for n, x in zip(("scapula X", "Y", "Z", "humerus X", "Y", "Z"),
                                        np.sign(d) * np.degrees(np.sqrt(np.abs(d))))))
    for g in fit.girdle:
        used = "left out of the girdle's part" if g.verdict == "fail" else "used"
        print(f"  {Path(g.file).name}: LS verdict {g.verdict} with the markers carried by the bones: {used}")
    judged = fit.judgement()
    if judged:
        print(format_held_out(fit.held_out, judged))
    data = dataclasses.replace(amp, judgement=judged).to_json()
    data["citation"] = args.citation or f"the lab's own trials ({', '.join(Path(t).name for t in args.trials)})"
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, lambda tmp: tmp.write_text(json.dumps(data, indent=2) + "\n"))
    print(f"wrote {out}: name it in a protocol as 'uncertainty_model: {out.name}' (relative to the protocol file)")
    return 0


def format_held_out(held, judged: dict) -> str:
    """The one-trial-out judgement as a table: per angle and trial, the % of measured frames where the
    bone lies within +-2u (the % of frames measured), then the cells below 90 % and above 99 % and the
    median RMS of error / u (their counts: ``judged``, ``UncertaintyFit.judgement``)."""
    from .compare import TRUTH_ANGLES

    names = [Path(h.trial).stem.removeprefix("dataSample_") for h in held]
    width = max(12, *(len(n) for n in names))
    lines = ["each trial judged with the model of the others (LS, the u of a lab's run with thorax markers): % of its "
             "measured frames where the bone lies within +-2u (% of frames measured)",
             f"{'angle':32s}" + "".join(f"{n:>{width + 2}s}" for n in names)]
    below = []
    for a in TRUTH_ANGLES:
        row = []
        for n, h in zip(names, held):
            c = h.angles.get(a)
            if c is None:
                row.append("-")
                continue
            if c[0] < 0.90:
                below.append(f"{n} {a}: {c[0]:.0%}" + (" (LS verdict fail)" if h.verdict == "fail" else ""))
            row.append(f"{100 * c[0]:.0f} ({100 * c[1]:.0f})")
        if any(x != "-" for x in row):
            lines.append(f"{a:32s}" + "".join(f"{x:>{width + 2}s}" for x in row))
    lines.append("LS verdicts: " + ", ".join(f"{n} {h.verdict or '-'}" + (f" (not judged: {h.skipped})" if h.skipped else "")
                                             for n, h in zip(names, held)))
    z = judged.get("median_rms_error_over_u")
    lines.append(f"{judged['cells']} cells; below 90 %: {judged['below_90']}" + (": " + "; ".join(below) if below else "")
                 + f"; above 99 % (u wider than needed): {judged['above_99']}"
                 + (f"; the RMS of error / u, median over the cells: {z:.2f} (about 1 where u is the error's size)"
                    if z is not None else ""))
    pooled = judged.get("pooled", {})
    if pooled:
        lines.append("pooled over the trials whose LS verdict is not fail (per angle, all their measured frames "
                     "together: what a 95 % band promises over a lab's trials): "
                     + ", ".join(f"{a} {100 * p['coverage']:.0f} %" for a, p in pooled.items())
                     + f"; below 90 %: {judged['pooled_below_90']}, above 99 %: {judged['pooled_above_99']} of {len(pooled)}")
    lines.append("(the files hold no thorax: it is taken as still in the lab, so the HT angles here also carry the "
                 "trunk's motion, which the u of a run with thorax markers does not; exubio truth adds it)")
    return "\n".join(lines)
