"""summary.json: the one place where a trial's typed results (its reconstruction, its assessment,
the session's calibration, the notes on the input files) fill the file's typed records
(exubio.run.summary_record), which exubio.io.records turns into the file's plain data (mm, deg,
strings). Everything above hands this module objects; nothing below it builds the file's dicts."""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from exubio.io.records import to_json
from exubio.model.angles import ANATOMICAL_ANGLES
from exubio.io.result_names import set_names
from exubio.model.signs import meaning
from exubio.protocol.labels import resolve_labels
from exubio.run.summary_record import CalibrationEntry, Gap, ReconstructionSummary, TrialSummary
from exubio.trust.assess import TrialAssessment
from exubio.trust.evaluate import residual_statistics
from exubio.trust.quality import Quality, Reason
from exubio.types import FrameStatus, Reconstruction

AGREEMENT_DEFINITION = "RMSE over the frames where the coordinate is determined in both reconstructions"


def finding_entry(f: Any, /) -> Any:
    """One label or model finding as the file records it: a typed finding (a dataclass, written by
    exubio.io.records) as it is; a dict, or an object with the finding's attributes, as a dict."""
    if dataclasses.is_dataclass(f) and not isinstance(f, type):
        return f
    if isinstance(f, Mapping):
        return dict(f)
    out = {k: getattr(f, k) for k in ("kind", "markers", "evidence", "severity") if hasattr(f, k)}
    if "markers" in out:
        out["markers"] = list(out["markers"])
    return out


def _absolute(path: Any, /) -> Any:
    """A file's path as summary.json gives every path: absolute (not relative to where the run
    was started); "" and None as they are."""
    return os.path.abspath(path) if path else path


def calibration_entry(cal: Any, /) -> CalibrationEntry:
    """The session's calibration (exubio.run.session.SessionCalibration) as summary.json records
    it: the full report under ``report``, the label findings on the static trial under ``labels``,
    what the reader read around in the static trial's file (io/trc.py, io/c3d.py)."""
    report = cal.report.to_dict()
    return CalibrationEntry(static=_absolute(cal.static), frames=cal.frames, model_file=_absolute(cal.model_file),
                            mean_residual_mm=cal.report.mean_residual_mm, residual_mm=report.get("residual_mm"),
                            report=report, labels=tuple(finding_entry(f) for f in cal.labels),
                            input_findings=tuple(cal.input_findings))


def reconstruction_entries(recon: Reconstruction, /, *, source: str = "") -> dict[str, Any]:
    """What summary.json says of the reconstruction itself (the fields of
    exubio.run.summary_record.ReconstructionEntries): frames, timings, residuals, constraint, gaps,
    the markers and coordinates."""
    total = float(recon.timings_s.get("total", np.nan))
    status = np.asarray(recon.status)
    rate = 1.0 / float(np.median(np.diff(recon.time_s))) if recon.n_frames > 1 else 1.0
    return dict(
        method=recon.method, source=source, n_frames=recon.n_frames,
        duration_s=float(recon.time_s[-1] - recon.time_s[0]) if recon.n_frames else 0.0,
        wall_time_s=total, ms_per_frame=total / max(recon.n_frames, 1) * 1000.0, timings_s=dict(recon.timings_s),
        residual_mm=residual_statistics(recon), constraint_max_abs=float(np.nanmax(np.abs(recon.constraint))),
        constraint_velocity_max_abs_per_s=float(np.nanmax(np.abs(recon.constraint_velocity))),
        frames={s.name.lower(): int((status == s.value).sum()) for s in FrameStatus},
        markers=tuple(recon.marker_names), coordinates=tuple(recon.coordinate_names),
        gaps=tuple(Gap(g.marker, g.start, g.stop, float(recon.time_s[g.start]) if g.start < recon.n_frames else None,
                       g.n_frames / rate) for g in recon.gaps if g.n_frames < recon.n_frames),
        absent_markers=tuple(g.marker for g in recon.gaps if g.n_frames >= recon.n_frames),
        info=dict(recon.info))


def assessment_entries(a: TrialAssessment, method: str, /, *, quality: Quality | None = None) -> dict[str, Any]:
    """That method's assessment as summary.json records it (fields of
    exubio.run.summary_record.TrialSummary); ``quality``: its verdict with the run's notes added
    (default: the assessment's own)."""
    angles = None if a.angles is None else {**a.angles[method].to_dict(), "protocol_can": dict(a.structural or {})}
    return dict(anatomical_angles=angles, model_mismatch=(a.mismatch or {}).get(method),
                quality=quality or a.quality[method], determinacy=a.determinacy[method].to_dict(),
                limits=tuple(a.limits[method]), labels=tuple(finding_entry(f) for f in a.labels),
                pf_ls_agreement_deg=agreement_entry(a.agreement_deg), not_measured=tuple(a.not_solved))


def agreement_entry(agreement_deg: Mapping[str, float] | None, /) -> dict[str, Any] | None:
    """The PF-LS agreement as summary.json records it: its definition and each angle's RMSE (deg) to
    4 decimals, None where no frame is measured by both; None without both methods."""
    if agreement_deg is None:
        return None
    return {"definition": AGREEMENT_DEFINITION,
            **{k: (None if v is None or not np.isfinite(v) else round(float(v), 4)) for k, v in agreement_deg.items()}}


def input_notes(findings: Sequence[str], /) -> list[Reason]:
    """A note per input finding (what the reader read around: the file is named, the result stands)."""
    return [Reason("input_file", "note", f"input file: {f}") for f in findings]


def failure_notes(failures: Mapping[str, str], /) -> list[Reason]:
    """A note per method of the run that failed (this result stands on its own: no PF-LS agreement)."""
    return [Reason("method_failed", "note", f"{m.upper()} failed on this trial, so this result is not compared with "
                   f"it (no PF-LS agreement): {reason}") for m, reason in failures.items()]


@dataclass(frozen=True)
class RunNotes:
    """What a trial's summaries say beyond its reconstruction and assessment: the session's
    calibration (exubio.run.session.SessionCalibration), a live recording's figures, the run's
    methods that failed (name -> reason), the fingerprint of the run's inputs (exubio.run.resume:
    a re-run of the same inputs keeps a complete set)."""

    calibration: Any = None
    live: Mapping[str, Any] | None = None
    failures: Mapping[str, str] = field(default_factory=dict)
    inputs_sha256: str | None = None


def unused_labels(inputs: Any, /) -> list[str]:
    """The trial's labels the protocol does not use, and those the reader ignored."""
    match = resolve_labels(inputs.protocol, inputs.trial.labels, source=inputs.trial.source)
    return list(match.unused) + list(inputs.trial.ignored_labels)


def _file_findings(inputs: Any, cal: Any) -> tuple[str, ...]:
    """What the readers of the trial and of its static read around (the static's named as such)."""
    read_around = tuple(inputs.trial.input_findings)
    return tuple(dict.fromkeys(read_around + tuple(
        f"static trial: {f}" for f in (cal.input_findings if cal is not None else ()) if f not in read_around)))


def trial_quality(assessment: TrialAssessment, method: str, inputs: Any, /, notes: RunNotes = RunNotes()) -> Quality:
    """That method's verdict as its files give it: the assessment's, with a note per input finding
    and per failed method of the run."""
    return assessment.quality[method].with_reasons(input_notes(_file_findings(inputs, notes.calibration))
                                                   + failure_notes(notes.failures))


def trial_summary(recon: Reconstruction, assessment: TrialAssessment, inputs: Any, /, *, source: str, stem: str,
                  notes: RunNotes = RunNotes(), quality: Quality | None = None) -> dict[str, Any]:
    """One method's summary.json: ``inputs`` the trial's (exubio.run.pipeline.TrialInputs),
    ``source`` the trial file, ``stem`` the result set's, ``notes`` the run's (RunNotes),
    ``quality`` its verdict (default: trial_quality)."""
    cal = notes.calibration
    quality = quality if quality is not None else trial_quality(assessment, recon.method, inputs, notes)
    signs = inputs.protocol.signs
    names = set_names(stem)
    return to_json(TrialSummary(
        **reconstruction_entries(recon, source=_absolute(source)), unused_trial_labels=tuple(unused_labels(inputs)),
        calibration=None if cal is None else calibration_entry(cal),
        live=None if notes.live is None else dict(notes.live),
        mean_spring_deflection_mm=recon.info.get("mean_spring_deflection_mm"),
        filter_cutoff_hz=dict(inputs.targets.cutoff_hz or {}),
        **assessment_entries(assessment, recon.method, quality=quality),
        input_findings=_file_findings(inputs, cal), failed_methods=dict(notes.failures),
        angles={"files": [names["csv"], names["mot"]], "units": "deg", "side": inputs.protocol.side,
                "definitions": {n: {"definition": d, "meaning": meaning(n, signs)} for n, d, _ in ANATOMICAL_ANGLES}},
        signs=signs, inputs_sha256=notes.inputs_sha256))


def reconstruction_summary(recon: Reconstruction, angles: Any, /, *, source: str = "", signs: str = "isb") -> dict[str, Any]:
    """The summary.json of a reconstruction written on its own (exubio.write_results): the
    reconstruction, its anatomical angles' status (``angles``: AngleDeterminacy) and, when the
    reconstruction carries one (exubio.reconstruct), its verdict."""
    return to_json(ReconstructionSummary(**reconstruction_entries(recon, source=source), anatomical_angles=angles.to_dict(),
                                         quality=getattr(recon, "quality", None), signs=signs))
