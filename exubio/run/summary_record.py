"""summary.json as typed records: the file's keys in its order, each a field, the typed results
where the file holds one (the verdict as a Quality, the limits as LimitReports, the label findings
as LabelFindings, the model-mismatch assessment). exubio.io.records writes them
(``to_json``) and reads a file back into them (``decode(TrialSummary, data)``); nothing else
describes the file. exubio.run.summary_file fills them from a trial's typed results.

Two kinds of file share the reconstruction's keys (``ReconstructionEntries``): a run's
(``TrialSummary``, written by exubio reconstruct, a study, live) and a reconstruction written on
its own (``ReconstructionSummary``, exubio.write_results). Fields typed as plain data
(``dict[str, Any]``) hold summaries computed from results that do not keep them (the determinacy's
and the anatomical angles' medians and fractions over the frames, the residual statistics) and
the calibration report: its residual means are of the unrounded residuals, so
``CalibrationReport.from_dict`` of it (what a reused calibration reports) would not write the
same bytes again; the file's data is kept as it is.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from exubio.io.records import optional
from exubio.model.ranges import LimitReport
from exubio.trust.labels import LabelFinding
from exubio.trust.mismatch import MismatchAssessment
from exubio.trust.quality import Quality

__all__ = ["CalibrationEntry", "Gap", "ReconstructionEntries", "ReconstructionSummary", "TrialSummary"]


@dataclass(frozen=True)
class Gap:
    """A marker's gap: frames [start_frame, stop_frame), its start time (None past the last frame)
    and duration (s)."""

    marker: str
    start_frame: int
    stop_frame: int
    start_s: float | None
    duration_s: float


@dataclass(frozen=True)
class CalibrationEntry:
    """The session's calibration: its static trial, frames and model file, the report (plain data,
    see the module docstring), the label findings on the static, what its reader read around."""

    static: str | None
    frames: str | None
    model_file: str | None
    mean_residual_mm: float
    residual_mm: dict[str, Any] | None
    report: dict[str, Any]
    labels: tuple[LabelFinding, ...]
    input_findings: tuple[str, ...] | None = optional(empty=True)


@dataclass(frozen=True, kw_only=True)
class ReconstructionEntries:
    """What a summary says of the reconstruction itself (m, s, mm)."""

    method: str
    source: str
    n_frames: int
    duration_s: float
    wall_time_s: float
    ms_per_frame: float
    timings_s: dict[str, float]
    residual_mm: dict[str, Any]
    constraint_max_abs: float
    constraint_velocity_max_abs_per_s: float
    frames: dict[str, int]
    markers: tuple[str, ...]
    coordinates: tuple[str, ...]
    gaps: tuple[Gap, ...]
    absent_markers: tuple[str, ...]
    info: dict[str, Any]


@dataclass(frozen=True, kw_only=True)
class TrialSummary(ReconstructionEntries):
    """A run's summary.json of one method (keys absent when None or empty, as marked)."""

    unused_trial_labels: tuple[str, ...]
    calibration: CalibrationEntry | None = optional()
    live: dict[str, Any] | None = optional()
    mean_spring_deflection_mm: float | None = optional()
    filter_cutoff_hz: dict[str, float] | None = optional(empty=True)
    anatomical_angles: dict[str, Any] | None = optional()
    model_mismatch: MismatchAssessment | None = optional()
    quality: Quality
    determinacy: dict[str, Any]
    limits: tuple[LimitReport, ...]
    labels: tuple[LabelFinding, ...]
    pf_ls_agreement_deg: dict[str, Any] | None
    not_measured: tuple[str, ...]
    input_findings: tuple[str, ...] | None = optional(empty=True)
    failed_methods: dict[str, str] | None = optional(empty=True)
    angles: dict[str, Any]
    signs: str
    inputs_sha256: str | None = optional(empty=True)


@dataclass(frozen=True, kw_only=True)
class ReconstructionSummary(ReconstructionEntries):
    """The summary.json of a reconstruction written on its own: its anatomical angles' status and,
    when it carries one, its verdict."""

    anatomical_angles: dict[str, Any]
    quality: Quality | None = optional()
    signs: str
