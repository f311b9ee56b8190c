"""``exubio export-model``: a model as an OpenSim .osim or a biorbd .bioMod."""
from __future__ import annotations

import argparse
from typing import Any

from exubio.cli.common import EXIT_OK, epilog
from exubio.model.signs import add_signs_arguments  # small: the --signs option


def cmd_export_model(args: argparse.Namespace) -> int:
    from exubio.export import write_biomod, write_osim
    from exubio.model.load import load_model

    from exubio.run.moments_outputs import export_model

    model = export_model(load_model(args.model, body_mass_kg=args.body_mass), args)  # --body-mass: the moments' inertia
    if args.format == "osim":
        path = write_osim(model, args.out, overwrite=args.overwrite, coordinates=args.coordinates, thorax=args.thorax or "free",
                          signs=args.signs or "isb")
        plays = ("its coordinates are the anatomical angles, so exubio's .mot plays on it" if args.coordinates == "anatomical"
                 else "its coordinates are exubio's model coordinates (the q of the .npz)")
    else:
        path = write_biomod(model, args.out, overwrite=args.overwrite, thorax=args.thorax or "weld")
        plays = "its generalized coordinates are exubio's model coordinates (the q of the .npz)"
    print(f"wrote {path}: an open chain (the scapulothoracic ellipsoid cannot be expressed in this format; the file's "
          f"header gives it); {plays}")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    e = sub.add_parser("export-model", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=epilog("export-model"),
                       help="write a model YAML (generic or calibrated) as an OpenSim .osim or a biorbd .bioMod")
    e.add_argument("model", help="model YAML (e.g. models/upper_extremity.yaml or one written by exubio calibrate)")
    e.add_argument("--format", required=True, choices=["osim", "biomod"], help="osim: OpenSim 4; biomod: biorbd")
    e.add_argument("--out", required=True, help="FILE.osim or FILE.bioMod to write")
    e.add_argument("--overwrite", action="store_true", help="replace an existing FILE")
    e.add_argument("--coordinates", choices=["anatomical", "model"], default="anatomical",
                   help="osim only: anatomical (default; SC, AC, GH between the ISB frames with the anatomical angles "
                        "as coordinates, so exubio's .mot plays on it) or model (exubio's own joint coordinates)")
    from exubio.run.moments_outputs import add_export_arguments

    add_export_arguments(e)
    add_signs_arguments(e, default="isb; osim with anatomical coordinates: the convention of the .mot it is to play")
    e.set_defaults(func=cmd_export_model)
