"""``exubio protocols`` and ``exubio model-points``: what a protocol measures, and the model's points to write one."""
from __future__ import annotations

import argparse
import sys
from typing import Any

from exubio.cli.common import EXIT_BAD_INPUT, EXIT_OK, PRINT_EXIT_CODES, epilog
from exubio.errors import InputError


def cmd_protocols(args: argparse.Namespace) -> int:
    from exubio.model.load import load_model
    from exubio.protocol.load import read_protocol_mapping, resolve_protocol, shipped_protocols
    from exubio.run.inputs import protocol_for_model

    if (args.trial or args.static) and not args.name:
        raise InputError("exubio protocols --trial/--static: give the protocol to check too (exubio protocols FILE "
                         "--trial TRIAL)")
    if not args.name:
        print("shipped protocols (use by name: --protocol NAME, from any folder):")
        for name in shipped_protocols():
            prot = protocol_for_model(load_model(), name)
            first = " ".join(str(read_protocol_mapping(name).get("description") or "").split())[:110]
            print(f"  {name:22s} {len(prot.markers)} markers; {first}")
        print("list one's markers: exubio protocols NAME")
        return EXIT_OK
    model = load_model()
    prot = protocol_for_model(model, args.name)
    print(f"{prot.name} ({resolve_protocol(args.name)}): thorax frame from "
          + (", ".join(f"{k}={getattr(prot.thorax_frame, k)}" for k in prot.thorax_frame.keys) or "identity"))
    if prot.held_coordinates:
        print(f"  holds: {', '.join(prot.held_coordinates)}")
    for m in prot.markers:
        extra = ", ".join(x for x in (f"landmark {m.landmark}" if m.landmark else "", f"cluster {m.cluster}" if m.cluster
                                       else "", "optional" if m.optional else "", f"aliases {list(m.aliases)}" if m.aliases
                                       else "") if x)
        print(f"  {m.name:12s} {m.segment:9s} {extra}")
    return _print_protocol_check(model, prot, args)


def _print_protocol_check(model, prot, args: argparse.Namespace) -> int:
    """What the protocol can measure, per angle, and its mistakes (exubio.trust.protocol_check):
    exit 2 on an error, 0 with warnings."""
    from exubio.io.trial import read_trial
    from exubio.trust.protocol_check import check_protocol

    trial = read_trial(args.trial) if args.trial else None
    static = read_trial(args.static) if args.static else None
    check = check_protocol(model, prot, trial=trial, static=static)
    print("what it can measure, before any trial (over elevations of 10-120 deg in three planes):")
    if prot.uncertainty_model:  # the protocol's uncertainty_model key: the bone-pin artefact below is the lab's
        print(f"  (the soft-tissue artefact and girdle error of the uncertainty: the lab's model {prot.uncertainty_model})")
        from exubio.trust.sta_amplitude import load_sta_amplitude

        line = load_sta_amplitude(prot.uncertainty_model).judgement_line()
        print(f"  ({line or 'the model records no judgement: exubio uncertainty-fit without --no-judge makes one'})")
    for name, st in check.status.items():
        why = check.why.get(name)
        print(f"  {name:30s} {st}" + (f": {why}" if why else ""))
    for f in check.findings:
        print(f"{f.level}: {f.message}", file=sys.stderr if f.level == "error" else sys.stdout)
    if check.errors:
        print(f"exubio: {len(check.errors)} error(s) in {prot.source or prot.name}: fix the key(s) named above",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"checked: {len(check.findings)} warning(s)" if check.findings else "checked: no mistake found"
          + ("" if (args.trial or args.static) else " (give --trial or --static to check it against your data too)"))
    return EXIT_OK


def cmd_model_points(args: argparse.Namespace) -> int:
    from exubio.model.load import load_model

    model = load_model(args.model)
    segments = [s for s in model.segments if args.segment in (None, s.name)]
    if not segments:
        raise InputError(f"--segment {args.segment}: not a segment of {model.source}; its segments are "
                         f"{list(model.segment_names)}")
    print(f"{model.name}: points per segment, mm, in the segment frame that local_position_mm uses (origin: the "
          f"segment's joint centre; axes parallel to the ISB thorax frame, X anterior, Y superior, Z right, in the "
          f"reference posture: arm hanging, palm forward). A marker over one of these gives point: NAME instead.")
    for seg in segments:
        origin = "" if seg.joint is None else f" (origin: its {seg.joint.name} joint centre)"
        print(f"{seg.name}{origin}:")
        for name, local in seg.points.items():
            print(f"  {name:12s} [{local[0] * 1000:7.1f}, {local[1] * 1000:7.1f}, {local[2] * 1000:7.1f}]")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    pr = sub.add_parser("protocols", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                        help="list the shipped protocols (by name, usable from any folder) and, with a name, the "
                        "markers of one", epilog=epilog("protocols", PRINT_EXIT_CODES))
    pr.add_argument("name", nargs="?", help="a shipped protocol's name or a protocol file: list its markers, say what "
                    "it can measure (per angle, and why not) and check it")
    pr.add_argument("--trial", help="check the protocol against this trial too: its labels (relabel keys, missing "
                    "markers with their near labels) and the arm's side")
    pr.add_argument("--static", help="check it against this static trial too: as --trial, and the markers declared on "
                    "a landmark that the calibrated static puts elsewhere (with the distances)")
    pr.set_defaults(func=cmd_protocols)

    mp = sub.add_parser("model-points", parents=[common], help="the model's points per segment in the segment frames "
                        "a protocol's local_position_mm uses (mm), to write a protocol for your marker set",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog=epilog("model-points", PRINT_EXIT_CODES))
    mp.add_argument("model", nargs="?", default="upper_extremity", help="model YAML or a shipped model's name "
                    "(default: upper_extremity)")
    mp.add_argument("--segment", help="only this segment")
    mp.set_defaults(func=cmd_model_points)
