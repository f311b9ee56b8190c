"""The ``exubio`` command: parse, call, print. Exit codes: 0 ok (verdicts ok or check), 1 a
reconstruction failed or a verdict is fail (with --method both: one method failed and the other's
result is written), 2 bad input (also an output folder that cannot be written or fills up), 130
interrupted (Ctrl-C). Results go to files, logs to stderr.

Kept whole: the command line's one job (parse, call, print) for every command; the bulk is the
parser's options with their help, examples and exit codes, each command's body a few calls into the run layer.
"""
from __future__ import annotations

import signal
import sys


def _interrupted_while_starting(signum, frame) -> None:  # noqa: ARG001
    """Ctrl-C while this module's own imports run (before main() can catch it): one line, exit 130."""
    sys.stderr.write("exubio: interrupted; nothing was written\n")
    raise SystemExit(130)


if __name__ == "__main__" and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
    signal.signal(signal.SIGINT, _interrupted_while_starting)

import argparse  # noqa: E402
import logging  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING, Callable, Sequence  # noqa: E402

import exubio  # noqa: E402
from exubio.errors import ExubioError, InputError, ModelError, ProtocolError, ReconstructionError  # noqa: E402
from exubio.run import interrupt  # noqa: E402 - Ctrl-C noted (small: no pipeline)
from exubio.truth.locator_cli import add_parser as add_locator_parser  # noqa: E402 - small: its work is imported when it runs
from exubio.run import bids, fill_run  # noqa: E402 - small: --fill's options and work (its solvers are imported when it runs)

if TYPE_CHECKING:  # the CLI imports the pipeline only when a command runs (fast --help)
    from exubio.run.job import TrialJob, TrialResult

log = logging.getLogger("exubio")

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
EXIT_CODES_HELP = (
    "exit codes: 0 ok (every verdict ok or check); 1 a reconstruction failed or a verdict is fail; with "
    "--method both, 1 also when one method failed and the other's result was written (the failure is printed with "
    "its reason); 2 bad input, nothing written (a file, key or marker is named; also an output folder that cannot "
    "be written or a disk that fills up: no result set is left half-written); 130 interrupted by Ctrl-C (results "
    "that were not complete are not there; the next run removes what was left). With several trials: the worst.")


SIMPLE_EXIT_CODES = "exit codes: 0 done; 2 bad input (the file, key or value is named), nothing written; 130 interrupted."
PRINT_EXIT_CODES = "exit codes: 0 printed; 2 bad input (the name, file or segment is named, with what exists)."

EXAMPLES = {
    "simulate": "exubio simulate --motion abduction --duration 10 --rate 100 --noise-mm 1 --sta-mm 10 --out abd.c3d",
    "reconstruct": "exubio reconstruct trial.c3d --static static.c3d --method both --out results/\n"
                   "  exubio reconstruct trial.trc --protocol thoracoscapular_9 --static-frames 0:50 --out results/",
    "calibrate": "exubio calibrate static.c3d --out subject.yaml   (then: exubio reconstruct trial.c3d --model subject.yaml ...)",
    "validate": "exubio validate            (about 4-6 minutes on 2 cores; --quick: a smoke run)",
    "export-model": "exubio export-model subject.yaml --format osim --out subject.osim   (exubio's .mot plays on it)",
    "study": "exubio study --template > study.yaml   (a study file with every key explained)\n"
             "  exubio study study.yaml --out results/ --jobs 2",
    "view": "exubio view results/trial.pf.npz --out trial.html",
    "demo": "exubio demo   (writes ./exubio_demo/)",
    "protocols": "exubio protocols   (the shipped ones)\n  exubio protocols upper_limb_21   (its markers, what it measures)\n"
                 "  exubio protocols my.yaml --static static.c3d   (checked against your static)",
    "model-points": "exubio model-points --segment humerus\n"
                    "  exubio model-points subject.yaml   (a calibrated model)",
}
"""An example per command, shown by its --help."""


def _epilog(command: str, codes: str = SIMPLE_EXIT_CODES) -> str:
    return f"example:\n  {EXAMPLES[command]}\n\n{codes}"


def _progress_factory(enabled: bool) -> Callable[[str, int], Callable[[int], None]] | None:
    if not enabled:
        return None
    from tqdm import tqdm

    def factory(label: str, total: int) -> Callable[[int], None]:
        bar = tqdm(total=total, desc=f"{label} frames", unit="frame", file=sys.stderr, leave=False,
                   mininterval=0.5)

        def update(n: int) -> None:
            bar.update(n)
            if bar.n >= total:
                bar.close()

        return update

    return factory


def _methods(value: str) -> list[str]:
    return ["pf", "ls"] if value == "both" else [value]


def cmd_simulate(args: argparse.Namespace) -> int:
    from exubio.model.load import load_model
    from exubio.synth.simulate import Motion, simulate_trial, write_simulated_trial

    out = Path(args.out)
    if out.suffix.lower() != ".c3d":
        raise InputError(f"--out {out}: expected a path ending in .c3d")
    from exubio.synth.perturb import ModelPerturbation

    model = (load_model(args.model, body_mass_kg=args.body_mass) if args.model
             else load_model(body_mass_kg=args.body_mass))
    perturbation = ModelPerturbation.parse(args.perturb) if args.perturb else None
    if perturbation is not None:
        perturbation.apply(model)  # bad segment or point names: exit 2 before any work
    out.parent.mkdir(parents=True, exist_ok=True)
    trial = simulate_trial(model, Motion.parse(args.motion), duration_s=args.duration, rate_hz=args.rate,
                           noise_mm=args.noise_mm, sta_mm=args.sta_mm, seed=args.seed, perturbation=perturbation,
                           sta_model=args.sta, cycle_s=args.cycle_s)
    if trial.sta_model != "per-marker":
        print(f"soft-tissue artefact: {trial.sta_model}")
    if args.protocol:
        from exubio.run.inputs import protocol_for_model
        from exubio.synth.protocol_markers import with_protocol_markers

        trial = with_protocol_markers(trial, [protocol_for_model(model, p) for p in args.protocol],
                                      noise_mm=args.noise_mm, seed=args.seed)
    c3d, truth = write_simulated_trial(trial, out)
    if perturbation is not None:
        print(f"generated with the model perturbed by {' '.join(perturbation.words()) or 'nothing'} (in {truth.name}'s header)")
    print(f"wrote {c3d} ({trial.trajectories.n_markers} markers, {trial.trajectories.n_frames} frames, "
          f"{args.rate:g} Hz, noise {args.noise_mm:g} mm, soft-tissue artefact {args.sta_mm:g} mm)")
    print(f"wrote {truth} (true joint angles, deg)")
    if args.body_mass is not None:
        from exubio.synth.truth_moments import write_truth_moments

        moments = write_truth_moments(trial, out, hand_load_kg=args.hand_load_kg)
        print(f"wrote {moments} (true joint moments, N m: {args.body_mass:g} kg, {args.hand_load_kg:g} kg in the hand)")
    return EXIT_OK


def _hand_load(args: argparse.Namespace) -> float | None:
    """The hand load of the joint moments (None: no moments): they are written with --body-mass."""
    load = getattr(args, "hand_load_kg", None)
    if load is not None and args.body_mass is None:
        raise InputError("--hand-load-kg: the joint moments need the subject's --body-mass (kg) too")
    if load is not None and not (load >= 0 and load != float("inf")):
        raise InputError(f"--hand-load-kg must be a number >= 0 (kg), got {load}")
    return None if args.body_mass is None else float(load or 0.0)


def _print_summary(method: str, paths: dict, summ: dict) -> None:
    r = summ["residual_mm"]
    print(f"[{method}] {summ['n_frames']} frames in {summ['wall_time_s']:.2f} s "
          f"({summ['ms_per_frame']:.3f} ms/frame); residual mean {r['mean']:.2f} mm, SD {r['sd']:.2f} mm, "
          f"max {r['max']:.2f} mm ({r['max_marker']}); max |g| {summ['constraint_max_abs']:.1e}")
    not_conv = summ["frames"].get("not_converged", 0) + summ["frames"].get("too_few_markers", 0)
    if not_conv:
        print(f"[{method}] WARNING: {not_conv} frames not converged or with too few markers "
              f"(see status in {Path(paths['npz']).name})")
    if summ["gaps"]:
        print(f"[{method}] gaps: " + ", ".join(f"{g['marker']} {g['duration_s']:.2f} s at {g['start_s']:.2f} s"
                                             for g in summ["gaps"][:8])
              + (" ..." if len(summ["gaps"]) > 8 else ""))
    if summ.get("absent_markers"):
        print(f"[{method}] optional markers absent from the trial: {', '.join(summ['absent_markers'])}")
    for key in ("csv", "mot", "npz", "summary"):
        print(f"  {paths[key]}")


def _print_result(recon, paths, summ) -> None:
    _print_summary(recon.method, paths, summ)


def _print_trial(result: TrialResult, quiet: bool) -> None:
    from exubio.calibration import format_report

    if result.calibration and not quiet:
        print(format_report(result.calibration.report))
        print(f"calibrated model: {result.calibration.model_file}")
    for m in result.methods:
        if m.method in result.kept:
            print(f"[{m.method}] kept: its result set is complete from an earlier run of the same inputs "
                  f"(resumed; --overwrite computes it again)")
        if not quiet:
            _print_summary(m.method, m.paths, m.summary)
    if result.agreement_deg and not quiet:
        agree = result.agreement_deg
        worst = max(agree, key=agree.get)
        print(f"PF-LS agreement: max RMSE {agree[worst]:.3f} deg ({worst})")
    if result.report and not quiet:
        kept = " (kept from the earlier run)" if "report" in result.kept else ""
        print(f"report: {result.report['pdf']} (+ .png){kept}")
    for m in result.methods:
        if quiet:
            _print_quality_short(m.method, m.paths, m.summary)
        else:
            _print_quality(m.method, m.summary)
    for method, reason in result.failed.items():
        print(f"[{method}] FAILED, nothing written for it: {reason}")
        print(f"[{method}] the other method's result is written (exit code 1)")


def _print_quality(method: str, summ: dict) -> None:
    q = summ.get("quality")
    if not q:
        return
    print(f"[{method}] QUALITY: {q['verdict'].upper()}")
    for r in q["reasons"]:
        print(f"[{method}]   {r['level']}: {r['message']}")
    if summ.get("not_measured"):
        print(f"[{method}]   not measured (held or not observed): {', '.join(summ['not_measured'])}")


def _print_quality_short(method: str, paths: dict, summ: dict) -> None:
    """-q: the verdict with the result files and the residual on one line, then only the reasons
    that make it a check or a fail (the notes are in summary.json and the report)."""
    q = summ.get("quality")
    files = str(paths["summary"])[: -len(".summary.json")] + ".*"
    r = summ["residual_mm"]
    verdict = q["verdict"].upper() if q else "NOT ASSESSED"
    print(f"[{method}] QUALITY: {verdict}: {files} ({summ['n_frames']} frames, residual mean {r['mean']:.2f} mm)")
    for reason in (q or {}).get("reasons", ()):
        if reason["level"] != "note" or reason["code"] in QUIET_NOTES or reason["code"].startswith("live_"):
            print(f"[{method}]   {reason['level']}: {reason['message']}")


QUIET_NOTES = ("gap", "input_file", "method_failed", "label_repaired", "missing_marker")
"""Notes -q still prints: what happened to this trial's data (a gap, a file read around, a method
that failed, labels repaired, a marker left out; live: frames dropped, late, skipped, restarts).
The notes on the marker set and the model (angles it cannot measure, gimbal lock, calibration
details) are the same for every trial of a protocol: summary.json and the report give them."""


def _trial_code(result: TrialResult) -> int:
    """1 when a method failed (the others' results written) or any method's verdict is 'fail'
    (see exubio.trust.quality), else 0."""
    return EXIT_FAILED if result.failed or "fail" in result.verdicts.values() else EXIT_OK


def _check_output_folder(folder: Path, out: str) -> None:
    """Refuse (exit 2) before any work an --out whose folder is a file, cannot be created or cannot
    be written (exubio.io.results.writable_folder)."""
    from exubio.io.results import writable_folder

    writable_folder(folder, label=f"--out {out}")


def cmd_calibrate(args: argparse.Namespace) -> int:
    from exubio.calibration import format_report, parse_frames
    from exubio.run.inputs import load_session
    from exubio.run.session import calibrate_file

    if Path(args.out).suffix.lower() not in (".yaml", ".yml"):
        raise InputError(f"--out {args.out}: expected a model file ending in .yaml")
    _check_output_folder(Path(args.out).parent, args.out)
    parse_frames(args.static_frames)  # a malformed --static-frames is refused before anything is read
    session = load_session(model_path=args.model, protocol_path=args.protocol, body_mass_kg=args.body_mass)
    _, _, report = calibrate_file(args.static, session=session, spec=_static_spec(args), out_path=args.out,
                                  overwrite=args.overwrite)
    print(format_report(report))
    print(f"wrote {args.out}")
    return EXIT_OK


def _static_spec(args: argparse.Namespace):
    from exubio.run.session import StaticSpec

    return StaticSpec(frames=args.static_frames, functional=Path(args.functional) if args.functional else None,
                      more_statics=tuple(Path(p) for p in args.also_static or ()),
                      scapula_trials=tuple(Path(p) for p in args.scapula_trial or ()))


def _run_trial(job: TrialJob) -> tuple[str, TrialResult | None, int, str]:
    """One trial in a worker process: (trial, result, exit code, error message)."""
    from exubio.run.job import run_job

    trial = str(job.trial)
    try:
        result = run_job(job)
        return trial, result, _trial_code(result), ""
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
    _check_output_folder(Path(args.out), args.out)
    fill_run.check_fill(args)
    relabel = parse_relabel(args.relabel, option="--relabel")
    static_relabel = parse_relabel(args.static_relabel, option="--static-relabel")
    if static_relabel and not args.static:
        raise InputError(f"--static-relabel {args.static_relabel}: relabels the static trial; give --static STATIC too")
    from exubio.run.inputs import load_session

    session = load_session(model_path=args.model, protocol_path=args.protocol, body_mass_kg=args.body_mass)
    calibration = None
    if args.static:
        from exubio.run.session import calibrate_session

        static = read_trial(args.static)
        if static_relabel:
            static = relabel_trajectories(static, static_relabel, option="--static-relabel")
        calibration = calibrate_session(static, session, args.out, Path(args.static).stem, spec=_static_spec(args),
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

    methods = _methods(args.method)
    jobs = [TrialJob(t, args.out, methods=tuple(methods), session=session, overwrite=args.overwrite,
                     options={"pf": {"gravity": args.gravity}} if "pf" in methods else {},
                     calibration=calibration, static_frames=None if args.static else args.static_frames,
                     report=not args.no_report, relabel=relabel, repair_labels=args.repair_labels,
                     hand_load_kg=_hand_load(args)) for t in args.trials]
    if len(jobs) == 1 and not args.scheduler:  # errors propagate to main(): one message, one exit code
        result = run_job(jobs[0], progress_factory=_progress_factory(not args.quiet))
        _print_trial(result, args.quiet)
        if args.fill:
            fill_run.fill_after_run(args, result, calibration.session if calibration else session)
        return _trial_code(result)
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
            _print_trial(result, args.quiet)
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


EXAMPLE_COMMAND = ("exubio simulate --motion abduction --duration 10 --rate 100 --noise-mm 1 --sta-mm 10 "
                   "--seed 1 --out exubio/data/example_abduction.c3d")


def cmd_demo(args: argparse.Namespace) -> int:
    import numpy as np

    from exubio.io.resources import shipped_file
    from exubio.io.results import read_angles_csv
    from exubio.run.pipeline import reconstruct_file
    from exubio.trust.evaluate import measured_angle_rmse_deg

    out = Path(args.out)
    c3d = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    truth_csv = c3d.with_name("example_abduction.truth.csv")
    print(f"example trial: {c3d}")
    print("  synthetic arm abduction, 10 s at 100 Hz, 22 markers, 1 mm noise, 10 mm soft-tissue artefact;")
    print(f"  made by: {EXAMPLE_COMMAND}")
    print(f"reconstructing it with the potential-field (pf) and least-squares (ls) methods -> {out}")
    from exubio.run.inputs import load_session
    from exubio.run.pipeline import RunSettings

    session = load_session()
    outputs = reconstruct_file(c3d, out, methods=["pf", "ls"], session=session,
                               settings=RunSettings(overwrite=True, progress_factory=_progress_factory(not args.quiet)))
    t_true, names, q_true = read_angles_csv(truth_csv)
    from exubio.model.angles import anatomical_table
    from exubio.io.results import read_npz_arrays

    angle_names, true_angles = anatomical_table(session.model, q_true)
    for recon, paths, summ in outputs:
        _print_result(recon, paths, summ)
        status = read_npz_arrays(paths["npz"], ("angle_status",))["angle_status"]
        measured = measured_angle_rmse_deg(session.model, recon.q_rad, q_true, status)
        print(f"[{recon.method}] anatomical angles against the truth, the {len(measured)} measured ones: RMSE mean "
              f"{np.mean(list(measured.values())):.2f} deg, max {max(measured.values()):.2f} deg "
              f"({max(measured, key=measured.get)}); SC elevation {measured.get('SC_X_elevation', float('nan')):.2f}, "
              f"SC protraction {measured.get('SC_Y_protraction', float('nan')):.2f} deg")
        others = (summ.get("anatomical_angles") or {}).get("status", {})
        for label in ("modelled", "not measured"):
            these = [n for n, v in others.items() if v.endswith(label)]
            if these:
                print(f"[{recon.method}] {label} (not compared with the truth): {', '.join(these)}")
        _print_quality(recon.method, summ)
    agree = {k: v for k, v in (outputs[0][2].get("pf_ls_agreement_deg") or {}).items() if isinstance(v, float)}
    worst = max(agree, key=agree.get)
    print(f"PF-LS agreement (measured anatomical angles): max RMSE {agree[worst]:.3f} deg ({worst})")
    from exubio.report.trial_report import Truth, build_trial_report

    pdf, png = build_trial_report([paths["npz"] for _, paths, _ in outputs], out / "example_abduction.report.pdf",
                                  truth=Truth(t_true, angle_names, true_angles))
    print(f"report: {pdf} and {png}")
    print(f"results are in {out.resolve()}")
    return EXIT_OK


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


def cmd_protocols(args: argparse.Namespace) -> int:
    from exubio.run.inputs import protocol_for_model
    from exubio.model.load import load_model
    from exubio.protocol.load import read_protocol_mapping, resolve_protocol, shipped_protocols

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


def cmd_export_model(args: argparse.Namespace) -> int:
    from exubio.export import write_biomod, write_osim
    from exubio.model.load import load_model

    model = load_model(args.model)
    if args.format == "osim":
        path = write_osim(model, args.out, overwrite=args.overwrite, coordinates=args.coordinates)
        plays = ("its coordinates are the anatomical angles, so exubio's .mot plays on it" if args.coordinates == "anatomical"
                 else "its coordinates are exubio's model coordinates (the q of the .npz)")
    else:
        path = write_biomod(model, args.out, overwrite=args.overwrite)
        plays = "its generalized coordinates are exubio's model coordinates (the q of the .npz)"
    print(f"wrote {path}: an open chain (the scapulothoracic ellipsoid cannot be expressed in this format; the file's "
          f"header gives it); {plays}")
    return EXIT_OK


def cmd_study(args: argparse.Namespace) -> int:
    from exubio.run.study import load_study, run_study
    from exubio.run.study_template import STUDY_TEMPLATE

    if args.template:
        print(STUDY_TEMPLATE, end="")
        return 0
    if not args.study or not args.out:
        raise InputError("exubio study: expected STUDY.yaml and --out FOLDER (or --template to print a study file)")
    spec = load_study(args.study)  # every key, path and glob checked before any work
    if args.jobs < 1:
        raise InputError(f"--jobs {args.jobs}: expected a whole number of processes >= 1")
    _check_output_folder(Path(args.out), args.out)
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


def cmd_view(args: argparse.Namespace) -> int:
    from exubio.report.viewer import write_view

    if args.max_frames < 2:
        raise InputError(f"--max-frames {args.max_frames}: expected at least 2 animation frames")
    out = write_view([Path(p) for p in args.results], Path(args.out), overwrite=args.overwrite,
                     model_path=args.model, max_frames=args.max_frames)
    print(f"view: {out} (one HTML file, works offline; open it in a browser)")
    return EXIT_OK


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

    from exubio.run.live.app import LiveControl, LiveOutput, run_live
    from exubio.run.live.causal import CausalOptions
    from exubio.run.live.display import Display
    from exubio.run.live.options import LiveOptions
    from exubio.run.live.transport import LSLSource, load_pylsl
    from exubio.run.inputs import load_model_and_protocol

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
    summ = _json_file(run.folder / f"{name}.pf.summary.json")
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


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="exubio", epilog=EXIT_CODES_HELP, description="Upper-extremity joint kinematics from skin markers "
                                "(potential-field and least-squares methods on Exudyn).")
    p.add_argument("--version", action="version", version=f"exubio {exubio.__version__}")
    # -v/-q work before and after the subcommand (SUPPRESS: a subcommand's default does not reset them)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="log details to stderr")
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help="no progress bars, shorter output")
    p.add_argument("-v", "--verbose", action="store_true", help="log details to stderr")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, shorter output")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=_epilog("simulate"), help="write a synthetic trial (C3D) and its true joint angles (CSV)")
    s.add_argument("--motion", required=True, choices=["abduction", "flexion", "scaption", "sier"])
    s.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    s.add_argument("--rate", type=float, default=100.0, help="sampling rate, Hz (default 100)")
    s.add_argument("--noise-mm", type=float, default=0.0, help="Gaussian measurement noise SD, mm")
    s.add_argument("--sta-mm", type=float, default=0.0, help="soft-tissue artefact amplitude, mm")
    s.add_argument("--sta", default="per-marker", metavar="MODEL",
                   help="soft-tissue artefact model: per-marker (default: each marker its own random artefact of "
                        "--sta-mm), bone (fitted on bone pins, S2M: exubio/data/sta_bone_s2m.json) or a model JSON of "
                        "'exubio sta-fit': the scapula and humerus markers move as a cluster over the bone as the model "
                        "predicts from the simulated angles, plus its non-rigid rest; the clavicle, forearm and hand "
                        "markers keep the per-marker artefact of --sta-mm (the model has no data for them), the thorax none")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--cycle-s", type=float, default=5.0, help="period of the elevation cycles, s (default 5: a slow "
                   "raise; 0.6: a fast one, peak angular accelerations of thousands of deg/s^2)")
    s.add_argument("--body-mass", type=float, help="body mass, kg: also write PATH.truth_moments.csv, the motion's "
                   "exact joint moments (Dumas et al. 2007 inertia)")
    s.add_argument("--hand-load-kg", type=float, default=0.0, help="mass held in the hand, kg (with --body-mass)")
    s.add_argument("--model", help="model YAML (default: the generic model)")
    s.add_argument("--perturb", nargs="+", metavar="KEY=VALUE",
                   help="generate with the model perturbed (mm in the thorax frame; a model mismatch for a reconstruction "
                        "with the unperturbed model): ellipsoid_centre_mm=DX,DY,DZ ellipsoid_radii_scale=S|SX,SY,SZ "
                        "length.SEGMENT=S joint.SEGMENT=DX,DY,DZ marker.POINT=DX,DY,DZ; written into the truth file's header")
    s.add_argument("--protocol", action="append", help="write this protocol's markers instead of the default set "
                   "(at its positions, under its labels; side: left mirrors the simulated arm); give it twice, one "
                   "per arm, for a trial of both arms (noise-free or --noise-mm; no --sta-mm)")
    s.add_argument("--out", required=True, help="PATH.c3d; PATH.truth.csv is written beside it")
    s.set_defaults(func=cmd_simulate)

    r = sub.add_parser("reconstruct", parents=[common], help="joint angles from a C3D/TRC trial",
                       formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_epilog("reconstruct", EXIT_CODES_HELP))
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
    r.add_argument("--method", choices=["pf", "ls", "both"], default="pf",
                   help="pf: potential field on Exudyn; ls: constrained least squares per frame; both: the "
                        "two, compared; if one fails, the other's result is still written, the failure is "
                        "reported with its reason and the exit code is 1 (default: pf)")
    r.add_argument("--body-mass", type=float, help="body mass, kg (scales segment inertia); also writes the joint "
                   "moments, <stem>.<method>.moments.csv (inverse dynamics, Dumas et al. 2007 inertia; docs: moments)")
    r.add_argument("--hand-load-kg", type=float, help="mass held in the hand, kg, for the joint moments (needs --body-mass)")
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
    r.set_defaults(func=cmd_reconstruct)

    c = sub.add_parser("calibrate", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=_epilog("calibrate"), help="fit the model to a subject from a static trial")
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

    v = sub.add_parser("validate", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=_epilog("validate"), help="the paper's evaluation (Fig. 2-5, Table 1) as a PDF/PNG report")
    v.add_argument("--out", default="reports/validation", help="output folder (default reports/validation)")
    v.add_argument("--quick", action="store_true", help="short trials (a smoke run, not the report)")
    v.set_defaults(func=cmd_validate)

    e = sub.add_parser("export-model", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=_epilog("export-model"),
                       help="write a model YAML (generic or calibrated) as an OpenSim .osim or a biorbd .bioMod")
    e.add_argument("model", help="model YAML (e.g. models/upper_extremity.yaml or one written by exubio calibrate)")
    e.add_argument("--format", required=True, choices=["osim", "biomod"], help="osim: OpenSim 4; biomod: biorbd")
    e.add_argument("--out", required=True, help="FILE.osim or FILE.bioMod to write")
    e.add_argument("--overwrite", action="store_true", help="replace an existing FILE")
    e.add_argument("--coordinates", choices=["anatomical", "model"], default="anatomical",
                   help="osim only: anatomical (default; SC, AC, GH between the ISB frames with the anatomical angles "
                        "as coordinates, so exubio's .mot plays on it) or model (exubio's own joint coordinates)")
    e.set_defaults(func=cmd_export_model)

    st = sub.add_parser("study", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                        help="run a study file (subjects x sessions x trials); re-running resumes it",
                        epilog=_epilog("study", EXIT_CODES_HELP))
    st.add_argument("study", nargs="?", help="STUDY.yaml (its format: exubio study --template)")
    st.add_argument("--out", help="output folder: <subject>/<session>/<trial>/, study.csv, study.json")
    st.add_argument("--template", action="store_true", help="print a study file with every key explained, and exit")
    st.add_argument("--jobs", type=int, default=1, help="trials in parallel local processes (default 1)")
    bids.add_bids_arguments(st)
    st.add_argument("--scheduler", help="run the trials on Dask: local:N (a local cluster of N workers) or "
                                        "tcp://HOST:PORT (a running scheduler)")
    st.set_defaults(func=cmd_study)

    w = sub.add_parser("view", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=_epilog("view"),
                       help="write an interactive 3D view of a reconstruction (one self-contained, offline HTML file)")
    w.add_argument("results", nargs="+", help="<trial>.<method>.npz (the trial's other method beside it is shown too)")
    w.add_argument("--out", required=True, help="the HTML file to write")
    w.add_argument("--overwrite", action="store_true", help="replace an existing file")
    w.add_argument("--model", help="the model YAML, when the one the result names cannot be found")
    w.add_argument("--max-frames", type=int, default=300, help="at most this many animation frames (default 300)")
    w.set_defaults(func=cmd_view)

    pr = sub.add_parser("protocols", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                        help="list the shipped protocols (by name, usable from any folder) and, with a name, the "
                        "markers of one", epilog=_epilog("protocols", PRINT_EXIT_CODES))
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
                        epilog=_epilog("model-points", PRINT_EXIT_CODES))
    mp.add_argument("model", nargs="?", default="upper_extremity", help="model YAML or a shipped model's name "
                    "(default: upper_extremity)")
    mp.add_argument("--segment", help="only this segment")
    mp.set_defaults(func=cmd_model_points)

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

    add_locator_parser(sub, common)  # exubio locator: exubio/truth/locator_cli.py
    from exubio.synth.sta_fit_cli import add_parser as _add_sta_fit
    _add_sta_fit(sub, common)

    d = sub.add_parser("demo", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=_epilog("demo"), help="reconstruct the shipped example trial with PF and LS, compare with its truth")
    d.add_argument("--out", default="exubio_demo", help="output folder (default ./exubio_demo)")
    d.set_defaults(func=cmd_demo)

    from exubio.truth.cli_truth import add_parser as add_truth_parser
    add_truth_parser(sub, common)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns its exit code. An output folder the command created and left empty
    (it failed before writing anything) is removed: a failed run leaves nothing behind."""
    new_folder: list[Path] = []
    try:
        return _main(argv, new_folder)
    finally:
        for folder in new_folder:
            try:
                if folder.is_dir() and not any(folder.iterdir()):
                    folder.rmdir()
            except OSError:
                pass


def _main(argv: Sequence[str] | None, new_folder: list[Path]) -> int:
    if signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)  # from here KeyboardInterrupt, caught below
    with interrupt.noted():
        try:  # Ctrl-C at any moment, also while the command's modules are still being imported: exit 130
            args = build_parser().parse_args(argv)
            logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
                                format="%(levelname)s %(name)s: %(message)s")
            out = getattr(args, "out", None)
            if isinstance(out, str) and out:  # the folders the run may create, deepest first
                new_folder += [f for f in (Path(out), *Path(out).parents) if not f.exists()]
            return int(args.func(args))
        except BaseException as exc:  # noqa: BLE001 - Ctrl-C as whatever Exudyn made of it (run.interrupt)
            if not (isinstance(exc, KeyboardInterrupt) or interrupt.pressed() and not isinstance(exc, SystemExit)):
                return _failed(exc)
        newline = "\n" if sys.stderr.isatty() else ""  # a progress bar's line is left open
        print(f"{newline}exubio: interrupted; results that were not complete were not written (the same command "
              "again resumes: it keeps what is complete)", file=sys.stderr)
        return EXIT_INTERRUPTED


def _failed(exc: BaseException) -> int:
    """The exit code of an error of exubio's (said on one line); any other error goes on."""
    if isinstance(exc, (InputError, ProtocolError, ModelError)):
        print(f"exubio: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if isinstance(exc, ReconstructionError):
        print(f"exubio: reconstruction failed: {exc}", file=sys.stderr)
        return EXIT_FAILED
    if isinstance(exc, ExubioError):
        print(f"exubio: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    raise exc


def run() -> None:
    """The ``exubio`` command (console script and ``python -m exubio.cli``): main(), then exit with its
    code. Once main() has returned the work is done and written; a Ctrl-C during the interpreter's
    teardown (it restores the default handler there, which would kill the process with -SIGINT, no
    message, though every result is complete) is then ignored."""
    code = main()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _forget_a_handled_interrupt()
    sys.exit(code)


def _forget_a_handled_interrupt() -> None:
    """A Ctrl-C that lands while an ``exec`` of a string runs (SciPy's imports run some) sets CPython's
    "unhandled KeyboardInterrupt" flag, though main() caught it and returns 130; ``python -m exubio.cli``
    then ends by SIGINT (exit -2) instead of 130. Every ``exec`` of a string starts by clearing that
    flag (CPython's run_eval_code_obj), so one more, of nothing, clears it."""
    exec("pass")  # noqa: S102 - a constant: see above


if __name__ == "__main__":
    run()
