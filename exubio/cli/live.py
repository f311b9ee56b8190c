"""``exubio live`` and ``exubio stream``: angles from a Lab Streaming Layer marker stream, and a trial replayed as one."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_FAILED, EXIT_OK
from exubio.errors import InputError


def _slice(text: str | None) -> slice | None:
    if not text:
        return None
    from exubio.calibration import parse_frames

    frames = parse_frames(text)
    start = frames.start or 0
    if frames.stop is None or start < 0 or frames.stop <= start:
        raise InputError(f"--static-frames {text}: expected A:B with 0 <= A < B (frames of the stream's start)")
    return frames


def cmd_live(args: argparse.Namespace) -> int:
    from datetime import datetime, timezone

    from exubio.run.inputs import load_model_and_protocol
    from exubio.run.live.app import LiveControl, LiveOutput, run_live
    from exubio.run.live.causal import CausalOptions
    from exubio.run.live.display import Display
    from exubio.run.live.options import LiveOptions
    from exubio.run.live.transport import LSLSource, load_pylsl

    load_pylsl(args.lsl_config)  # the LSL configuration is set before pylsl is loaded
    model, protocol = load_model_and_protocol(model_path=args.model, protocol_path=args.protocol)
    options = LiveOptions(causal=CausalOptions(cutoff_hz=args.cutoff), max_behind_s=args.max_behind,
                          end_after_s=None if args.end_after <= 0 else args.end_after, open_timeout_s=args.timeout)
    source = LSLSource(name=args.stream, source_id=args.source_id)
    display = Display(sys.stderr, quiet=args.quiet)
    name = args.name or f"live_{datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%SZ')}"
    try:
        output = LiveOutput(args.out, name, publish_name=args.publish or None, overwrite=args.overwrite,
                            report=not args.no_report)
        run = run_live(model, protocol, source, output, options=options, static_frames=_slice(args.static_frames),
                       control=LiveControl(on_event=display.event, on_status=display.status, duration_s=args.duration))
    finally:
        display.close()
    rec = run.recording
    q = rec.live_quality
    st = rec.stats
    print(f"live: {rec.n_frames} frames of '{rec.info.name}' ({rec.info.rate_hz:g} Hz, {len(rec.info.labels)} markers); "
          f"ended by {rec.ended_by}; dropped {st['dropped']}, late {st['late']}, skipped {st['skipped']}, "
          f"PF runs {st['runs']}")
    lat = st["loop_latency_ms"]
    if lat["p50"] is not None:
        print(f"live: loop latency p50 {lat['p50']:.2f} ms, p99 {lat['p99']:.2f} ms, max {lat['max']:.2f} ms")
    print(f"live verdict: {q.verdict}" + "".join(f"\n  - [{r.level}] {r.message}" for r in q.reasons))
    print(f"recording: {run.folder}")
    from exubio.io.result_names import method_stem, set_paths

    summ = _json_file(set_paths(run.folder, method_stem(name, "pf"))["summary"])
    off = summ.get("quality", {})
    print(f"offline assessment of the recording: {off.get('verdict')}"
          + "".join(f"\n  - [{r['level']}] {r['message']}" for r in off.get("reasons", [])))
    return EXIT_FAILED if off.get("verdict") == "fail" or q.verdict == "fail" else EXIT_OK


def _json_file(path) -> dict:
    import json

    return json.loads(Path(path).read_text())


def cmd_stream(args: argparse.Namespace) -> int:
    from exubio.io.trial import read_trial
    from exubio.run.live.app import stream_file
    from exubio.run.live.transport import load_pylsl

    load_pylsl(args.lsl_config)
    trial = read_trial(args.trial)
    name = args.name or Path(args.trial).stem
    if not args.quiet:
        print(f"stream: '{name}' ({len(trial.labels)} markers, {trial.n_frames} frames, {trial.rate_hz:g} Hz x "
              f"{args.speed:g}, {args.units}) on LSL ({args.lsl_config})", file=sys.stderr)
    sent = stream_file(trial, name=name, speed=args.speed, units=args.units, source_id=args.source_id or "",
                       wait_s=args.wait)
    print(f"stream: sent {sent} frames of {args.trial}")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    lv = sub.add_parser(
        "live", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
        help="joint angles live from an LSL marker stream (PF, causal); writes the recording at the end",
        description="Reconstruct a marker stream (Lab Streaming Layer) frame by frame with PF and publish the ISB "
                    "angles, their rates, the per-marker residuals and a running verdict as the LSL stream "
                    "--publish (and --publish_events). Ctrl-C or the end of the stream writes the recording "
                    "(input markers and the result files of 'exubio reconstruct') into --out/NAME.",
        epilog="example (two terminals, on this machine only):\n"
               "  exubio stream exubio/data/example_abduction.c3d\n"
               "  exubio live --out recordings/ --name demo\n\n"
               "exit codes: 0 recording written (verdict ok or check); 1 verdict fail or reconstruction failed; "
               "2 bad input (no stream, labels, units, model/protocol files); 130 interrupted while writing")
    lv.add_argument("--stream", help="LSL name of the marker stream (default: the first stream of type Mocap)")
    lv.add_argument("--source-id", help="LSL source id of the marker stream")
    lv.add_argument("--model", help="calibrated model YAML (exubio calibrate; default: the generic model)")
    lv.add_argument("--protocol", help="protocol YAML (default: protocols/upper_limb_21.yaml)")
    lv.add_argument("--static-frames", help="A:B: calibrate the model from these first frames of the stream first")
    lv.add_argument("--cutoff", type=float, default=None,
                    help="causal Butterworth low-pass cut-off, Hz (default: none, the PF dampers filter)")
    lv.add_argument("--out", required=True, help="folder the recording goes into (as --out/NAME/)")
    lv.add_argument("--name", help="recording name (default live_<UTC time>)")
    lv.add_argument("--overwrite", action="store_true", help="replace a recording of the same name")
    lv.add_argument("--no-report", action="store_true", help="skip the PDF/PNG report of the recording")
    lv.add_argument("--publish", default="exubio_angles", help="LSL name of the output stream ('' for none)")
    lv.add_argument("--duration", type=float, help="stop after this many seconds")
    lv.add_argument("--end-after", type=float, default=5.0,
                    help="the stream has ended after this many seconds without a sample (0: wait for Ctrl-C)")
    lv.add_argument("--max-behind", type=float, default=0.5,
                    help="a backlog longer than this (s) is skipped and PF restarts at the newest frame")
    lv.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for the stream to appear")
    lv.add_argument("--lsl-config", default="loopback",
                    help="loopback (default: 127.0.0.1 only), system (liblsl's own lsl_api.cfg: a lab network), "
                         "or the path of an lsl_api.cfg")
    lv.set_defaults(func=cmd_live)

    sm = sub.add_parser(
        "stream", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
        help="replay a C3D/TRC trial as a live LSL marker stream",
        description="Send a trial as an LSL marker stream (type Mocap, channels LABEL_X/_Y/_Z, double precision) at "
                    "its own rate or --speed times it, as a camera system's LSL app would: to try 'exubio live' "
                    "without cameras.",
        epilog="example:\n  exubio stream exubio/data/example_abduction.c3d --speed 1\n\n"
               "exit codes: 0 sent; 2 bad input (the trial file, --speed, LSL not available)")
    sm.add_argument("trial", help="trial file (.c3d or .trc)")
    sm.add_argument("--speed", type=float, default=1.0, help="times the trial's rate (default 1)")
    sm.add_argument("--name", help="LSL stream name (default: the trial's file name)")
    sm.add_argument("--source-id", help="LSL source id (default exubio-replay-NAME)")
    sm.add_argument("--units", choices=["mm", "m"], default="mm", help="units of the positions sent (default mm)")
    sm.add_argument("--wait", type=float, default=10.0, help="seconds to wait for a consumer before sending (0: none)")
    sm.add_argument("--lsl-config", default="loopback", help="loopback (default), system, or an lsl_api.cfg path")
    sm.set_defaults(func=cmd_stream)
