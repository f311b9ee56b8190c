"""One trial from file to results: read, preprocess, reconstruct with a method, write the outputs.

The steps are plain functions so that scripts, the CLI and the validation report compose them:
``load_inputs`` -> ``reconstruct`` (or ``stream_reconstruct``) -> ``write_outputs``; ``reconstruct_file`` does
all of it for one trial file, streamed (bounded memory). One trial as a job: exubio.run.job; a
session's calibration: exubio.run.session.
"""
from __future__ import annotations

import enum
import logging
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

import exubio
from exubio.errors import InputError, PartialReconstructionError, ProtocolError, ReconstructionError
from exubio.trust.evaluate import summary
from exubio.io import results
from exubio.io.trial import read_trial
from exubio.model.load import DEFAULT_MODEL, load_model
from exubio.prep.targets import prepare_targets
from exubio.protocol.load import check_landmarks, load_protocol
from exubio.io.resources import shipped_file
from exubio.types import MarkerTargets, Model, Protocol, Reconstruction, Trajectories

log = logging.getLogger(__name__)

DEFAULT_PROTOCOL = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols")


class Method(str, enum.Enum):
    PF = "pf"  # potential field (Exudyn forward dynamics)
    LS = "ls"  # constrained least squares per frame

    @classmethod
    def parse(cls, value: "str | Method") -> "Method":
        try:
            return cls(value)
        except ValueError:
            raise InputError(f"unknown method '{value}'; valid methods are {[m.value for m in cls]}") from None


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
    model: Model
    protocol: Protocol
    targets: MarkerTargets
    dropped: tuple[str, ...] = ()
    partial_swaps: tuple = ()  # labels exchanged in part of the trial (exubio.trust.label_ranges)
    repaired: bool = False  # ... and exchanged back (--repair-labels)


def protocol_for_model(model: Model, protocol_path: str | Path | None = None, /) -> Protocol:
    """Load a protocol against a model; a calibrated model rebinds the markers to the points the
    calibration registered for them."""
    points = {s.name: dict(s.points) for s in model.segments}
    protocol = load_protocol(protocol_path or DEFAULT_PROTOCOL, segments=model.segment_names, model_points=points,
                             coordinates=model.coordinate_names)
    check_landmarks(protocol, points)
    check_held(model, protocol)
    if model.metadata.get("calibration"):
        from exubio.calibration import calibrated_protocol

        protocol = calibrated_protocol(protocol, model)
    return protocol


def check_held(model: Model, protocol: Protocol, /) -> None:
    """Refuse (ProtocolError naming the protocol's ``hold`` key) a hold that leaves the methods
    nothing to solve: every coordinate held, or fewer coordinates free in the chain that moves the
    ellipsoid's contact points than there are contact constraints (they could not be met: a singular
    system in both methods)."""
    held = set(protocol.held_coordinates)
    names = model.coordinate_names
    where = f"{protocol.source or protocol.name}: hold"
    if names and held >= set(names):
        raise ProtocolError(f"{where}: holds every coordinate of the model ({len(names)}); nothing is left for the "
                            f"markers to determine: hold fewer (thoracoscapular_9 holds sc_posterior_rotation only)")
    by_name = {s.name: s for s in model.segments}
    for segment in sorted({seg for seg, _ in model.ellipsoid.contact_points}):
        chain, name = [], segment
        while name in by_name:
            s = by_name[name]
            chain = list(s.joint.coordinates if s.joint else ()) + chain
            name = s.parent
        free = [c for c in chain if c not in held]
        n_constraints = sum(seg == segment for seg, _ in model.ellipsoid.contact_points)
        if chain and len(free) < n_constraints:
            raise ProtocolError(
                f"{where}: leaves {len(free)} of the coordinates that move the {segment} free ({free or 'none'} of "
                f"{chain}); its {n_constraints} points on the thorax ellipsoid need at least {n_constraints}: hold fewer")


def load_model_and_protocol(*, model_path: str | Path | None = None, protocol_path: str | Path | None = None,
                            body_mass_kg: float | None = None) -> tuple[Model, Protocol]:
    model = load_model(model_path or DEFAULT_MODEL, body_mass_kg=body_mass_kg)
    return model, protocol_for_model(model, protocol_path)


def load_inputs(trial_path: str | Path | Trajectories, /, *, model_path: str | Path | None = None,
                protocol_path: str | Path | None = None, body_mass_kg: float | None = None,
                model: Model | None = None, repair_labels: bool = False) -> TrialInputs:
    """Read the trial (or take it, read already), the model and the protocol, check the labels that
    must be right before anything is computed (thorax landmarks, missing markers, labels exchanged
    in part of the trial: repaired with ``repair_labels``), and prepare the marker targets."""
    traj = trial_path if isinstance(trial_path, Trajectories) else read_trial(trial_path)
    if model is None:
        model, protocol = load_model_and_protocol(model_path=model_path, protocol_path=protocol_path,
                                                  body_mass_kg=body_mass_kg)
    else:
        protocol = protocol_for_model(model, protocol_path)
    from exubio.trust.missing_markers import drop_missing_markers
    from exubio.trust.thorax_check import check_thorax_labels

    from exubio.trust.label_ranges import find_partial_swaps, repair_partial_swaps

    protocol, dropped = drop_missing_markers(traj, protocol, model)
    check_thorax_labels(traj, protocol, model)  # before the thorax frame is built from them
    partial = find_partial_swaps(traj, protocol, model)
    if partial and repair_labels:
        traj = repair_partial_swaps(traj, protocol, partial)
    targets = prepare_targets(traj, protocol)
    return TrialInputs(TrialInfo.of(traj), model, protocol, targets, dropped, partial, bool(partial and repair_labels))


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


def stream_reconstruct(model: Model, protocol: Protocol, targets: MarkerTargets, sink: Callable[[Reconstruction], None],
                       /, *, method: Method | str = Method.PF, options: Any = None,
                       progress: Callable[[int], None] | None = None, chunk_frames: int | None = None,
                       **values: Any) -> tuple[dict[str, float], dict[str, Any]]:
    """Run one method handing its result to ``sink`` in chunks (bounded memory on trials of any
    length: exubio.methods.common); returns the method's (timings_s, info)."""
    from exubio.methods import method_spec
    from exubio.methods.common import CHUNK_FRAMES

    spec = method_spec(Method.parse(method).value)
    return spec.load_stream()(model, protocol, targets, sink, options=_options(spec, options, values),
                              progress=progress, chunk_frames=chunk_frames or CHUNK_FRAMES)


def output_stem(trial_path: str | Path, method: Method | str) -> str:
    return f"{Path(trial_path).stem}.{Method.parse(method).value}"


@dataclass(frozen=True)
class AngleOutputs:
    """The anatomical angles of one reconstruction as the files carry them: names
    (exubio.model.angles.ANATOMICAL_COLUMNS), values (n, a) rad, status (n, a) AngleStatus codes, the
    comment lines that describe them (``angle_header``)."""

    names: tuple[str, ...]
    values_rad: np.ndarray
    status: np.ndarray
    comments: tuple[str, ...] = ()


def write_outputs(recon: Reconstruction, out_dir: str | Path, stem: str, /, *,
                  metadata: dict[str, Any], summary_data: dict[str, Any], angles: AngleOutputs,
                  undetermined: np.ndarray | None = None, streamed: dict[str, Any] | None = None,
                  overwrite: bool = True) -> dict[str, Path]:
    """Write <stem>.csv and .mot (the anatomical angles ``angles`` in degrees, each one's status in
    the header), .npz (everything: the model coordinates, ``undetermined`` (n, m) per coordinate and
    the angles' status per frame) and .summary.json into out_dir as one result set, complete or
    absent (exubio.io.results.ResultSet: written in a hidden staging folder, renamed into place,
    summary.json last; without ``overwrite`` no existing file is ever replaced); ``streamed``:
    arrays the reconstruction left on disk (exubio.io.streamed), copied into the .npz."""
    out = Path(out_dir)
    names = {"csv": f"{stem}.csv", "mot": f"{stem}.mot", "npz": f"{stem}.npz", "summary": f"{stem}.summary.json"}
    notes = [f"exubio_{line.split(':', 1)[0].replace(' ', '_')}={line.split(':', 1)[1].strip()}"
             for line in angles.comments if line.startswith("status ")]
    if summary_data.get("quality"):
        notes.append(f"exubio_quality={summary_data['quality']['verdict']}")
    extra = {"angle_status": np.asarray(angles.status, dtype=np.int8), "angle_names": np.array(angles.names)}
    if undetermined is not None:
        extra["undetermined"] = undetermined
    with results.ResultSet(out, stem, overwrite=overwrite) as result_set:
        staged = {kind: result_set.path(name) for kind, name in names.items()}
        results.write_angles_csv(staged["csv"], recon.time_s, [f"{n}_deg" for n in angles.names], angles.values_rad,
                                 comments=angles.comments)
        results.write_mot(staged["mot"], recon.time_s, angles.names, angles.values_rad, name=stem, notes=notes)
        results.write_npz(staged["npz"], recon, metadata=metadata, extra_arrays=extra, streamed=streamed)
        results.write_json(staged["summary"], summary_data)
        placed = result_set.commit(last=names["summary"])
    return {kind: placed[name] for kind, name in names.items()}


def run_metadata(inputs: TrialInputs, trial_path: str | Path, method: Method) -> dict[str, Any]:
    return {
        "exubio_version": exubio.__version__,
        "python": platform.python_version(),
        "trial": str(trial_path),
        "model": inputs.model.source,
        "model_name": inputs.model.name,
        "body_mass_kg": inputs.model.body_mass_kg,
        "protocol": inputs.protocol.source,
        "protocol_name": inputs.protocol.name,
        "held_coordinates": list(inputs.protocol.held_coordinates),
        "protocol_relabel": dict(inputs.protocol.relabel),
        "method": method.value,
        "units": {"angles_in_files": "deg", "positions_in_npz": "m", "time": "s"},
        "ignored_labels": list(inputs.trial.ignored_labels),
        "units_in_trial_file": inputs.trial.units_in_file,
        "rate_hz": inputs.trial.rate_hz,
    }


def reconstruct_file(trial_path: str | Path, out_dir: str | Path, /, *, methods: list[Method | str],
                     trajectories: Trajectories | None = None,
                     model_path: str | Path | None = None, protocol_path: str | Path | None = None,
                     body_mass_kg: float | None = None, overwrite: bool = False, model: Model | None = None,
                     method_options: dict[str, Any] | None = None,
                     summary_extra: dict[str, Any] | None = None,
                     progress_factory: Callable[[str, int], Callable[[int], None]] | None = None,
                     calibration: dict[str, Any] | None = None, static_reference: Any = None,
                     chunk_frames: int | None = None, repair_labels: bool = False
                     ) -> list[tuple[Reconstruction, dict[str, Path], dict[str, Any]]]:
    """Everything ``exubio reconstruct`` does for one trial; returns (reconstruction, paths, summary)
    per method. Every method runs first (one that fails, ReconstructionError, does not stop the
    others: their results are written, then PartialReconstructionError carries them and each failed
    method's reason; its summary says so, ``failed_methods``); then the trial is assessed (label checks, determinacy,
    range limits, PF-LS agreement, ``calibration``: the calibration report dict) and every summary
    carries its quality verdict. Refuses (InputError) to replace earlier results unless
    ``overwrite``. ``trajectories``: the trial ``trial_path`` already read. Bounded memory: each method streams its result in chunks of ``chunk_frames``
    (exubio.io.streamed), the model points going to disk as they come; the reconstructions
    returned hold no model points (``model_points_m`` None: they are in the .npz)."""
    from contextlib import ExitStack

    from exubio.io.streamed import StreamedReconstruction

    methods = [Method.parse(m) for m in methods]
    stems = [output_stem(trial_path, m) for m in methods]
    results.writable_folder(out_dir)
    with ExitStack() as parts:  # the locks, and the streamed model points' part files, go whatever happens
        parts.enter_context(results.claim(out_dir, stems))  # no other run writes these results meanwhile
        results.prepare_output_dir(out_dir, stems, overwrite=overwrite)
        inputs = load_inputs(trajectories if trajectories is not None else trial_path, model_path=model_path,
                             protocol_path=protocol_path, body_mass_kg=body_mass_kg, model=model,
                             repair_labels=repair_labels)
        return _reconstruct_streamed(inputs, trial_path, out_dir, methods, stems, parts, StreamedReconstruction,
                                     method_options=method_options, summary_extra=summary_extra,
                                     progress_factory=progress_factory, calibration=calibration,
                                     static_reference=static_reference, chunk_frames=chunk_frames,
                                     overwrite=overwrite)


def _reconstruct_streamed(inputs: TrialInputs, trial_path, out_dir, methods, stems, parts, sink_type, /, *,
                          method_options, summary_extra, progress_factory, calibration, static_reference,
                          chunk_frames, overwrite) -> list[tuple[Reconstruction, dict[str, Path], dict[str, Any]]]:
    from exubio.trust.assess import assess_trial, trial_label_findings

    recons, sinks, done, failures = [], [], [], {}
    for method, stem in zip(methods, stems):
        progress = progress_factory(method.value, inputs.targets.n_frames) if progress_factory else None
        opts = (method_options or {}).get(method.value)  # the options object, or a dict of its fields
        values = opts if isinstance(opts, dict) else {}
        sink = parts.enter_context(sink_type(out_dir, stem, inputs.targets, inputs.model.coordinate_names))
        try:
            timings, info = stream_reconstruct(inputs.model, inputs.protocol, inputs.targets, sink, method=method,
                                               options=None if isinstance(opts, dict) else opts, progress=progress,
                                               chunk_frames=chunk_frames, **values)
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
    methods, stems = [m for m, _ in done], [s for _, s in done]
    findings = trial_label_findings(inputs.model, inputs.protocol, inputs.targets, reference=static_reference)
    session = ()
    if static_reference is not None:  # does the static belong to this trial's session?
        from exubio.trust.labels import pair_distances
        from exubio.trust.session_check import placed_anew, static_consistency

        trial_pd = pair_distances(inputs.targets.positions_m, inputs.targets.marker_names)
        session = tuple(placed_anew(static_consistency(static_reference, trial_pd, inputs.protocol)))
    assessment = assess_trial(inputs.model, inputs.protocol, inputs.targets, recons, label_findings=findings,
                              calibration=calibration, session=session, dropped=inputs.dropped,
                              partial_swaps=inputs.partial_swaps, repaired=inputs.repaired,
                              static_name=getattr(static_reference, "source", "") or "")
    out = write_assessed(inputs, trial_path, out_dir, methods, stems, recons, assessment, summary_extra=summary_extra,
                         model_points=[sink.model_points for sink in sinks], failures=failures, overwrite=overwrite)
    if failures:
        raise PartialReconstructionError(
            "; ".join(f"{m.upper()} failed: {reason}" for m, reason in failures.items())
            + f" ({', '.join(r.method.upper() for r, _, _ in out)} written)", outputs=out, failures=failures)
    return out


def write_assessed(inputs: TrialInputs, trial_path: str | Path, out_dir: str | Path, methods: list[Method],
                   stems: list[str], recons: list[Reconstruction], assessment: Any, /, *,
                   summary_extra: dict[str, Any] | None = None, model_points: list[Any] | None = None,
                   failures: dict[str, str] | None = None,
                   overwrite: bool = True) -> list[tuple[Reconstruction, dict[str, Path], dict[str, Any]]]:
    """Write every method's result set (write_outputs: the anatomical angles with their status, the
    assessment's verdict in summary.json); ``model_points``: per method, the streamed model points
    (exubio.io.streamed) when the reconstructions do not hold them; ``failures``: the methods of the
    run that failed, named in each summary. Returns (reconstruction, paths, summary) per method."""
    from exubio.model.angles import ANATOMICAL_ANGLES, anatomical_table

    failures = failures or {}
    out = []
    for i, (method, stem, recon) in enumerate(zip(methods, stems, recons)):
        meta = run_metadata(inputs, trial_path, method)
        extra = {"unused_trial_labels": _unused(inputs), **(summary_extra or {})}
        if isinstance(extra.get("calibration"), dict):  # private entries (the static's distances) stay out
            extra["calibration"] = {k: v for k, v in extra["calibration"].items() if not k.startswith("_")}
        if "mean_spring_deflection_mm" in recon.info:
            extra["mean_spring_deflection_mm"] = recon.info["mean_spring_deflection_mm"]
        if inputs.targets.cutoff_hz:
            extra["filter_cutoff_hz"] = dict(inputs.targets.cutoff_hz)
        extra.update(assessment.summary_for(recon.method))
        cal = extra.get("calibration") if isinstance(extra.get("calibration"), dict) else {}
        file_findings = tuple(dict.fromkeys(tuple(inputs.trial.input_findings) + tuple(
            f"static trial: {f}" for f in cal.get("input_findings") or () if f not in inputs.trial.input_findings)))
        if file_findings:
            extra["input_findings"] = list(file_findings)
            extra["quality"] = with_input_findings(extra["quality"], file_findings)
        if failures:
            extra["failed_methods"] = dict(failures)
            extra["quality"] = with_failed_methods(extra["quality"], failures)
        names, values = anatomical_table(inputs.model, recon.q_rad)
        det = assessment.angles[recon.method]
        extra["angles"] = {"files": [f"{stem}.csv", f"{stem}.mot"], "units": "deg", "side": inputs.protocol.side,
                           "definitions": {n: {"definition": d, "meaning": m} for n, d, m in ANATOMICAL_ANGLES}}
        summ = summary(recon, source=str(trial_path), extra=extra)
        angles = AngleOutputs(names, values, det.status,
                              angle_header(det, Path(trial_path).name, method.value, inputs.protocol.side))
        paths = write_outputs(recon, out_dir, stem, metadata=meta, summary_data=summ, angles=angles,
                              undetermined=assessment.determinacy[recon.method].undetermined,
                              streamed=None if model_points is None else {"model_points_m": model_points[i]},
                              overwrite=overwrite)
        out.append((recon, paths, summ))
    return out


def with_input_findings(quality: dict[str, Any], findings: tuple[str, ...], /) -> dict[str, Any]:
    """A summary's ``quality`` with a note per input finding (what the reader read around: the file is
    named, the result stands: exubio.trust.quality's "note" level, which leaves the verdict as it is)."""
    from exubio.trust.quality import Reason

    notes = [Reason("input_file", "note", f"input file: {f}").to_dict() for f in findings]
    return {**quality, "reasons": list(quality["reasons"]) + notes}


def with_failed_methods(quality: dict[str, Any], failures: dict[str, str], /) -> dict[str, Any]:
    """A summary's ``quality`` with a note per method of the run that failed (this result stands
    on its own: no PF-LS agreement was measured)."""
    from exubio.trust.quality import Reason

    notes = [Reason("method_failed", "note", f"{m.upper()} failed on this trial, so this result is not compared with it "
                    f"(no PF-LS agreement): {reason}").to_dict() for m, reason in failures.items()]
    return {**quality, "reasons": list(quality["reasons"]) + notes}


MAX_STATUS_RUNS = 12
"""An angle whose status changes more often than this is summarised by shares in the file headers
(its every frame is in the .npz)."""


def angle_header(det, trial: str, method: str, side: str) -> tuple[str, ...]:
    """Comment lines of ``<trial>.<method>.csv``: what the angles are (definition, sign), and each
    one's status (exubio.trust.observability.AngleStatus) with the frame ranges where it changes."""
    from exubio.model.angles import ANATOMICAL_ANGLES
    from exubio.trust.observability import AngleStatus

    lines = [f"exubio anatomical joint angles of {trial} ({method.upper()}); angles in degrees, time in seconds",
             "ISB frames (Wu et al. 2005) from the model's landmarks, intrinsic sequences, raw signs; GH in ISB Y-X'-Y'' "
             "and in Phadke's X-Z'-Y''"]
    lines += [f"{n}: {d}; {m}" for n, d, m in ANATOMICAL_ANGLES]
    if side == "left":
        lines.append("LEFT arm: its markers were mirrored through the thorax's sagittal plane (Z -> -Z of the ISB thorax "
                     "frame) onto the right-arm model, so every angle carries the right arm's sign (Wu et al. 2005)")
    else:
        lines.append("right arm, signs of Wu et al. 2005")
    lines.append("status: measured = the markers determine it; modelled = set by a named protocol rule; not measured = "
                 "neither (read it as no measurement)")
    for j, n in enumerate(det.names):
        col = np.asarray(det.status[:, j])
        rule = f" ({det.rule[n]})" if n in det.rule else ""
        change = np.flatnonzero(np.diff(col)) + 1
        if not change.size:
            lines.append(f"status {n}: {AngleStatus(int(col[0])).label if col.size else 'measured'}{rule}")
            continue
        if change.size > MAX_STATUS_RUNS:
            share = ", ".join(f"{AngleStatus(k).label} {100 * np.mean(col == k):.0f} %" for k in np.unique(col))
            lines.append(f"status {n}: changes {change.size} times: {share} of the frames (every frame: the .npz, "
                         f"angle_status){rule}")
            continue
        starts = np.concatenate([[0], change])
        ends = np.concatenate([change, [col.size]])
        runs = ", ".join(f"{AngleStatus(int(col[a])).label} {a}-{b - 1}" for a, b in zip(starts, ends))
        lines.append(f"status {n}: by frame: {runs}{rule}")
    return tuple(lines)


def _unused(inputs: TrialInputs) -> list[str]:
    from exubio.protocol.labels import resolve_labels

    match = resolve_labels(inputs.protocol, inputs.trial.labels, source=inputs.trial.source)
    return list(match.unused) + list(inputs.trial.ignored_labels)


def agreement_deg(a: Reconstruction, b: Reconstruction, /) -> dict[str, float]:
    """RMSE (deg) per coordinate between two reconstructions of the same trial."""
    d = np.rad2deg(a.q_rad - b.q_rad)
    return {n: float(v) for n, v in zip(a.coordinate_names, np.sqrt(np.mean(d**2, axis=0)))}
