"""``exubio locator FILE.csv [--json OUT]``: the scapula calibrations judged against a scapula
locator (exubio.truth.locator_eval), printed as a table (mm, deg) per participant and calibration
over the postures every calibration left out; ``--groups`` adds one row per posture group.
``--json`` writes every held-out trial's errors, the summaries and the notes."""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from exubio.errors import InputError

if TYPE_CHECKING:  # imported when the command runs: exubio's --help stays fast
    from exubio.truth.locator_eval import Evaluation, Summary

EXAMPLE = "exubio locator scapula_locator.csv --json locator.json"
EXIT_CODES = "exit codes: 0 done; 2 bad input (the file, a column, a value, --json)"


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register the ``locator`` subcommand on exubio's subparsers."""
    p = sub.add_parser(
        "locator", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
        help="scapula calibrations (skin, cluster; single, double, multiple) against a scapula locator's landmarks",
        description="Judge the scapula calibrations a lab can run against a scapula locator (bone truth): for every "
                    "static posture a calibration was not calibrated on, the distance of AA, TS and AI from the "
                    "locator and the error of the ISB scapula frame. Recommended: the double calibration of the "
                    "skin markers at 45 and 120 deg of flexion (studies/README.md).",
        epilog=f"example:\n  {EXAMPLE}\n\n{EXIT_CODES}")
    p.add_argument("file", help="locator CSV (participant, file, system, AA_x ... TS_mean; mm)")
    p.add_argument("--plane", choices=["flex", "abd"], default="flex",
                   help="the plane whose statics calibrate (default flex; the others are held out)")
    p.add_argument("--side", choices=["left", "right"], default="left", help="the arm measured (default left)")
    p.add_argument("--groups", action="store_true", help="also a row per posture group")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from exubio.truth.locator import read_locator_csv
    from exubio.truth.locator_eval import evaluate, summarize

    if args.json and Path(args.json).is_dir():
        raise InputError(f"--json {args.json}: is a folder; expected a file name")
    evaluation = evaluate(read_locator_csv(args.file), plane=args.plane, side=args.side)
    summaries = summarize(evaluation, by_group=args.groups)
    print(format_table(summaries, evaluation))
    if args.json:
        _write_json(Path(args.json), to_json(evaluation, summaries))
        print(f"locator: wrote {args.json}")
    return 0


def format_table(summaries: Sequence[Summary], evaluation: Evaluation, /) -> str:
    """The summaries as a Markdown table (mm, deg), then the calibration postures and the notes."""
    from exubio.truth.locator_eval import COMMON, RECOMMENDED

    head = ("| participant | calibration | postures | n | AA med | TS med | AI med | AA max | TS max | AI max "
            "| orient. med (deg) | orient. max (deg) |")
    lines = [f"Scapula calibrations against the locator ({evaluation.source}; calibrated in {evaluation.plane}, "
             f"{evaluation.side} arm; distances in mm)", "", head, "|" + "---|" * 12]
    for s in summaries:
        name = s.method + (" (recommended)" if s.method == RECOMMENDED.name else "")
        lines.append(f"| {s.participant} | {name} | {s.group} | {s.n} | "
                     + " | ".join(_mm(v) for v in (*s.median_m, *s.max_m))
                     + f" | {_deg(s.median_orientation_rad)} | {_deg(s.max_orientation_rad)} |")
    lines += ["", f"'{COMMON}': the postures no calibration of the participant used."]
    used: dict[str, list[str]] = {}
    for participant, method, files in evaluation.calibrated_on:
        used.setdefault(participant, []).append(f"{method}: {'+'.join(files)}")
    lines += [f"calibrated on, {p}: " + "; ".join(v) for p, v in used.items()]
    lines += [f"note: {n}" for n in evaluation.notes]
    return "\n".join(lines)


def to_json(evaluation: Evaluation, summaries: Sequence[Summary], /) -> dict[str, Any]:
    """Plain data, mm and deg (NaN: null)."""
    from exubio.truth.locator import LANDMARKS
    from exubio.truth.locator_eval import RECOMMENDED

    return {
        "file": evaluation.source, "plane": evaluation.plane, "side": evaluation.side,
        "recommended": RECOMMENDED.name, "landmarks": list(LANDMARKS),
        "calibrated_on": [{"participant": p, "calibration": m, "files": list(f)} for p, m, f in evaluation.calibrated_on],
        "held_out": [{"participant": r.participant, "calibration": r.method, "file": r.file, "group": r.group,
                      "common": r.common, "distance_mm": [_num(v * 1000) for v in r.distance_m],
                      "orientation_deg": _num(math.degrees(r.orientation_rad))} for r in evaluation.results],
        "summary": [{"participant": s.participant, "calibration": s.method, "postures": s.group, "n": s.n,
                     "median_mm": [_num(v * 1000) for v in s.median_m], "max_mm": [_num(v * 1000) for v in s.max_m],
                     "orientation_median_deg": _num(math.degrees(s.median_orientation_rad)),
                     "orientation_max_deg": _num(math.degrees(s.max_orientation_rad))} for s in summaries],
        "notes": list(evaluation.notes),
    }


def _write_json(path: Path, payload: dict[str, Any]) -> None:
    import json
    import os
    import tempfile

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(payload, f, indent=1)
        os.replace(tmp, path)
    except OSError as exc:
        raise InputError(f"--json {path}: cannot write ({exc})") from None


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else round(v, 2)


def _mm(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v * 1000:.1f}"


def _deg(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{math.degrees(v):.1f}"
