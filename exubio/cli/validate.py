"""``exubio validate``: the paper's evaluation as a report."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_OK, epilog


def cmd_validate(args: argparse.Namespace) -> int:
    from exubio.validation import run_validation

    results = run_validation(args.out, quick=args.quick,
                             progress=None if args.quiet else (lambda msg: print(msg, file=sys.stderr)))
    for c in results.checks:
        state = {True: "PASS", False: "FAIL", None: "n/a "}[c.passed]
        print(f"{state}  {c.what}: {c.value:.3g} {c.unit} (limit {c.limit:.3g} {c.unit})")
    print(f"wrote {Path(args.out) / 'validation.pdf'}, the figures and table1.json; "
          f"{sum(c.passed is True for c in results.checks)}/{len(results.checks)} checks passed")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    v = sub.add_parser("validate", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=epilog("validate"), help="the paper's evaluation (Fig. 2-5, Table 1) as a PDF/PNG report")
    v.add_argument("--out", default="reports/validation", help="output folder (default reports/validation)")
    v.add_argument("--quick", action="store_true", help="short trials (a smoke run, not the report)")
    v.set_defaults(func=cmd_validate)
