"""What the commands share: exit codes, examples, progress bars and how a trial's result is printed."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from exubio.run.job import TrialResult

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


def epilog(command: str, codes: str = SIMPLE_EXIT_CODES) -> str:
    return f"example:\n  {EXAMPLES[command]}\n\n{codes}"


def progress_factory(enabled: bool) -> Callable[[str, int], Callable[[int], None]] | None:
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


def print_summary(method: str, paths: dict, summ: dict) -> None:
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


def print_result(recon, paths, summ) -> None:
    print_summary(recon.method, paths, summ)


def print_trial(result: TrialResult, quiet: bool) -> None:
    from exubio.calibration import format_report

    if result.calibration and not quiet:
        print(format_report(result.calibration.report))
        print(f"calibrated model: {result.calibration.model_file}")
    for m in result.methods:
        if m.method in result.kept:
            print(f"[{m.method}] kept: its result set is complete from an earlier run of the same inputs "
                  f"(resumed; --overwrite computes it again)")
        if not quiet:
            print_summary(m.method, m.paths, m.summary)
    if result.agreement_deg and not quiet:
        agree = result.agreement_deg
        worst = max(agree, key=agree.get)
        print(f"PF-LS agreement: max RMSE {agree[worst]:.3f} deg ({worst})")
    if result.report and not quiet:
        kept = " (kept from the earlier run)" if "report" in result.kept else ""
        print(f"report: {result.report['pdf']} (+ .png){kept}")
    for m in result.methods:
        if quiet:
            print_quality_short(m.method, m.paths, m.quality, m.summary)
        else:
            print_quality(m.method, m.quality, m.summary.get("not_measured"))
    for method, reason in result.failed.items():
        print(f"[{method}] FAILED, nothing written for it: {reason}")
        print(f"[{method}] the other method's result is written (exit code 1)")


def print_quality(method: str, quality, not_measured=None) -> None:
    """The verdict (exubio.trust.quality.Quality; None: not assessed) and every reason, then the angles
    not measured (held or not observed)."""
    if quality is None:
        return
    print(f"[{method}] QUALITY: {quality.verdict.value.upper()}")
    for r in quality.reasons:
        print(f"[{method}]   {r.level.value}: {r.message}")
    if not_measured:
        print(f"[{method}]   not measured (held or not observed): {', '.join(not_measured)}")


def print_quality_short(method: str, paths: dict, quality, summ: dict) -> None:
    """-q: the verdict (a Quality, or None) with the result files and the residual (as summary.json
    says them) on one line, then only the reasons that make it a check or a fail (the notes are in
    summary.json and the report)."""
    from exubio.io.result_names import SUFFIXES

    files = str(paths["summary"])[: -len(SUFFIXES["summary"])] + ".*"
    r = summ["residual_mm"]
    verdict = quality.verdict.value.upper() if quality is not None else "NOT ASSESSED"
    print(f"[{method}] QUALITY: {verdict}: {files} ({summ['n_frames']} frames, residual mean {r['mean']:.2f} mm)")
    for reason in (quality.reasons if quality is not None else ()):
        if reason.level.value != "note" or reason.code in QUIET_NOTES or reason.code.startswith("live_"):
            print(f"[{method}]   {reason.level.value}: {reason.message}")


QUIET_NOTES = ("gap", "input_file", "method_failed", "label_repaired", "missing_marker")
"""Notes -q still prints: what happened to this trial's data (a gap, a file read around, a method
that failed, labels repaired, a marker left out; live: frames dropped, late, skipped, restarts).
The notes on the marker set and the model (angles it cannot measure, gimbal lock, calibration
details) are the same for every trial of a protocol: summary.json and the report give them."""


def trial_code(result: TrialResult) -> int:
    """1 when a method failed (the others' results written) or any method's verdict is 'fail'
    (see exubio.trust.quality), else 0."""
    return EXIT_FAILED if result.failed or "fail" in result.verdicts.values() else EXIT_OK


def check_output_folder(folder: Path, out: str) -> None:
    """Refuse (exit 2) before any work an --out whose folder is a file, cannot be created or cannot
    be written (exubio.io.results.writable_folder)."""
    from exubio.io.results import writable_folder

    writable_folder(folder, label=f"--out {out}")


def static_spec(args: argparse.Namespace):
    from exubio.run.session import StaticSpec

    return StaticSpec(frames=args.static_frames, functional=Path(args.functional) if args.functional else None,
                      more_statics=tuple(Path(p) for p in args.also_static or ()),
                      scapula_trials=tuple(Path(p) for p in args.scapula_trial or ()))
