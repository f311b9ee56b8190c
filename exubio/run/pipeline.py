"""One trial from file to results: read, preprocess, reconstruct with a method, write the outputs.

The steps are plain functions so that scripts, the CLI and the validation report compose them:
``load_inputs`` -> ``reconstruct`` (or ``stream_reconstruct``) -> ``write_outputs``; ``reconstruct_file`` does
all of it for one trial file, streamed (bounded memory). One trial as a job: exubio.run.job; a
session's calibration: exubio.run.session.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping


from exubio.errors import InputError, PartialReconstructionError, ReconstructionError
from exubio.io import results
from exubio.io.result_names import stem_of
from exubio.io.trial import read_trial
from exubio.prep.targets import preparation_key, prepare_targets
from exubio.protocol.bind import Binding
from exubio.run.inputs import Session, load_session
from exubio.run.outcome import MethodOutcome, run_metadata, write_outcome  # noqa: F401 - run_metadata re-exported
from exubio.run.summary_file import RunNotes, trial_quality
from exubio.run.trial_files import AngleOutputs, angle_header, mot_thorax, write_outputs  # noqa: F401 - re-exported
from exubio.types import MarkerTargets, Method, Model, Protocol, Reconstruction, Trajectories

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class TrialInfo:
    """What the outputs say of the trial file once its markers are prepared (its raw positions are
    not kept: on a long trial they are as large as the targets)."""

    source: str
    labels: tuple[str, ...]
    ignored_labels: tuple[str, ...]
    units_in_file: str
    rate_hz: float
    input_findings: tuple[str, ...] = ()  # what the reader read around (Trajectories.input_findings)

    @classmethod
    def of(cls, traj: Trajectories) -> "TrialInfo":
        return cls(traj.source, traj.labels, traj.ignored_labels, traj.units_in_file, traj.rate_hz,
                   traj.input_findings)


@dataclass(frozen=True)
class TrialInputs:
    """A trial ready to reconstruct; ``dropped``: protocol markers the trial lacks, left out because
    the others still measure every angle (exubio.trust.missing_markers); ``partial_swaps``: labels exchanged
in part of the trial, ``repaired``: exchanged back before preparing (``--repair-labels``)."""

    trial: TrialInfo
    binding: Binding  # the model and protocol (the session's, or rebound without the dropped markers)
    targets: MarkerTargets
    dropped: tuple[str, ...] = ()
    partial_swaps: tuple = ()  # labels exchanged in part of the trial (exubio.trust.label_ranges)
    repaired: bool = False  # ... and exchanged back (--repair-labels)
    expect: Binding | None = None  # what the label checks expect (exubio.run.inputs.Session.generic_binding)
    moment_inputs: Any = None  # the thorax's motion and the loads (exubio.prep.moment_inputs.MomentInputs)

    @property
    def model(self) -> Model:
        return self.binding.model

    @property
    def protocol(self) -> Protocol:
        return self.binding.protocol

    @property
    def generic_binding(self) -> Binding:
        return self.expect if self.expect is not None else self.binding


@dataclass(frozen=True)
class Prepared:
    """Targets a trial was already prepared into, with the preparation_key of the protocol used
    (the calibration's, when a trial is calibrated on its own frames): reused when the trial's
    protocol prepares it the same way."""

    key: tuple
    targets: MarkerTargets


@dataclass(frozen=True)
class RunSettings:
    """How the trials of a run are run: per method its options object (or a dict of its fields),
    ``overwrite`` earlier results, the chunk size of the streamed result (frames), ``repair_labels``
    (exchange back labels exchanged in part of a trial), ``progress_factory`` (method, frames) ->
    a callback told the frames done."""

    method_options: Mapping[str, Any] = field(default_factory=dict)
    overwrite: bool = False
    chunk_frames: int | None = None
    repair_labels: bool = False
    progress_factory: Callable[[str, int], Callable[[int], None]] | None = None  # per method: a progress callback
    hand_load_kg: float | None = None  # joint moments (exubio.dynamics) with this mass in the hand; None: none
    moment_request: Any = None  # their lab vertical and loads files (exubio.prep.moment_inputs.MomentRequest)


def load_inputs(trial: str | Path | Trajectories, session: Session | None = None, /, *, repair_labels: bool = False,
                prepared: Prepared | None = None, moment_request: Any = None) -> TrialInputs:
    """Read the trial (or take it, read already), check the labels that must be right before
    anything is computed (thorax landmarks, missing markers, labels exchanged in part of the trial:
    repaired with ``repair_labels``), and prepare the marker targets (or take ``prepared``, when
    the protocol prepares the trial the same way). ``session``: default the shipped model and
    protocol (exubio.run.inputs.load_session); ``moment_request`` (exubio.prep.moment_inputs.MomentRequest):
    also the thorax's motion in the lab and the external loads of the joint moments."""
    from exubio.trust.label_ranges import find_partial_swaps, repair_partial_swaps
    from exubio.trust.missing_markers import drop_missing_markers
    from exubio.trust.thorax_check import check_thorax_labels

    traj = trial if isinstance(trial, Trajectories) else read_trial(trial)
    session = session if session is not None else load_session()
    model = session.model
    binding, dropped = drop_missing_markers(traj, session.binding)
    protocol = binding.protocol
    check_thorax_labels(traj, protocol, model)  # before the thorax frame is built from them
    partial = find_partial_swaps(traj, protocol, model)
    repaired = bool(partial and repair_labels)
    if repaired:
        traj = repair_partial_swaps(traj, protocol, partial)
    if prepared is not None and not repaired and prepared.key == preparation_key(protocol):
        targets = prepared.targets
    else:
        targets = prepare_targets(traj, protocol)
    extra = None
    if moment_request is not None:
        from exubio.prep.moment_inputs import moment_inputs

        extra = moment_inputs(traj, protocol, targets, model, moment_request)
    return TrialInputs(TrialInfo.of(traj), binding, targets, dropped, partial, repaired, session.generic_binding, extra)


def reconstruct(model: Model, protocol: Protocol, targets: MarkerTargets, /, *, method: Method | str = Method.PF,
                options: Any = None, progress: Callable[[int], None] | None = None, **values: Any) -> Reconstruction:
    """Run one method on loaded objects: ``options`` is the method's options object (PFOptions,
    LSOptions: exubio.methods.REGISTRY), or give its fields as keywords (e.g. step_s=0.005)."""
    from exubio.methods import method_spec

    spec = method_spec(Method.parse(method).value)  # exubio.methods.REGISTRY
    _, run = spec.load()
    return run(model, protocol, targets, options=_options(spec, options, values), progress=progress)


def _options(spec: Any, options: Any, values: dict[str, Any]) -> Any:
    if options is not None and values:
        raise InputError(f"method {spec.name}: give an options object or option keywords, not both")
    return spec.make_options(options if options is not None else values)


def stream_reconstruct(binding: Binding, targets: MarkerTargets, sink: Callable[[Reconstruction], None],
                       /, *, method: Method | str = Method.PF, options: Any = None,
                       progress: Callable[[int], None] | None = None,
                       chunk_frames: int | None = None) -> tuple[dict[str, float], dict[str, Any]]:
    """Run one method with ``binding`` (the model and protocol: exubio.protocol.bind) handing its result
    to ``sink`` in chunks (bounded memory on trials of any length: exubio.methods.common); ``options``: the method's options object or a dict of its
    fields (exubio.methods.REGISTRY); returns the method's (timings_s, info)."""
    from exubio.methods import method_spec
    from exubio.methods.common import CHUNK_FRAMES

    spec = method_spec(Method.parse(method).value)
    return spec.load_stream()(binding, targets, sink, options=spec.make_options(options),
                              progress=progress, chunk_frames=chunk_frames or CHUNK_FRAMES)


def _moments_key(key: str | None, body_mass_kg: float, hand_load_kg: float | None, request: Any = None) -> str | None:
    """A run's fingerprint (exubio.run.resume.run_key) that also holds the joint moments' body mass
    and hand load when it writes them, the lab vertical and the loads files' contents, so an earlier set
    without them (or with others) is not kept."""
    if key is None or hand_load_kg is None:
        return key
    import hashlib

    loads = []
    for path in () if request is None else request.loads:  # a file's content, not only its name
        p = Path(path)
        loads.append(hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else str(p))
    lab_up = "auto" if request is None else request.lab_up
    what = (key, "moments", float(body_mass_kg), float(hand_load_kg), "thorax motion and loads", lab_up, tuple(loads))
    return hashlib.sha256(repr(what).encode()).hexdigest()


def _request(settings: RunSettings) -> Any:
    """What the joint moments need prepared with the trial (None: no moments)."""
    if settings.hand_load_kg is None:
        return None
    from exubio.prep.moment_options import MomentRequest

    return settings.moment_request if settings.moment_request is not None else MomentRequest()


def reconstruct_file(trial_path: str | Path, out_dir: str | Path, /, *, methods: list[Method | str],
                     session: Session | None = None, settings: RunSettings = RunSettings(),
                     trajectories: Trajectories | None = None, calibration: Any = None, prepared: Prepared | None = None
                     ) -> list[MethodOutcome]:
    """Everything ``exubio reconstruct`` does for one trial; returns each method's outcome
    (exubio.run.outcome.MethodOutcome: reconstruction, assessment, angles, files, summary). Every method runs first (one that fails, ReconstructionError, does not stop the
    others: their results are written, then PartialReconstructionError carries them and each failed
    method's reason; its summary says so, ``failed_methods``); then the trial is assessed (label
    checks, determinacy, range limits, PF-LS agreement, ``calibration``: the session's
    exubio.run.session.SessionCalibration) and every summary carries its quality verdict. Refuses
    (InputError) to replace earlier results unless ``settings.overwrite``. ``session``: the model
    and protocol (default: the shipped ones); ``trajectories``: the trial ``trial_path`` already
    read; ``prepared``: its targets already prepared (load_inputs). Bounded memory: each method
    streams its result in chunks (exubio.io.streamed), the model points going to disk as they come;
    the reconstructions returned hold no model points (``model_points_m`` None: they are in the .npz)."""
    from contextlib import ExitStack

    from exubio.io.streamed import StreamedReconstruction

    from exubio.run.resume import kept_set, run_key

    methods = [Method.parse(m) for m in methods]
    stems = [stem_of(trial_path, m.value) for m in methods]
    results.writable_folder(out_dir)
    session = session if session is not None else load_session()
    labels = trajectories.labels if trajectories is not None else ()
    keys = {s: _moments_key(run_key(trial_path, session.model, session.protocol, m.value, labels=labels,
                                    options=settings.method_options.get(m.value), repair_labels=settings.repair_labels),
                            session.model.body_mass_kg, settings.hand_load_kg, settings.moment_request)
            for m, s in zip(methods, stems)}
    with ExitStack() as parts:  # the locks, and the streamed model points' part files, go whatever happens
        parts.enter_context(results.claim(out_dir, stems))  # no other run writes these results meanwhile
        results.remove_leftovers(Path(out_dir), stems)  # a killed run's set is finished from its journal first
        kept = {} if settings.overwrite else {s: k for s in stems if (k := kept_set(out_dir, s, keys[s])) is not None}
        if len(kept) == len(stems):  # an earlier run of the same inputs completed them all: resumed
            log.info("kept the complete result sets of an earlier run of the same inputs: %s", ", ".join(stems))
            return [kept[s] for s in stems]
        results.prepare_output_dir(out_dir, [s for s in stems if s not in kept], overwrite=settings.overwrite)
        run = _Run(load_inputs(trajectories if trajectories is not None else trial_path, session,
                               repair_labels=settings.repair_labels, prepared=prepared,
                               moment_request=_request(settings)), Path(trial_path), Path(out_dir), settings, calibration,
                   keys, kept)  # the run alone holds the inputs: their rates go once the methods are done
        return run.reconstruct(methods, stems, parts, StreamedReconstruction)


@dataclass(frozen=True)
class _Run:
    """One trial's run after its inputs are prepared: the methods, the assessment, the files."""

    inputs: TrialInputs
    trial_path: Path
    out_dir: Path
    settings: RunSettings
    calibration: Any
    keys: Mapping[str, str | None] = field(default_factory=dict)  # stem -> its inputs' fingerprint (resume.run_key)
    kept: Mapping[str, tuple] = field(default_factory=dict)  # stem -> a complete set of an earlier run, kept

    def reconstruct(self, methods, stems, parts, sink_type) -> list[MethodOutcome]:
        inputs, out_dir = self.inputs, self.out_dir
        recons, sinks, done, failures = [], [], [], {}
        for method, stem in zip(methods, stems):
            factory = self.settings.progress_factory
            progress = factory(method.value, inputs.targets.n_frames) if factory else None
            sink = parts.enter_context(sink_type(out_dir, stem, inputs.targets, inputs.model.coordinate_names))
            try:
                timings, info = stream_reconstruct(inputs.binding, inputs.targets, sink, method=method,
                                                   options=self.settings.method_options.get(method.value),
                                                   progress=progress, chunk_frames=self.settings.chunk_frames)
            except ReconstructionError as exc:  # the other methods still give their results
                if len(methods) == 1:
                    raise
                failures[method.value] = str(exc)
                log.warning("%s failed: %s", method.value.upper(), exc)
                sink.discard()
                continue
            recons.append(sink.reconstruction(timings_s=timings, info=info))
            sinks.append(sink)
            done.append((method, stem))
        if not recons:
            raise ReconstructionError("; ".join(f"{m.upper()}: {reason}" for m, reason in failures.items()))
        from exubio.io.streamed import without_rates  # the methods are done: the rest reads the positions

        # (the one field of this frozen run replaced, so that nothing holds the rates from here on)
        object.__setattr__(self, "inputs", dataclasses.replace(inputs, targets=without_rates(inputs.targets)))
        inputs = self.inputs
        assessment = self.assess(recons)
        out = []
        for (method, stem), recon, sink in zip(done, recons, sinks):
            if stem in self.kept:
                out.append(self.kept[stem])
                continue
            notes = RunNotes(self.calibration, failures=failures, inputs_sha256=self.keys.get(stem))
            out += write_assessed(inputs, self.trial_path, out_dir, [(method, stem, recon, sink.model_points)],
                                  assessment, notes=notes, overwrite=self.settings.overwrite,
                                  hand_load_kg=self.settings.hand_load_kg)
        if failures:
            raise PartialReconstructionError(
                "; ".join(f"{m.upper()} failed: {reason}" for m, reason in failures.items())
                + f" ({', '.join(o.method.upper() for o in out)} written)", outputs=out, failures=failures)
        return out

    def assess(self, recons: list[Reconstruction]):
        return assess_inputs(self.inputs, recons, self.calibration)


def assess_inputs(inputs: TrialInputs, recons: list[Reconstruction], calibration: Any = None, /):
    """The trial's assessment (exubio.trust.assess.TrialAssessment) as ``exubio reconstruct`` makes
    it: the label checks against the generic model (and, with the session's ``calibration``,
    against its static trial), then determinacy, limits, agreement and the verdicts."""
    from exubio.trust.assess import TrialContext, assess_trial, trial_label_findings

    reference = calibration.reference if calibration is not None else None
    findings = trial_label_findings(inputs.generic_binding, inputs.targets, reference=reference)
    session = ()
    if reference is not None:  # does the static belong to this trial's session?
        from exubio.trust.labels import pair_distances
        from exubio.trust.session_check import placed_anew, static_consistency

        trial_pd = pair_distances(inputs.targets.positions_m, inputs.targets.marker_names)
        session = tuple(placed_anew(static_consistency(reference, trial_pd, inputs.protocol)))
    context = TrialContext(
        label_findings=tuple(findings), calibration=None if calibration is None else calibration.report,
        static_labels=() if calibration is None or calibration.reference is None else tuple(calibration.labels),
        session=session, static_name=getattr(reference, "source", "") or "", dropped=inputs.dropped,
        partial_swaps=inputs.partial_swaps, repaired=inputs.repaired)
    return assess_trial(inputs.binding, inputs.targets, recons, context=context)


def write_assessed(inputs: TrialInputs, trial_path: str | Path, out_dir: str | Path, done: list[tuple], assessment: Any,
                   /, *, notes: Any = None, overwrite: bool = True, hand_load_kg: float | None = None
                   ) -> list[MethodOutcome]:
    """Write every method's result set: its outcome (exubio.run.outcome.MethodOutcome: the verdict with
    the run's notes, the anatomical angles with their status, with ``hand_load_kg`` not None the joint
    moments (exubio.dynamics)), written by exubio.run.outcome.write_outcome, which makes its
    summary.json; ``done``: per method (Method, stem, reconstruction, its streamed model points
    (exubio.io.streamed) or None when the reconstruction holds them); ``notes``: the run's
    calibration, live figures and failed methods (exubio.run.summary_file.RunNotes). Returns the
    outcome of each method, with its files and summary."""
    from exubio.model.angles import anatomical_table

    notes = notes or RunNotes()
    out = []
    for method, stem, recon, model_points in done:
        quality = trial_quality(assessment, recon.method, inputs, notes)
        recon = dataclasses.replace(recon, quality=quality)  # the verdict travels typed, as the file gives it
        moments = None
        if hand_load_kg is not None:
            from exubio.dynamics.moments import reconstruction_moments

            extra = inputs.moment_inputs
            moments = reconstruction_moments(inputs.model, recon, hand_load_kg=hand_load_kg,
                                             thorax=None if extra is None else extra.thorax,
                                             loads=() if extra is None else extra.loads)
        names, values = anatomical_table(inputs.model, recon.q_rad, kinematics=inputs.binding.kin)
        det = assessment.angles[recon.method]
        signs = inputs.protocol.signs
        angles = AngleOutputs(names, values, det.status,
                              angle_header(det, Path(trial_path).name, method.value, inputs.protocol.side, signs),
                              assessment.determinacy[recon.method].undetermined, det.uncertainty_rad, moments,
                              thorax_coordinates=mot_thorax(moments), signs=signs)
        outcome = MethodOutcome(method.value, stem, recon, assessment, angles)
        out.append(write_outcome(outcome, inputs, trial_path, out_dir, notes=notes, overwrite=overwrite,
                                 streamed=None if model_points is None else {"model_points_m": model_points}))
    return out
