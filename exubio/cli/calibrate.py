"""``exubio calibrate``: the model fitted to a subject from a static trial."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_OK, check_output_folder, epilog, static_spec
from exubio.errors import InputError


def cmd_calibrate(args: argparse.Namespace) -> int:
    from exubio.calibration import format_report, parse_frames
    from exubio.run.inputs import load_session
    from exubio.run.session import calibrate_file

    if Path(args.out).suffix.lower() not in (".yaml", ".yml"):
        raise InputError(f"--out {args.out}: expected a model file ending in .yaml")
    check_output_folder(Path(args.out).parent, args.out)
    parse_frames(args.static_frames)  # a malformed --static-frames is refused before anything is read
    session = load_session(model_path=args.model, protocol_path=args.protocol, body_mass_kg=args.body_mass)
    _, _, report = calibrate_file(args.static, session=session, spec=static_spec(args), out_path=args.out,
                                  overwrite=args.overwrite)
    print(format_report(report))
    print(f"wrote {args.out}")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    c = sub.add_parser("calibrate", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=epilog("calibrate"), help="fit the model to a subject from a static trial")
    c.add_argument("static", help="static trial (.c3d or .trc)")
    c.add_argument("--protocol", help="protocol YAML (default: protocols/upper_limb_21.yaml)")
    c.add_argument("--model", help="generic model YAML (default: models/upper_extremity.yaml)")
    c.add_argument("--body-mass", type=float, help="body mass, kg")
    c.add_argument("--scapula-trial", metavar="TRIAL", action="append", help="movement trial of the same session (arm raised in one or more "
                        "planes): the thorax ellipsoid is fitted through the scapula contact points of all its postures "
                        "and the static pose (repeatable: postures pooled); not used, with the reason, if the movement cannot determine it")
    c.add_argument("--static-frames", help="A:B frames to use (default: the longest still stretch)")
    c.add_argument("--also-static", metavar="TRIAL", action="append", help="a further static pose of the session (e.g. arm raised; repeatable): the thorax ellipsoid is "
                        "fitted through the scapula contact points of every static pose")
    c.add_argument("--functional", metavar="TRIAL", help="movement trial of the same session (arm moved in several planes): glenohumeral centre by SCoRE "
                        "(Ehrig et al. 2006) instead of from the generic model; not used, with the reason, if its "
                        "motion does not determine it")
    c.add_argument("--out", required=True, help="MODEL.yaml to write")
    c.add_argument("--overwrite", action="store_true", help="replace an existing MODEL.yaml")
    c.set_defaults(func=cmd_calibrate)
