"""One trial as a job: what is to be done with it (``TrialJob``) and what came of it (``TrialResult``).

Both are frozen, typed and picklable: ``exubio reconstruct`` runs a job in this process, in a
process pool or on Dask workers, and ``exubio study`` makes one job per trial of its sessions. A job
names its files (trial, model, protocol) and carries the methods' options as their typed objects
(PFOptions, LSOptions: exubio.methods.REGISTRY), checked when the job is made, before any work.
``run_job`` reads the trial once (also when it is calibrated on its own frames), reconstructs it
with every method (exubio.run.pipeline.reconstruct_file: streamed, bounded memory), writes the results
and the trial report, and returns the TrialResult: per method the summary and the files, the
PF-LS agreement, the verdicts, the calibration, and the methods that failed with their reasons
(a method that fails does not take the others' results with it).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from exubio.errors import PartialReconstructionError
from exubio.io import results
from exubio.io.trial import read_trial
from exubio.prep.targets import preparation_key, prepare_targets
from exubio.protocol.labels import relabel_trajectories
from exubio.io.result_names import method_stem, set_paths
from exubio.run.inputs import Session, load_session
from exubio.run.outcome import MethodOutcome, reported
from exubio.run.pipeline import Prepared, RunSettings, reconstruct_file
from exubio.types import Method
from exubio.run.session import SessionCalibration


@dataclass(frozen=True)
class TrialJob:
    """trial: the C3D/TRC file; out_dir: where its results go (named after the trial file);
    methods: "pf" and/or "ls"; session: the model and protocol, loaded once for the session
    (exubio.run.inputs.Session; None: the shipped ones); options: per method its options object
    (or a dict of its fields, turned into the object here); static_frames: calibrate on these
    frames of the trial itself ("0:50"); calibration: the session's calibration
    (exubio.run.session.SessionCalibration: its model, report and static reference go into every
    summary and verdict); relabel: this trial's labels read as other labels ({file label: read
    as}), for this trial only (exubio.protocol.load.relabel_trajectories), before the protocol's
    own relabel; repair_labels: exchange back labels exchanged in part of the trial
    (exubio.trust.label_ranges), reported frame range by range; final_dir: the folder out_dir
    becomes when the job is complete (a study writes each trial in a temporary folder): the
    calibrated model file the results name is the one there."""

    trial: Path
    out_dir: Path
    methods: tuple[str, ...] = ("pf",)
    session: Session | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    static_frames: str | None = None
    report: bool = True
    overwrite: bool = False
    calibration: SessionCalibration | None = None
    relabel: Mapping[str, str] = field(default_factory=dict)
    repair_labels: bool = False
    final_dir: Path | None = None  # where out_dir is renamed to once complete (a study's trial): what the files name
    hand_load_kg: float | None = None  # joint moments with this mass in the hand (exubio.dynamics); None: none
    moment_request: Any = None  # the moments' lab vertical and loads files (exubio.prep.moment_inputs.MomentRequest)

    def __post_init__(self) -> None:
        from exubio.methods import method_spec

        set_ = object.__setattr__
        set_(self, "trial", Path(self.trial))
        set_(self, "out_dir", Path(self.out_dir))
        set_(self, "methods", tuple(Method.parse(m).value for m in self.methods))
        set_(self, "options", {m: method_spec(m).make_options(self.options.get(m)) for m in self.methods})


@dataclass(frozen=True)
class MethodResult:
    """One method's results: its files by kind (csv, mot, npz, summary, isb) and its summary.json."""

    method: str
    paths: Mapping[str, str]
    summary: Mapping[str, Any]
    quality: Any = None  # exubio.trust.quality.Quality: the verdict and its reasons, as summary.json gives them

    @property
    def verdict(self) -> str:
        return self.quality.verdict.value


@dataclass(frozen=True)
class Calibrated:
    """The model a trial was calibrated to on its own frames: its file and CalibrationReport."""

    model_file: str
    report: Any


@dataclass(frozen=True)
class TrialResult:
    trial: str
    methods: tuple[MethodResult, ...]
    agreement_deg: Mapping[str, float] | None = None  # PF-LS RMSE per determined coordinate
    calibration: Calibrated | None = None
    report: Mapping[str, str] | None = None  # "pdf", "png"
    failed: Mapping[str, str] = field(default_factory=dict)  # methods that failed: their reason (no files)
    kept: tuple[str, ...] = ()  # methods (and "report") an earlier run of the same inputs left complete: kept (resumed)

    @property
    def verdicts(self) -> dict[str, str]:
        """Per method its verdict, "failed" for a method that failed."""
        return {**{m.method: m.verdict for m in self.methods}, **{m: "failed" for m in self.failed}}


def run_job(job: TrialJob, /, *, progress_factory: Callable[[str, int], Callable[[int], None]] | None = None
            ) -> TrialResult:
    """Process one trial (see the module docstring). Refuses (InputError) to replace earlier results
    unless ``job.overwrite``."""
    stem = job.trial.stem
    if not job.report:
        return _run_job(job, progress_factory)
    results.writable_folder(job.out_dir)
    with results.claim(job.out_dir, [f"{stem}.report"]):  # no other run writes this trial's report meanwhile
        # a report beside complete result sets may be a resumed run's (exubio.run.resume): judged once
        # the sets are found kept or refused; otherwise refused here, before any work
        sets_there = all(set_paths(job.out_dir, method_stem(stem, m))["summary"].is_file() for m in job.methods)
        results.prepare_output_dir(job.out_dir, [f"{stem}.report.pdf", f"{stem}.report.png"],
                                   overwrite=job.overwrite or sets_there)
        return _run_job(job, progress_factory)


def _run_job(job: TrialJob, progress_factory: Callable[[str, int], Callable[[int], None]] | None) -> TrialResult:
    stem = job.trial.stem
    session = job.session if job.session is not None else load_session()
    calibration, calibrated, prepared = job.calibration, None, None
    trajectories = None  # read here only when it is relabelled or calibrated on its own frames: then read once
    if job.relabel:
        trajectories = relabel_trajectories(read_trial(job.trial), job.relabel)
    if job.static_frames:
        from exubio.run.session import StaticSpec, calibrate_session, calibration_protocol

        trajectories = trajectories if trajectories is not None else read_trial(job.trial)
        gprot = calibration_protocol(trajectories, session)  # a marker the trial lacks: left out, or refused
        static = prepare_targets(trajectories, gprot)  # the calibration's and the trial's
        calibration = calibrate_session(trajectories, session, job.out_dir, stem, spec=StaticSpec(frames=job.static_frames),
                                        overwrite=job.overwrite, reference=False, targets=static)
        if job.final_dir is not None:
            calibration = calibration.moved_to(Path(job.final_dir) / calibration.model_file.name)
        calibrated = Calibrated(str(calibration.model_file), calibration.report)
        prepared = Prepared(preparation_key(gprot), static)
    if calibration is not None:
        session = calibration.session
    settings = RunSettings(method_options=dict(job.options), overwrite=job.overwrite, repair_labels=job.repair_labels,
                           progress_factory=progress_factory, hand_load_kg=job.hand_load_kg,
                           moment_request=job.moment_request)
    failed: dict[str, str] = {}
    try:
        outputs = reconstruct_file(job.trial, job.out_dir, methods=list(job.methods), session=session, settings=settings,
                                   trajectories=trajectories, calibration=calibration, prepared=prepared)
    except PartialReconstructionError as exc:  # one method failed, the others' results are written
        outputs, failed = exc.outputs, dict(exc.failures)
    methods = tuple(MethodResult(o.method, {k: str(v) for k, v in o.paths.items()}, o.summary, o.quality)
                    for o in outputs)
    agreement = outputs[0].agreement_deg if len(outputs) == 2 else None
    result = TrialResult(str(job.trial), methods, agreement, calibrated, failed=failed,
                         kept=tuple(o.method for o in outputs if o.resumed))
    if job.report:
        report, kept = _report(job, outputs, resumed=len(result.kept) == len(methods), model=session.model)
        result = dataclasses.replace(result, report=report, kept=result.kept + (("report",) if kept else ()))
    return result


def _report(job: TrialJob, outcomes: list[MethodOutcome], /, *, resumed: bool, model=None) -> tuple[dict[str, str], bool]:
    """The trial's report, drawn from the methods' outcomes in memory (exubio.run.outcome.reported), or
    kept when every result set was kept from an earlier run of the same inputs and the report that run
    left is not older than them (exubio.run.resume)."""
    from exubio.run.resume import fresh_report

    pdf, png = job.out_dir / f"{job.trial.stem}.report.pdf", job.out_dir / f"{job.trial.stem}.report.png"
    there = pdf.exists() or png.exists()
    if there and resumed and fresh_report([pdf, png], [o.paths for o in outcomes]):
        return {"pdf": str(pdf), "png": str(png)}, True
    if there and not (job.overwrite or resumed):  # sets computed now beside an earlier run's report
        results.prepare_output_dir(job.out_dir, [pdf.name, png.name], overwrite=False)  # refused, named
    from exubio.report.trial_report import draw_trial_report

    pdf, png = draw_trial_report([reported(o, model=model) for o in outcomes], pdf)
    return {"pdf": str(pdf), "png": str(png)}, False
