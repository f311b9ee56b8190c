"""A session's calibration: the subject model from a static trial (or frames of a trial), written as
a model file, and the static trial's label checks and pair distances that the session's task
trials are checked against. Each function takes a trial file or a trial already read
(Trajectories), so that a trial calibrated on its own frames is read once."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from exubio.errors import InputError
from exubio.io import results
from exubio.io.trial import read_trial
from exubio.run.pipeline import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.types import Trajectories


def _read(source: str | Path | Trajectories) -> Trajectories:
    return source if isinstance(source, Trajectories) else read_trial(source)


def _name(source: str | Path | Trajectories) -> str:
    return source.source if isinstance(source, Trajectories) else str(source)


def calibration_summary(report, /, *, static: str, model_file: str | Path, frames: str | None = None,
                        labels: Any = ()) -> dict[str, Any]:
    """The calibration as summary.json records it (the full report dict under ``report``, the
    label findings on the static trial under ``labels``)."""
    from exubio.trust.assess import _finding_dict

    return {"static": static, "frames": frames, "model_file": str(model_file),
            "mean_residual_mm": report.mean_residual_mm, "residual_mm": report.to_dict().get("residual_mm"),
            "report": report.to_dict(), "labels": [_finding_dict(f) for f in labels]}


def static_checks(static_path: str | Path | Trajectories, /, *, protocol_path: str | Path | None = None,
                  model_path: str | Path | None = None, frames: slice | None = None):
    """The label findings on a static trial (against the generic model) and its pair distances,
    the reference the session's task trials are checked against (exubio.trust.labels)."""
    from exubio.trust.labels import check_trial, pair_distances

    model, protocol = load_model_and_protocol(model_path=model_path, protocol_path=protocol_path)
    targets = prepare_targets(_read(static_path), protocol)
    pos = targets.positions_m if frames is None else targets.positions_m[frames]
    findings = check_trial(targets, model=model, protocol=protocol, ranges_rad=model.coordinate_ranges_rad)
    return findings, pair_distances(pos, targets.marker_names, source=_name(static_path))


def calibrate_file(static_path: str | Path | Trajectories, /, *, protocol_path: str | Path | None = None,
                   model_path: str | Path | None = None, body_mass_kg: float | None = None,
                   frames: slice | None = None, out_path: str | Path | None = None,
                   overwrite: bool = False, functional_path: str | Path | None = None,
                   more_static_paths: tuple[str | Path, ...] = (), scapula_paths: tuple[str | Path, ...] = ()):
    """Everything ``exubio calibrate`` does: read the trial, the generic model and the protocol,
    calibrate (``exubio.calibration.calibrate_model``, a pure step), and (with ``out_path``) write
    the calibrated model YAML. Returns (calibrated model, the protocol bound to it, the
    CalibrationReport). An existing ``out_path`` is replaced only with ``overwrite``.
    ``functional_path``: a movement trial of the same session for a functional (SCoRE)
    glenohumeral centre; ``more_static_paths``: further static poses (e.g. arm raised) the
    thorax ellipsoid is fitted through as well; ``scapula_paths``: movement trials of the session
    (arm raised in one or more planes) whose scapula postures the thorax ellipsoid is fitted
    through with the static pose(s) (exubio.calibration.scapula_motion)."""
    from exubio.calibration import calibrate_model, calibrated_protocol
    from exubio.model.load import save_model

    if out_path is not None and Path(out_path).exists() and not overwrite:
        raise InputError(f"{out_path}: the model file already exists; pass --overwrite to replace it")
    model, protocol = load_model_and_protocol(model_path=model_path, protocol_path=protocol_path,
                                              body_mass_kg=body_mass_kg)
    functional = None
    if functional_path is not None:
        functional = prepare_targets(read_trial(functional_path), protocol)
    more = tuple(prepare_targets(read_trial(p), protocol) for p in more_static_paths)
    scapula = tuple(prepare_targets(read_trial(p), protocol) for p in scapula_paths) or None
    calibrated, report = calibrate_model(model, protocol, _read(static_path), frames=frames, functional=functional,
                                         more_statics=more, scapula_motion=scapula)
    if out_path is not None:
        save_model(calibrated, out_path, calibration=report.to_dict())
    return calibrated, calibrated_protocol(protocol, calibrated), report


def calibrate_into(source: str | Path | Trajectories, out_dir: str | Path, stem: str, /, *, protocol_path: str | Path | None = None,
                   model_path: str | Path | None = None, body_mass_kg: float | None = None,
                   frames_text: str | None = None, overwrite: bool = False,
                   functional_path: str | Path | None = None, more_static_paths: tuple[str | Path, ...] = (),
                   scapula_paths: tuple[str | Path, ...] = ()):
    """Calibrate the model to ``source`` (a static trial, or frames of the trial itself) and write
    ``out_dir/<stem>.model.yaml``; returns (model file, CalibrationReport)."""
    from exubio.calibration import parse_frames
    from exubio.model.load import save_model

    model_file = Path(out_dir) / f"{stem}.model.yaml"
    results.prepare_output_dir(out_dir, [model_file.name], overwrite=overwrite)
    model, _, report = calibrate_file(source, protocol_path=protocol_path, model_path=model_path,
                                      body_mass_kg=body_mass_kg, frames=parse_frames(frames_text),
                                      functional_path=functional_path, more_static_paths=more_static_paths,
                                      scapula_paths=scapula_paths)
    save_model(model, model_file, calibration=report.to_dict())
    return model_file, report


def calibrate_session(source: str | Path | Trajectories, out_dir: str | Path, stem: str, /, *, protocol_path: str | Path | None = None,
                      model_path: str | Path | None = None, body_mass_kg: float | None = None,
                      frames_text: str | None = None, overwrite: bool = False,
                      reference: bool = True, functional_path: str | Path | None = None,
                      more_static_paths: tuple[str | Path, ...] = (),
                      scapula_paths: tuple[str | Path, ...] = ()) -> tuple[Path, Any, dict[str, Any]]:
    """calibrate_into plus the static trial's label checks: (model file, report, the calibration
    summary for summary.json). With ``reference`` (a static trial apart from the task trials) the
    summary's private ``_reference`` holds the static's pair distances, which the session's trials
    are checked against; it is not written to summary.json."""
    from exubio.calibration import parse_frames

    source = _read(source)  # read once for the calibration and the checks
    model_file, report = calibrate_into(source, out_dir, stem, protocol_path=protocol_path, model_path=model_path,
                                        body_mass_kg=body_mass_kg, frames_text=frames_text, overwrite=overwrite,
                                        functional_path=functional_path, more_static_paths=more_static_paths,
                                        scapula_paths=scapula_paths)
    frames = parse_frames(frames_text)
    findings, ref_distances = static_checks(source, protocol_path=protocol_path, model_path=model_path,
                                        frames=slice(*report.frames) if frames is not None else None)
    summary = calibration_summary(report, static=_name(source), model_file=model_file, frames=frames_text,
                                  labels=findings)
    if source.input_findings:  # what the reader read around in the static trial's file (io/trc.py, io/c3d.py)
        summary["input_findings"] = list(source.input_findings)
    if reference:
        summary["_reference"] = ref_distances
    return model_file, report, summary
