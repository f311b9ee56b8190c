"""One trial from file to results: read, preprocess, reconstruct with a method, write the outputs.

The steps are plain functions so that scripts, the CLI and the validation report compose them:
``load_inputs`` -> ``reconstruct`` (or ``stream_reconstruct``) -> ``write_outputs``; ``reconstruct_file`` does
all of it for one trial file, streamed (bounded memory). One trial as a job: exubio.jobs; a
session's calibration: exubio.session.
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
from exubio.errors import InputError
from exubio.evaluate import summary
from exubio.io import results
from exubio.io.trial import read_trial
from exubio.model import DEFAULT_MODEL, load_model
from exubio.preprocess import prepare_targets
from exubio.protocol import check_landmarks, load_protocol
from exubio.resources import shipped_file
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

    @classmethod
    def of(cls, traj: Trajectories) -> "TrialInfo":
        return cls(traj.source, traj.labels, traj.ignored_labels, traj.units_in_file, traj.rate_hz)


@dataclass(frozen=True)
class TrialInputs:
    trial: TrialInfo
    model: Model
    protocol: Protocol
    targets: MarkerTargets


def protocol_for_model(model: Model, protocol_path: str | Path | None = None, /) -> Protocol:
    """Load a protocol against a model; a calibrated model rebinds the markers to the points the
    calibration registered for them."""
    points = {s.name: dict(s.points) for s in model.segments}
    protocol = load_protocol(protocol_path or DEFAULT_PROTOCOL, segments=model.segment_names, model_points=points,
                             coordinates=model.coordinate_names)
    check_landmarks(protocol, points)
    if model.metadata.get("calibration"):
        from exubio.calibration import calibrated_protocol

        protocol = calibrated_protocol(protocol, model)
    return protocol


def load_model_and_protocol(*, model_path: str | Path | None = None, protocol_path: str | Path | None = None,
                            body_mass_kg: float | None = None) -> tuple[Model, Protocol]:
    model = load_model(model_path or DEFAULT_MODEL, body_mass_kg=body_mass_kg)
    return model, protocol_for_model(model, protocol_path)


def load_inputs(trial_path: str | Path | Trajectories, /, *, model_path: str | Path | None = None,
                protocol_path: str | Path | None = None, body_mass_kg: float | None = None,
                model: Model | None = None) -> TrialInputs:
    """Read the trial (or take it, read already), the model and the protocol, and prepare the
    marker targets."""
    traj = trial_path if isinstance(trial_path, Trajectories) else read_trial(trial_path)
    if model is None:
        model, protocol = load_model_and_protocol(model_path=model_path, protocol_path=protocol_path,
                                                  body_mass_kg=body_mass_kg)
    else:
        protocol = protocol_for_model(model, protocol_path)
    targets = prepare_targets(traj, protocol)
    return TrialInputs(TrialInfo.of(traj), model, protocol, targets)


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


def write_outputs(recon: Reconstruction, out_dir: str | Path, stem: str, /, *,
                  metadata: dict[str, Any], summary_data: dict[str, Any],
                  undetermined: np.ndarray | None = None,
                  isb: tuple[tuple[str, ...], np.ndarray] | None = None,
                  isb_comments: tuple[str, ...] = (), streamed: dict[str, Any] | None = None) -> dict[str, Path]:
    """Write <stem>.csv, .mot, .npz and .summary.json into out_dir, each atomically, and with
    ``isb`` (column names, angles (n, 15) rad) the ISB angles as <stem>.isb.csv (degrees). Coordinates
    that are not measurements (held, locked, undetermined for the trial) are named in the .mot
    header and summary.json; ``undetermined`` (n, m) per frame goes into the .npz; ``streamed``:
    arrays the reconstruction left on disk (exubio.io.streamed), copied into the .npz."""
    out = Path(out_dir)
    paths = {
        "csv": out / f"{stem}.csv",
        "mot": out / f"{stem}.mot",
        "npz": out / f"{stem}.npz",
        "summary": out / f"{stem}.summary.json",
    }
    notes = []
    not_measured = summary_data.get("not_measured") or []
    undet = (summary_data.get("determinacy") or {}).get("undetermined_for_trial") or []
    if not_measured:
        notes.append("exubio_not_measured=" + ",".join(not_measured) + " (held or locked: not solved from markers)")
    if undet:
        notes.append("exubio_undetermined=" + ",".join(undet) + " (the markers do not determine them; see summary.json)")
    if summary_data.get("quality"):
        notes.append(f"exubio_quality={summary_data['quality']['verdict']}")
    results.write_angles_csv(paths["csv"], recon.time_s, recon.coordinate_names, recon.q_rad)
    if isb is not None:
        paths["isb"] = out / f"{stem}.isb.csv"
        results.write_angles_csv(paths["isb"], recon.time_s, isb[0], isb[1], comments=isb_comments)
    results.write_mot(paths["mot"], recon.time_s, recon.coordinate_names, recon.q_rad, name=stem, notes=notes)
    results.write_npz(paths["npz"], recon, metadata=metadata,
                      extra_arrays=None if undetermined is None else {"undetermined": undetermined}, streamed=streamed)
    results.write_json(paths["summary"], summary_data)
    return paths


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
                     chunk_frames: int | None = None) -> list[tuple[Reconstruction, dict[str, Path], dict[str, Any]]]:
    """Everything ``exubio reconstruct`` does for one trial; returns (reconstruction, paths, summary)
    per method. Every method runs first; then the trial is assessed (label checks, determinacy,
    range limits, PF-LS agreement, ``calibration``: the calibration report dict) and every summary
    carries its quality verdict. Refuses (InputError) to replace earlier results unless
    ``overwrite``. ``trajectories``: the trial ``trial_path`` already read. Bounded memory: each method streams its result in chunks of ``chunk_frames``
    (exubio.io.streamed), the model points going to disk as they come; the reconstructions
    returned hold no model points (``model_points_m`` None: they are in the .npz)."""
    from contextlib import ExitStack

    from exubio.io.streamed import StreamedReconstruction

    methods = [Method.parse(m) for m in methods]
    stems = [output_stem(trial_path, m) for m in methods]
    results.prepare_output_dir(out_dir, stems, overwrite=overwrite)
    inputs = load_inputs(trajectories if trajectories is not None else trial_path, model_path=model_path,
                         protocol_path=protocol_path, body_mass_kg=body_mass_kg, model=model)
    with ExitStack() as parts:  # the streamed model points' part files go, whatever happens
        return _reconstruct_streamed(inputs, trial_path, out_dir, methods, stems, parts, StreamedReconstruction,
                                     method_options=method_options, summary_extra=summary_extra,
                                     progress_factory=progress_factory, calibration=calibration,
                                     static_reference=static_reference, chunk_frames=chunk_frames)


def _reconstruct_streamed(inputs: TrialInputs, trial_path, out_dir, methods, stems, parts, sink_type, /, *,
                          method_options, summary_extra, progress_factory, calibration, static_reference,
                          chunk_frames) -> list[tuple[Reconstruction, dict[str, Path], dict[str, Any]]]:
    from exubio.assess import assess_trial, trial_label_findings

    recons, sinks = [], []
    for method, stem in zip(methods, stems):
        progress = progress_factory(method.value, inputs.targets.n_frames) if progress_factory else None
        opts = (method_options or {}).get(method.value)  # the options object, or a dict of its fields
        values = opts if isinstance(opts, dict) else {}
        sink = parts.enter_context(sink_type(out_dir, stem, inputs.targets, inputs.model.coordinate_names))
        timings, info = stream_reconstruct(inputs.model, inputs.protocol, inputs.targets, sink, method=method,
                                           options=None if isinstance(opts, dict) else opts, progress=progress,
                                           chunk_frames=chunk_frames, **values)
        recons.append(sink.reconstruction(timings_s=timings, info=info))
        sinks.append(sink)
    findings = trial_label_findings(inputs.model, inputs.protocol, inputs.targets, reference=static_reference)
    assessment = assess_trial(inputs.model, inputs.protocol, inputs.targets, recons, label_findings=findings,
                              calibration=calibration)
    return write_assessed(inputs, trial_path, out_dir, methods, stems, recons, assessment, summary_extra=summary_extra,
                          model_points=[sink.model_points for sink in sinks])


def write_assessed(inputs: TrialInputs, trial_path: str | Path, out_dir: str | Path, methods: list[Method],
                   stems: list[str], recons: list[Reconstruction], assessment: Any, /, *,
                   summary_extra: dict[str, Any] | None = None,
                   model_points: list[Any] | None = None) -> list[tuple[Reconstruction, dict[str, Path], dict[str, Any]]]:
    """Write every method's result files (exubio.pipeline.write_outputs, with the ISB angles and the
    assessment's verdict in summary.json); ``model_points``: per method, the streamed model points
    (exubio.io.streamed) when the reconstructions do not hold them. Returns (reconstruction, paths,
    summary) per method."""
    from exubio.angles import ANGLE_NAMES, ISB_SEQUENCES, isb_table, measured_isb_joints

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
        isb = isb_table(inputs.model, recon.q_rad)
        measured = measured_isb_joints(inputs.model, set(assessment.not_solved))
        extra["isb_angles"] = {
            "file": f"{stem}.isb.csv", "units": "deg",
            "sequences": {j: f"{s[0]}-{s[1]}'-{s[2]}''" for j, s in ISB_SEQUENCES.items()},
            "meaning": {j: list(v) for j, v in ANGLE_NAMES.items()},
            "measured": measured,
            "not_measured": [j for j in ISB_SEQUENCES if j not in measured],
            "side": inputs.protocol.side,
            "definition": "Wu et al. 2005 anatomical frames from the model's landmarks; intrinsic sequences; "
                          "GH X-Z'-Y'' (Phadke et al. 2011), HT Y-X'-Y'' (exubio.angles)"}
        summ = summary(recon, source=str(trial_path), extra=extra)
        paths = write_outputs(recon, out_dir, stem, metadata=meta, summary_data=summ,
                              undetermined=assessment.determinacy[recon.method].undetermined, isb=isb,
                              isb_comments=isb_header(extra["isb_angles"], Path(trial_path).name, method.value),
                              streamed=None if model_points is None else {"model_points_m": model_points[i]})
        out.append((recon, paths, summ))
    return out


def isb_header(info: dict[str, Any], trial: str, method: str) -> tuple[str, ...]:
    """Comment lines of ``<trial>.<method>.isb.csv``: what the angles are, their sequences and
    signs, and which joints the markers do not measure."""
    lines = [f"exubio ISB shoulder angles of {trial} ({method.upper()}), degrees; time in seconds",
             f"definition: {info['definition']}"]
    for joint, seq in info["sequences"].items():
        lines.append(f"{joint}: sequence {seq} (intrinsic); angles: " + "; ".join(info["meaning"][joint]))
    if info.get("side") == "left":
        lines.append("LEFT arm: its markers were mirrored through the thorax's sagittal plane (Z -> -Z of the ISB thorax "
                     "frame) onto the right-arm model, so every angle carries the right arm's sign (Wu et al. 2005)")
    else:
        lines.append("right arm, signs of Wu et al. 2005")
    if info["not_measured"]:
        lines.append("NOT MEASURED by this marker set (a segment's own joint is held or unobserved): "
                     + ", ".join(info["not_measured"]))
    return tuple(lines)


def _unused(inputs: TrialInputs) -> list[str]:
    from exubio.protocol import resolve_labels

    match = resolve_labels(inputs.protocol, inputs.trial.labels, source=inputs.trial.source)
    return list(match.unused) + list(inputs.trial.ignored_labels)


def agreement_deg(a: Reconstruction, b: Reconstruction, /) -> dict[str, float]:
    """RMSE (deg) per coordinate between two reconstructions of the same trial."""
    d = np.rad2deg(a.q_rad - b.q_rad)
    return {n: float(v) for n, v in zip(a.coordinate_names, np.sqrt(np.mean(d**2, axis=0)))}
