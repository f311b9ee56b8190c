"""``exubio truth FILE.mat``: a bone-referenced trial reconstructed with PF and LS as a lab would, and
each angle's error against the bone (RMSE, max, coverage of its stated uncertainty)."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from ..errors import InputError

__all__ = ["add_parser", "cmd_truth", "format_table"]

HELP = """\
The file: a trial in the ISB soft-tissue-artefact data-sharing format (Cereatti et al. 2017, J Biomech
62:5-13): skin markers in the bone frame, the bone's pose in the lab, anatomical landmarks of the
scapula and the humerus. What is assumed where the file has no thorax or clavicle marker is printed
with the results (exubio.truth.lab_run). Figures over the frames where each angle is measured;
coverage: the fraction of those frames where the bone lies within +-2u of the angle.

  exubio truth dataSample_S2M_armAbd.mat --rate 300 --json abd.json
"""


def add_parser(sub, common) -> None:
    t = sub.add_parser("truth", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter, epilog=HELP,
                       help="reconstruct a bone-referenced trial (ISB STA data-sharing .mat) and compare with bone")
    t.add_argument("file", help="a .mat trial of the ISB STA data-sharing format")
    t.add_argument("--rate", type=float, default=None,
                   help="the motion capture's sampling rate, Hz (the format does not store it)")
    t.add_argument("--filled", action="store_true",
                   help="use the file's gap-filled markers (default: the raw ones, gaps left as gaps)")
    t.add_argument("--json", dest="json_out", help="write the figures as JSON to this path")
    t.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    t.add_argument("--uncertainty-model", metavar="FILE.json", default=None,
                   help="the STA amplitude model of every angle's uncertainty (a lab's, from 'exubio uncertainty-fit'; "
                        "default: the shipped one, fitted on the S2M pins)")
    t.set_defaults(func=cmd_truth)


def _fmt(x: float | None, spec: str = ".1f") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def format_table(comp) -> str:
    """The comparison as a text table (degrees)."""
    lines = [f"{comp.file}: {comp.task}, {comp.n_frames} frames at {comp.rate_hz:g} Hz",
             f"assumed: {comp.assumption}",
             "verdicts: " + ", ".join(f"{m.upper()} {v}" for m, v in comp.verdicts.items()),
             *(f"  {m.upper()} {line}" for m, lines in comp.reasons.items() for line in lines),
             *(f"note: {n}" for n in comp.notes),
             f"{'angle (deg)':32s} {'method':6s} {'RMSE':>6s} {'max':>6s} {'cover':>6s} {'e/u':>5s} {'u med':>6s} "
             f"{'measured':>8s} | lab: {'RMSE':>6s} {'cover':>6s} {'e/u':>5s} {'u med':>6s} {'measured':>8s}"]
    for a, per in comp.angles.items():
        for m, e in per.items():
            if m not in comp.verdicts or comp.verdicts[m].startswith("failed"):
                continue
            lab = e.lab
            lines.append(f"{a:32s} {m.upper():6s} {_fmt(e.rmse_deg):>6s} {_fmt(e.max_deg):>6s} "
                         f"{_fmt(e.coverage, '.0%'):>6s} {_fmt(e.rms_error_over_u, '.2f'):>5s} {_fmt(e.median_u_deg):>6s} "
                         f"{e.measured_fraction:>8.0%}"
                         + ("" if lab is None else f" |      {_fmt(lab.rmse_deg):>6s} {_fmt(lab.coverage, '.0%'):>6s} "
                                                   f"{_fmt(lab.rms_error_over_u, '.2f'):>5s} {_fmt(lab.median_u_deg):>6s} "
                                                   f"{lab.measured_fraction:>8.0%}"))
    lines.append("e/u: the RMS of error / u over the measured frames (about 1 where u is the error's size; below 1, u "
                 "is wider than the error; an error systematic over a task covers 100 % once u is its RMS)")
    return "\n".join(lines)


def cmd_truth(args: argparse.Namespace) -> int:
    from ..errors import ModelError
    from ..io.yaml import read_yaml
    from ..model.load import DEFAULT_MODEL
    from .compare import compare_bone_trial
    from .lab_run import setup_lab_run
    from .sta_format import read_sta_trial

    if args.rate is None:
        raise InputError(f"{args.file}: the data-sharing format stores no sampling rate; give --rate HZ (the motion "
                         "capture's rate, from the dataset's documentation)")
    out = Path(args.json_out) if args.json_out else None
    if out is not None and out.exists() and not args.overwrite:
        raise InputError(f"{out}: exists; give --overwrite to replace it")
    amplitude = None
    if args.uncertainty_model:
        from ..trust.sta_amplitude import load_sta_amplitude

        amplitude = load_sta_amplitude(args.uncertainty_model)
        if not amplitude.has_trunk:
            raise InputError(f"{args.uncertainty_model}: no trunk motion in the model; exubio truth takes the thorax as "
                             "still and needs it (a model written by 'exubio uncertainty-fit' has the shipped one's)")
    trial = read_sta_trial(args.file)
    run = setup_lab_run(trial, read_yaml(DEFAULT_MODEL, error=ModelError), rate_hz=float(args.rate),
                        raw_markers=not args.filled)
    comp, _ = compare_bone_trial(run, amplitude=amplitude)
    if amplitude is not None:
        print(f"uncertainty: the STA amplitude model {amplitude.path} ({amplitude.source})")
    print(format_table(comp))
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".part")
        tmp.write_text(json.dumps(comp.to_json(), indent=2, allow_nan=False, default=_none) + "\n")
        tmp.replace(out)
    return 0


def _none(x):
    return None
