"""The verdict's checks, as one list: what each reads, its thresholds, and the reasons it gives.

``CHECKS`` is the one place the verdict is made from: the offline assessment of a trial
(exubio.trust.assess) and the running verdict of a live session (exubio.run.live.monitor) both fill
an ``Evidence`` with what they know and call ``judge``; a check whose evidence is absent (a live
session has no PF-LS agreement yet, an offline trial no dropped stream frames) gives nothing.
Adding a check is one function and one line here (docs: the verdict and each check). The criteria
and their thresholds, each with the reason for its value, are in exubio.trust.quality and
exubio.trust.mismatch; this module only says which evidence each one reads, in which order the
reasons are listed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from exubio.trust import quality as Q
from exubio.trust.mismatch import mismatch_reasons, unseen_mismatch_reasons

__all__ = ["Check", "CHECKS", "Evidence", "LiveCounts", "judge"]


@dataclass(frozen=True)
class LiveCounts:
    """What only a live session sees: frames that never came, came late or were skipped, PF runs
    restarted, and labels that look swapped now (pairs of marker names with the time since, s)."""

    dropped: int = 0
    late: int = 0
    skipped: int = 0
    restarts: int = 0
    max_behind_s: float = 0.0
    swapped: Sequence[tuple[str, str, float]] = ()


@dataclass(frozen=True)
class Evidence:
    """What the checks read of one method's reconstruction of a trial, or of a live session's frames
    so far. ``None`` or empty: not known here, and the checks that read it give nothing."""

    n_frames: int
    rate_hz: float
    label_findings: Sequence[Any] = ()  # exubio.trust.labels findings on the trial
    label_findings_in_static: Sequence[Any] = ()  # the same findings seen on the static too (one fix for both)
    static_label_findings: Sequence[Any] = ()  # findings on the static trial alone
    calibration: Any = None  # the session's CalibrationReport, or None
    scale_bounds: tuple[float, float] = (0.0, np.inf)
    off_segment: Mapping[str, float] = field(default_factory=dict)
    accepted_offsets_mm: Mapping[str, float] = field(default_factory=dict)
    not_measured: Sequence[str] = ()  # coordinates the marker set cannot determine
    session_shifts: Sequence[Any] = ()
    static_name: str = ""
    dropped_markers: Sequence[str] = ()
    partial_swaps: Sequence[Any] = ()
    repaired: bool = False
    residual_mm: Mapping[str, Any] | None = None  # {"mean", "per_marker_rmse"}
    per_frame_residual_mm: np.ndarray | None = None
    limits: Sequence[Mapping[str, Any]] | None = None
    angle_status: Mapping[str, str] | None = None
    structural_status: Mapping[str, str] = field(default_factory=dict)
    measured_fraction: Mapping[str, float] = field(default_factory=dict)
    undetermined_trial_fraction: float = 0.5
    angle_causes: Mapping[str, Any] | None = None
    frames: Mapping[str, int] | None = None  # {"not_converged", "too_few_markers"}
    info: Mapping[str, Any] | None = None  # the method's info (its fallback run)
    gaps: Sequence[Any] | None = None
    agreement_deg: Mapping[str, float] | None = None
    mismatch: Any = None  # exubio.trust.mismatch.MismatchAssessment
    protocol: Any = None  # for the mismatch no check can see (None: not said)
    scapula_calibrated: bool = False
    live: LiveCounts | None = None


@dataclass(frozen=True)
class Check:
    """One check: its name, the evidence it reads, its thresholds (exubio.trust.quality's names) and
    the function from the evidence to its reasons."""

    name: str
    reads: str
    thresholds: str
    reasons: Callable[[Evidence], list[Q.Reason]]


def _labels(e: Evidence) -> list[Q.Reason]:
    return (Q.label_reasons(e.label_findings, in_static=e.label_findings_in_static)
            + Q.label_reasons(e.static_label_findings, prefix="static trial: "))


def _calibration(e: Evidence) -> list[Q.Reason]:
    return Q.calibration_reasons(e.calibration, scale_bounds=e.scale_bounds, off_segment=e.off_segment,
                                 not_measured=e.not_measured, accepted_offsets_mm=e.accepted_offsets_mm)


def _residuals(e: Evidence) -> list[Q.Reason]:
    if e.residual_mm is None:
        return []
    frames = e.per_frame_residual_mm if e.per_frame_residual_mm is not None else np.zeros(0)
    return Q.residual_reasons(e.residual_mm, frames)


def _angles(e: Evidence) -> list[Q.Reason]:
    if e.angle_status is None:
        return []
    return Q.angle_reasons(e.angle_status, e.structural_status, e.measured_fraction, e.undetermined_trial_fraction,
                           causes=e.angle_causes)


def _mismatch(e: Evidence) -> list[Q.Reason]:
    return mismatch_reasons(e.mismatch, calibrated=e.calibration is not None) if e.mismatch is not None else []


def _unseen_mismatch(e: Evidence) -> list[Q.Reason]:
    return [] if e.protocol is None else unseen_mismatch_reasons(e.protocol, scapula_calibrated=e.scapula_calibrated)


def _live(e: Evidence) -> list[Q.Reason]:
    c = e.live
    if c is None:
        return []
    out = [Q.Reason("label", "fail", f"markers {a} and {b} look swapped since t = {since:.2f} s (springs off)")
           for a, b, since in c.swapped]
    if c.dropped:
        out.append(Q.Reason("live_dropped", "note", f"{c.dropped} frame(s) never came (springs off there; see the events)"))
    if c.late:
        out.append(Q.Reason("live_late", "note", f"{c.late} sample(s) came late and were dropped"))
    if c.skipped:
        out.append(Q.Reason("live_skip", "check", f"{c.skipped} frames skipped: the solver fell more than "
                            f"{c.max_behind_s:g} s behind"))
    if c.restarts:
        out.append(Q.Reason("live_restart", "note", f"{c.restarts} PF run(s) restarted from the LS pose (stream "
                            "restarted or diverged)"))
    return out


CHECKS: tuple[Check, ...] = (
    Check("labels", "the label findings on the trial and on its static (exubio.trust.labels)",
          "the findings' own severities", _labels),
    Check("calibration", "the session's calibration report, markers off their segment, accepted landmark offsets",
          "SCALE_AT_BOUND, WINDOW_MOTION_MM, LANDMARK_OFFSET_MM, LANDMARK_ACCEPT_MARGIN_MM, OFF_SEGMENT_MARGIN_M",
          _calibration),
    Check("session", "segments whose markers look placed anew since the static", "exubio.trust.session_check",
          lambda e: Q.session_reasons(e.session_shifts, e.static_name)),
    Check("missing markers", "protocol markers the trial lacks, left out", "none: said when any",
          lambda e: Q.dropped_reasons(e.dropped_markers)),
    Check("partial swaps", "labels exchanged in part of the trial (exubio.trust.label_ranges)", "fail; check once repaired",
          lambda e: Q.partial_swap_reasons(e.partial_swaps, e.repaired)),
    Check("residuals", "the trial's and each marker's residual, the frames' mean residuals",
          "RESIDUAL_MEAN_MM, MARKER_RMSE_MM, FRAME_RESIDUAL_MM, FRAME_RESIDUAL_FRACTION", _residuals),
    Check("joint limits", "solved coordinates at their range limits", "LIMIT_BEYOND_DEG",
          lambda e: [] if e.limits is None else Q.limit_reasons(e.limits, e.n_frames, not_measured=e.not_measured)),
    Check("angles measured", "each angle's status per frame (exubio.trust.angle_uncertainty) and the marker set's",
          "UNDETERMINED_TRIAL_FRACTION, U_BOUND_DEG, GIMBAL_MARGIN_DEG", _angles),
    Check("convergence", "frames not converged or with too few markers", "NOT_CONVERGED_FRACTION",
          lambda e: [] if e.frames is None else Q.convergence_reasons(e.frames, e.n_frames)),
    Check("solver fallback", "PF's second run, when its first stopped", "none: said when it happened",
          lambda e: Q.fallback_reasons(e.info or {})),
    Check("gaps", "each marker's gaps", "GAP_NOTE_FRACTION",
          lambda e: [] if e.gaps is None else Q.gap_reasons(e.gaps, e.n_frames, e.rate_hz)),
    Check("PF-LS agreement", "the RMSE between PF's and LS's measured angles, when both ran", "AGREEMENT_DEG",
          lambda e: Q.agreement_reasons(e.agreement_deg, ())),
    Check("model mismatch", "each segment's misfit pattern (exubio.trust.mismatch)",
          "CONTACT_INSIDE_MM, RMS_MM, OUTSIDE_MM (exubio.trust.mismatch)", _mismatch),
    Check("unseen mismatch", "whether the markers measure the scapula and its ellipsoid was fitted",
          "none: a note", _unseen_mismatch),
    Check("live", "frames dropped, late or skipped, PF restarts, labels swapped now (live sessions only)",
          "a skip is a check, a swap a fail", _live),
)
"""Every check of the verdict, in the order its reasons are listed (within a level)."""


def judge(evidence: Evidence, /, checks: Sequence[Check] = CHECKS) -> Q.Quality:
    """The verdict of ``evidence``: every check's reasons, the worst level deciding."""
    return Q.Quality.of(r for c in checks for r in c.reasons(evidence))
