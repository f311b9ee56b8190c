"""``exubio reconstruct``: joint angles of one or more trials (one arm or both; a process pool or Dask)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from exubio.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_CODES_HELP,
    EXIT_FAILED,
    check_output_folder,
    epilog,
    print_trial,
    progress_factory,
    static_spec,
    trial_code,
)
from exubio.method_registry import REGISTRY, method_names
from exubio.errors import ExubioError, InputError, ModelError, ProtocolError
from exubio.prep.moment_options import add_moment_arguments  # small: argparse options only
from exubio.model.signs import add_signs_arguments  # small: the --signs option
from exubio.run import fill_run  # small: --fill's options and work (its solvers are imported when it runs)

if TYPE_CHECKING:  # the CLI imports the pipeline only when a command runs (fast --help)
    from exubio.run.job import TrialJob, TrialResult


def _methods(value: str) -> list[str]:
    return ["pf", "ls"] if value == "both" else [value]


def _moment_request(args: argparse.Namespace):
    from exubio.prep.moment_options import moment_request

    if getattr(args, "loads", None) and args.body_mass is None:
        raise InputError("--loads: the joint moments need the subject's --body-mass (kg) too")
    return moment_request(args)


def _hand_load(args: argparse.Namespace) -> float | None:
    """The hand load of the joint moments (None: no moments): they are written with --body-mass."""
    load = getattr(args, "hand_load_kg", None)
    if load is not None and args.body_mass is None:
        raise InputError("--hand-load-kg: the joint moments need the subject's --body-mass (kg) too")
    if load is not None and not (load >= 0 and load != float("inf")):
        raise InputError(f"--hand-load-kg must be a number >= 0 (kg), got {load}")
    return None if args.body_mass is None else float(load or 0.0)


def _run_trial(job: TrialJob) -> tuple[str, TrialResult | None, int, str]:
    """One trial in a worker process: (trial, result, exit code, error message)."""
    from exubio.run.job import run_job

    trial = str(job.trial)
    try:
        result = run_job(job)
        return trial, result, trial_code(result), ""
    except (InputError, ProtocolError, ModelError) as exc:
        return trial, None, EXIT_BAD_INPUT, str(exc)
    except ExubioError as exc:
        return trial, None, EXIT_FAILED, str(exc)


def cmd_reconstruct(args: argparse.Namespace) -> int:
    protocols = args.protocol or [None]
    if args.both_arms:
        protocols = _both_arms(protocols)
    if len(protocols) > 1:
        return _reconstruct_arms(args, protocols)
    args = argparse.Namespace(**{**vars(args), "protocol": protocols[0]})
    return _reconstruct_one_protocol(args)


def _both_arms(protocols: list[str | None]) -> list[str]:
    """--both-arms: the protocol given and the one its ``other_arm`` names (next to it, else shipped)."""
    from exubio.protocol.load import find_other_arm

    if len(protocols) != 1 or protocols[0] is None:
        raise InputError("--both-arms: give one --protocol (its other_arm key names the other arm's protocol), e.g. "
                         "--protocol plug_in_gait_upper --both-arms")
    return [protocols[0], str(find_other_arm(protocols[0]))]


def _reconstruct_arms(args: argparse.Namespace, protocols: list[str]) -> int:
    """Both arms of one trial: one protocol per arm (``side: right`` and ``side: left``), each
    reconstructed as its own chain into ``--out/<side>/`` (its calibration too, with --static)."""
    from exubio.protocol.load import read_protocol_mapping

    sides: dict[str, str] = {}
    for path in protocols:
        side = read_protocol_mapping(path).get("side", "right")
        if side in sides:
            raise InputError(f"--protocol {path} and --protocol {sides[side]} are both for the {side} arm; give one "
                             f"protocol per arm (side: right / side: left)")
        sides[side] = path
    codes = []
    for side, path in sides.items():
        print(f"== {side} arm ({path})")
        codes.append(_reconstruct_one_protocol(argparse.Namespace(**{**vars(args), "protocol": path,
                                                                     "out": str(Path(args.out) / side)})))
    return max(codes)


def _reconstruct_one_protocol(args: argparse.Namespace) -> int:
    from exubio.io.trial import read_trial
    from exubio.protocol.labels import parse_relabel, relabel_trajectories
    from exubio.run.session import calibrate_session

    if args.also_static and not args.static:
        raise InputError(f"--also-static {args.also_static[0]}: further static poses refine the calibration on a static "
                         f"trial; give --static STATIC as well")
    if args.functional and not args.static:
        raise InputError(f"--functional {args.functional}: a functional trial refines the calibration on a static "
                         f"trial; give --static STATIC as well")
    if args.scapula_trial and not args.static:
        raise InputError(f"--scapula-trial {args.scapula_trial[0]}: a scapula movement trial refines the calibration on a "
                         f"static trial; give --static STATIC as well")
    if args.jobs < 1:
        raise InputError(f"--jobs {args.jobs}: expected a whole number of processes >= 1")
    seen: dict[str, str] = {}  # file name -> the trial of that name
    for t in args.trials:  # results are named after the trial file: two of one name would mix
        other = seen.get(Path(t).stem)
        if other is not None and Path(t).resolve() == Path(other).resolve():
            raise InputError(f"{t}: the same trial is given twice ({other} and {t}); give each trial once")
        if other is not None:
            raise InputError(f"{t} and {other} have the same file name: their results in {args.out} would be mixed; "
                             f"reconstruct them into different --out folders")
        seen[Path(t).stem] = str(t)
    check_output_folder(Path(args.out), args.out)
    fill_run.check_fill(args)
    relabel = parse_relabel(args.relabel, option="--relabel")
    static_relabel = parse_relabel(args.static_relabel, option="--static-relabel")
    if static_relabel and not args.static:
        raise InputError(f"--static-relabel {args.static_relabel}: relabels the static trial; give --static STATIC too")
    from exubio.run.inputs import load_session

    session = load_session(model_path=args.model, protocol_path=args.protocol, body_mass_kg=args.body_mass,
                           signs=args.signs)
    calibration = None
    if args.static:
        from exubio.run.session import calibrate_session

        static = read_trial(args.static)
        if static_relabel:
            static = relabel_trajectories(static, static_relabel, option="--static-relabel")
        calibration = calibrate_session(static, session, args.out, Path(args.static).stem, spec=static_spec(args),
                                        overwrite=args.overwrite)
        if not args.quiet:
            from exubio.calibration import format_report

            print(format_report(calibration.report))
            print(f"calibrated model: {calibration.model_file}")
        if calibration.reused:
            print(f"calibration reused (same static, protocol, model and options): {calibration.model_file}")
        for f in calibration.labels:
            fix = f"; to fix: --static-relabel {','.join(f'{a}={b}' for a, b in f.relabel.items())}" if f.relabel else ""
            print(f"static trial {args.static}: {f.severity}: {f.kind} ({', '.join(f.markers)}): {f.evidence}{fix}")
    from exubio.run.job import TrialJob, run_job
    from exubio.run.moments_outputs import check_pf_option, pf_options

    methods = _methods(args.method)
    check_pf_option(args, methods)
    jobs = [TrialJob(t, args.out, methods=tuple(methods), session=session, overwrite=args.overwrite,
                     options={"pf": pf_options(args, session.protocol)} if "pf" in methods else {},
                     calibration=calibration, static_frames=None if args.static else args.static_frames,
                     report=not args.no_report, relabel=relabel, repair_labels=args.repair_labels,
                     hand_load_kg=_hand_load(args), moment_request=_moment_request(args)) for t in args.trials]
    if len(jobs) == 1 and not args.scheduler:  # errors propagate to main(): one message, one exit code
        result = run_job(jobs[0], progress_factory=progress_factory(not args.quiet))
        print_trial(result, args.quiet)
        if args.fill:
            fill_run.fill_after_run(args, result, calibration.session if calibration else session)
        return trial_code(result)
    codes = []
    from exubio.run.executors import run_all

    try:
        done = run_all(_run_trial, jobs, jobs=args.jobs, scheduler=args.scheduler,
                       on_error=lambda job, exc: (str(job.trial), None, EXIT_FAILED, f"{type(exc).__name__}: {exc}"))
    except KeyboardInterrupt:
        if args.scheduler:  # Dask's workers were stopped: their unfinished files go now
            from exubio.io.results import remove_after_interrupt

            for job in jobs:
                remove_after_interrupt(job.out_dir, [f"{job.trial.stem}.{m}" for m in job.methods]
                                       + [f"{job.trial.stem}.report"])
        raise
    for trial, result, code, message in done:
        print(f"== {trial}")
        if result is not None:
            print_trial(result, args.quiet)
            print(f"verdict: {', '.join(f'{m} {v}' for m, v in result.verdicts.items())}")
        else:
            print(f"exubio: {'error' if code == EXIT_BAD_INPUT else 'reconstruction failed'}: {message}",
                  file=sys.stderr)
        codes.append(code)
    failed = sum(r is None for _, r, _, _ in done)
    print(f"{len(codes) - failed} of {len(codes)} trials reconstructed")
    for trial, result, _, _ in done:
        if result is not None:
            print(f"  {trial}: " + ", ".join(f"{m} {v}" for m, v in result.verdicts.items()))
    return max(codes)


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    r = sub.add_parser("reconstruct", parents=[common], help="joint angles from a C3D/TRC trial",
                       formatter_class=argparse.RawDescriptionHelpFormatter, epilog=epilog("reconstruct", EXIT_CODES_HELP))
    r.add_argument("trials", nargs="+", metavar="TRIAL", help="trial file(s) (.c3d or .trc); several = a study")
    r.add_argument("--jobs", type=int, default=1, help="trials reconstructed in parallel processes (default 1)")
    r.add_argument("--scheduler", help="reconstruct the trials on Dask: local:N (a local cluster of N workers) or "
                                       "tcp://HOST:PORT (a running scheduler); the files are those of a local run")
    r.add_argument("--protocol", action="append",
                   help="protocol YAML (default: protocols/upper_limb_21.yaml); give it twice, one per arm (side: right "
                        "and side: left), to reconstruct both arms of the trial into --out/right and --out/left")
    r.add_argument("--both-arms", action="store_true", help="both arms of the trial with one --protocol: it and the "
                   "protocol its other_arm key names (the shipped plug_in_gait_upper and isb_landmarks have one), into "
                   "--out/right and --out/left")
    r.add_argument("--model", help="model YAML (default: models/upper_extremity.yaml)")
    r.add_argument("--method", choices=[*method_names(), "both"], default="pf",
                   help="; ".join(f"{m}: {REGISTRY[m].description}" for m in method_names())
                        + "; both: pf and ls, compared; if one fails, the other's result is still written, the failure "
                        "is reported with its reason and the exit code is 1 (default: pf)")
    r.add_argument("--body-mass", type=float, help="body mass, kg (scales segment inertia); also writes the joint "
                   "moments, <stem>.<method>.moments.csv (inverse dynamics, Dumas et al. 2007 inertia; docs: moments)")
    r.add_argument("--hand-load-kg", type=float, help="mass held in the hand, kg, for the joint moments (needs --body-mass)")
    add_moment_arguments(r)
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--overwrite", action="store_true", help="replace earlier results in --out")
    r.add_argument("--no-report", action="store_true", help="skip the per-trial PDF/PNG report")
    r.add_argument("--static", help="static trial: calibrate the model to the subject first (once, for every trial)")
    r.add_argument("--relabel", metavar="A=B,...", help="read these labels of the task trial(s) as others, for these "
                   "trials only (not the static): e.g. RADIUS=ULNA,ULNA=RADIUS undoes a swap; a permutation, never a merge")
    r.add_argument("--repair-labels", action="store_true", help="exchange back two labels that auto-labelling "
                   "exchanged in part of a trial (found frame range by range; reported, the verdict a check)")
    r.add_argument("--static-relabel", metavar="A=B,...", help="the same for the --static trial only (a protocol's "
                   "relabel: applies to every trial of the session, the static included)")
    r.add_argument("--also-static", metavar="TRIAL", action="append", help="a further static pose of the session (e.g. arm raised; repeatable): the thorax ellipsoid is "
                        "fitted through the scapula contact points of every static pose")
    r.add_argument("--functional", metavar="TRIAL", help="movement trial of the same session (arm moved in several planes): glenohumeral centre by SCoRE "
                        "(Ehrig et al. 2006) instead of from the generic model; not used, with the reason, if its "
                        "motion does not determine it")
    r.add_argument("--scapula-trial", metavar="TRIAL", action="append", help="movement trial of the same session (arm raised in one or more "
                        "planes): the thorax ellipsoid is fitted through the scapula contact points of all its postures "
                        "and the static pose (repeatable: postures pooled); not used, with the reason, if the movement cannot determine it")
    r.add_argument("--static-frames", help="A:B frames used for the calibration (of --static, or of each trial "
                   "itself when there is no static trial)")
    fill_run.add_fill_arguments(r)
    r.add_argument("--gravity", action="store_true",
                   help="PF: apply gravity (-Y of the thorax frame); off by default, the springs then also "
                        "carry the limb's weight and model points sag below their markers")
    from exubio.run.moments_outputs import add_moments_arguments

    add_moments_arguments(r)
    add_signs_arguments(r)
    r.set_defaults(func=cmd_reconstruct)
