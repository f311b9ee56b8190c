"""``exubio view``: an interactive 3D view of a reconstruction."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_OK, epilog
from exubio.errors import InputError


def cmd_view(args: argparse.Namespace) -> int:
    from exubio.report.viewer import write_view

    if args.max_frames < 2:
        raise InputError(f"--max-frames {args.max_frames}: expected at least 2 animation frames")
    out = write_view([Path(p) for p in args.results], Path(args.out), overwrite=args.overwrite,
                     model_path=args.model, max_frames=args.max_frames)
    print(f"view: {out} (one HTML file, works offline; open it in a browser)")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    w = sub.add_parser("view", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=epilog("view"),
                       help="write an interactive 3D view of a reconstruction (one self-contained, offline HTML file)")
    w.add_argument("results", nargs="+", help="<trial>.<method>.npz (the trial's other method beside it is shown too)")
    w.add_argument("--out", required=True, help="the HTML file to write")
    w.add_argument("--overwrite", action="store_true", help="replace an existing file")
    w.add_argument("--model", help="the model YAML, when the one the result names cannot be found")
    w.add_argument("--max-frames", type=int, default=300, help="at most this many animation frames (default 300)")
    w.set_defaults(func=cmd_view)
