"""``exubio study``: a study file run (subjects x sessions x trials), resumable."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_CODES_HELP, EXIT_FAILED, EXIT_OK, check_output_folder, epilog
from exubio.errors import InputError
from exubio.model.signs import add_signs_arguments  # small: the --signs option
from exubio.run import bids  # small: --bids's options and work


def cmd_study(args: argparse.Namespace) -> int:
    from exubio.run.study import load_study, run_study
    from exubio.run.study_template import STUDY_TEMPLATE

    if args.template:
        print(STUDY_TEMPLATE, end="")
        return 0
    if not args.study or not args.out:
        raise InputError("exubio study: expected STUDY.yaml and --out FOLDER (or --template to print a study file)")
    spec = load_study(args.study, body_mass_kg=args.body_mass, signs=args.signs)  # every key, path and glob checked before any work
    if args.jobs < 1:
        raise InputError(f"--jobs {args.jobs}: expected a whole number of processes >= 1")
    check_output_folder(Path(args.out), args.out)
    bids.check_bids(args)
    outcomes = run_study(spec, args.out, jobs=args.jobs, scheduler=args.scheduler,
                         progress=None if args.quiet else (lambda m: print(m, file=sys.stderr)))
    failed = [o for o in outcomes if o.status == "failed"]
    fails = [o for o in outcomes if {"fail", "failed"} & set(o.verdicts.values())]
    print(f"study {spec.name}: {len(outcomes)} trial(s): {sum(o.status == 'done' for o in outcomes)} done, "
          f"{sum(o.status.startswith('skipped') for o in outcomes)} already complete, {len(failed)} failed; "
          f"table: {Path(args.out) / 'study.csv'}")
    for o in failed:
        print(f"failed: {o.subject}/{o.session}/{Path(o.trial).name}: {o.error}")
    if args.bids:
        bids.bids_after_study(args, spec.name)
    return EXIT_FAILED if failed or fails else EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    st = sub.add_parser("study", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                        help="run a study file (subjects x sessions x trials); re-running resumes it",
                        epilog=epilog("study", EXIT_CODES_HELP))
    st.add_argument("study", nargs="?", help="STUDY.yaml (its format: exubio study --template)")
    st.add_argument("--out", help="output folder: <subject>/<session>/<trial>/, study.csv, study.json")
    st.add_argument("--template", action="store_true", help="print a study file with every key explained, and exit")
    st.add_argument("--jobs", type=int, default=1, help="trials in parallel local processes (default 1)")
    st.add_argument("--body-mass", type=float, help="body mass, kg, of every session without its own body_mass_kg: "
                    "the joint moments too (moments.parquet; docs: moments)")
    bids.add_bids_arguments(st)
    st.add_argument("--scheduler", help="run the trials on Dask: local:N (a local cluster of N workers) or "
                                        "tcp://HOST:PORT (a running scheduler)")
    add_signs_arguments(st)
    st.set_defaults(func=cmd_study)
