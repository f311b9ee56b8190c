"""A session's calibration: the subject model from a static trial (or frames of a trial), and the
static trial's label checks and pair distances that the session's task trials are checked against.
The calibration returns the calibrated model as an object (``SessionCalibration.session``); its
model file is written as a by-product, and the run goes on with the object, exactly as the file
holds it (exubio.model.load.as_written), without reading it back. The static trial is read once
and prepared once, for the calibration and its label checks alike."""
from __future__ import annotations

import dataclasses
import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from exubio.errors import InputError
from exubio.io import results
from exubio.io.trial import read_trial
from exubio.prep.targets import prepare_targets
from exubio.run.inputs import Session, load_session
from exubio.types import MarkerTargets, Protocol, Trajectories

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StaticSpec:
    """How a session's static calibrates the model (the command line's --static options):
    ``frames`` of the static ("0:50"; None: its longest still stretch), a ``functional`` movement
    trial for a functional (SCoRE) glenohumeral centre, ``more_statics`` (further static poses the
    thorax ellipsoid is fitted through), ``scapula_trials`` (movement trials whose scapula postures
    it is fitted through: exubio.calibration.scapula_motion)."""

    frames: str | None = None
    functional: Path | None = None
    more_statics: tuple[Path, ...] = ()
    scapula_trials: tuple[Path, ...] = ()  # (each of these paths may be a read Trajectories: the API's)


@dataclass(frozen=True)
class SessionCalibration:
    """A session's calibration as the run carries it: ``session`` (the calibrated model, the
    protocol bound to it, and the generic ones), the CalibrationReport, the static trial's name,
    the model file written, the label findings on the static, its pair distances (``reference``:
    what the task trials are checked against; None when a trial is calibrated on its own frames)
    and what its reader read around (``input_findings``)."""

    session: Session
    report: Any
    static: str
    model_file: Path
    frames: str | None = None
    labels: tuple = ()
    reference: Any = None
    input_findings: tuple[str, ...] = ()
    reused: bool = False  # the session folder's calibration from the same inputs, read, not fitted again

    def moved_to(self, model_file: Path, /) -> "SessionCalibration":
        """The same calibration, its model file moved (a study renames its calibration folder): the
        model's ``source`` names the file where it is now, as a model read from there would."""
        model = dataclasses.replace(self.session.model, source=str(model_file))
        session = self.session.replaced(model=model)
        return dataclasses.replace(self, session=session, model_file=Path(model_file))


def _read(source: str | Path | Trajectories) -> Trajectories:
    return source if isinstance(source, Trajectories) else read_trial(source)


def calibrate(static: Trajectories, session: Session, spec: StaticSpec = StaticSpec(), /, *,
              targets: MarkerTargets | None = None):
    """Calibrate the session's generic model to ``static`` (exubio.calibration.calibrate_model, a pure
    step; ``targets``: the static prepared with the generic protocol): (calibrated model, report)."""
    from exubio.calibration import calibrate_model, parse_frames

    protocol = session.generic_protocol
    functional = prepare_targets(_read(spec.functional), protocol) if spec.functional is not None else None
    more = tuple(prepare_targets(_read(p), protocol) for p in spec.more_statics)
    scapula = tuple(prepare_targets(_read(p), protocol) for p in spec.scapula_trials) or None
    return calibrate_model(session.generic_model, protocol, static, frames=parse_frames(spec.frames), targets=targets,
                           functional=functional, more_statics=more, scapula_motion=scapula)


def calibrate_file(static: str | Path | Trajectories, /, *, session: Session | None = None,
                   spec: StaticSpec = StaticSpec(), out_path: str | Path | None = None, overwrite: bool = False):
    """Everything ``exubio calibrate`` does: read the static trial, calibrate the session's generic
    model (default: the shipped model and protocol) and, with ``out_path``, write the calibrated
    model YAML (replaced only with ``overwrite``). Returns (calibrated model, the protocol bound
    to it, the CalibrationReport)."""
    from exubio.model.load import as_written, save_model

    if out_path is not None and Path(out_path).exists() and not overwrite:
        raise InputError(f"{out_path}: the model file already exists; pass --overwrite to replace it")
    session = session if session is not None else load_session()
    model, report = calibrate(_read(static), session, spec)
    if out_path is not None:
        save_model(model, out_path, calibration=report.to_dict())
        model = as_written(model, calibration=report.to_dict(), source=out_path)
    calibrated = session.with_model(model)
    return calibrated.model, calibrated.protocol, report


def calibration_protocol(static: Trajectories, session: Session, /):
    """The generic protocol a static (or a trial's own frames) is calibrated with: a marker it lacks
    left out (optional) where the others still measure every angle, with a warning that names it and
    the near label the static has (exubio.trust.missing_markers); else the InputError saying so. The
    session's own protocol keeps the marker: a trial that lacks it too gets the check naming it."""
    from exubio.trust.missing_markers import drop_missing_markers

    binding, dropped = drop_missing_markers(static, session.generic_binding)
    for what in dropped:
        log.warning("%s: marker %s missing: calibrated without it (the other markers still measure every angle)",
                    static.source or "static", what)
    return binding.protocol


def _without_absent(protocol: Protocol, targets: MarkerTargets, /) -> Protocol:
    """``protocol`` with the markers ``targets`` (prepared with it or calibration_protocol's) never has
    made optional: the protocol they were prepared with."""
    absent = {n for j, n in enumerate(targets.marker_names) if not targets.present[:, j].any()}
    return dataclasses.replace(protocol, markers=tuple(dataclasses.replace(m, optional=True) if m.name in absent else m
                                                       for m in protocol.markers))


def calibrate_session(static: str | Path | Trajectories, session: Session, out_dir: str | Path, stem: str, /, *,
                      spec: StaticSpec = StaticSpec(), overwrite: bool = False, reference: bool = True,
                      targets: MarkerTargets | None = None) -> SessionCalibration:
    """Calibrate the session's generic model to ``static`` (a static trial, or frames of the trial
    itself), write ``out_dir/<stem>.model.yaml``, check the static's labels and (with ``reference``:
    a static trial apart from the task trials) keep its pair distances, which the session's trials
    are checked against. ``targets``: the static already prepared with the generic protocol, or with
    calibration_protocol's (the generic one with a marker the static lacks made optional)."""
    from exubio.model.load import as_written, save_model

    source = _read(static)  # read once for the calibration and the checks
    model_file = Path(out_dir) / f"{stem}.model.yaml"
    key = calibration_key(source, session, spec)
    reused = None if overwrite else reusable_calibration(model_file, key)
    gprot = calibration_protocol(source, session) if targets is None else _without_absent(session.generic_protocol,
                                                                                            targets)
    targets = targets if targets is not None else prepare_targets(source, gprot)  # prepared once
    if reused is not None:
        model, report = reused
    else:
        results.prepare_output_dir(out_dir, [model_file.name], overwrite=overwrite)
        model, report = calibrate(source, dataclasses.replace(session, generic_protocol=gprot), spec, targets=targets)
        written = {**report.to_dict(), **({"inputs_sha256": key} if key else {})}
        save_model(model, model_file, calibration=written)
        model = as_written(model, calibration=written, source=model_file)
    findings, distances = _static_evidence(source, session, spec, report, gprot, targets, reference)
    return SessionCalibration(session.with_model(model), report, source.source, model_file, spec.frames, findings,
                              distances, tuple(source.input_findings), reused is not None)


def _static_evidence(source: Trajectories, session: Session, spec: StaticSpec, report: Any, gprot: Protocol,
                     targets: MarkerTargets, reference: bool, /) -> tuple[tuple, Any]:
    """What the trials' verdicts read of the static besides the calibration: its label findings
    against the generic model, and its pair distances (with ``reference``, else None)."""
    from exubio.calibration import parse_frames
    from exubio.trust.assess import trial_label_findings
    from exubio.trust.labels import pair_distances

    pos = targets.positions_m[slice(*report.frames)] if parse_frames(spec.frames) is not None else targets.positions_m
    findings = trial_label_findings(session.generic_binding.rebound(gprot), targets)
    return tuple(findings), (pair_distances(pos, targets.marker_names, source=source.source) if reference else None)


def calibrate_in_memory(static: str | Path | Trajectories, session: Session, spec: StaticSpec = StaticSpec(), /
                        ) -> SessionCalibration:
    """What calibrate_session does for ``exubio reconstruct --static``, without writing the model
    (``model_file`` None): the calibration exubio.calibrate returns, so the API's verdicts read
    the same calibration, static labels and static pair distances as the CLI's."""
    source = _read(static)
    gprot = calibration_protocol(source, session)
    targets = prepare_targets(source, gprot)
    model, report = calibrate(source, dataclasses.replace(session, generic_protocol=gprot), spec, targets=targets)
    findings, distances = _static_evidence(source, session, spec, report, gprot, targets, True)
    return SessionCalibration(session.with_model(model), report, source.source, None, spec.frames, findings, distances,
                              tuple(source.input_findings))


def calibration_key(static: Trajectories, session: Session, spec: StaticSpec, /) -> str | None:
    """A fingerprint of what a calibration is made from: the static trial's file and labels (a
    relabel changes them), the generic model and protocol files (the protocol's extends chain with it),
    the static options and their
    files, exubio's version and code (exubio.run.resume.code_fingerprint). None when the static is not a file
    (nothing to find again)."""
    import exubio
    from exubio.run.resume import code_fingerprint

    if not static.source or not Path(static.source).is_file():
        return None
    proto = session.generic_protocol
    protocol = proto.files or (proto.source,)  # with the files of its extends chain
    files = [static.source, session.generic_model.source, *protocol, spec.functional, *spec.more_statics,
             *spec.scapula_trials]
    h = hashlib.sha256()
    for f in files:
        h.update(hashlib.sha256(Path(f).read_bytes() if f and Path(f).is_file() else str(f).encode()).digest())
    h.update(repr((tuple(static.labels), spec.frames, exubio.__version__, code_fingerprint())).encode())
    return h.hexdigest()


def reusable_calibration(model_file: Path, key: str | None, /) -> tuple[Any, Any] | None:
    """The calibrated model and its report in ``model_file``, when that file was calibrated from
    the inputs ``key`` fingerprints (calibration_key); None otherwise (no file, other inputs, a
    file exubio did not write)."""
    from exubio.calibration.report import CalibrationReport
    from exubio.errors import ExubioError
    from exubio.model.load import load_model

    if key is None or not model_file.is_file():
        return None
    try:
        model = load_model(model_file)
        cal = model.metadata.get("calibration") or {}
        if cal.get("inputs_sha256") != key:
            return None
        return model, CalibrationReport.from_dict(cal)
    except (ExubioError, KeyError, TypeError, ValueError):
        return None
