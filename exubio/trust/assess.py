"""Everything measured about one trial's reconstructions to decide whether to trust them: which
coordinates the markers determine (exubio.trust.observability), frames at a range limit
(exubio.model.ranges), PF-LS agreement on determined coordinates, the label checks and the calibration;
turned into one quality verdict per method (exubio.trust.quality). No solver is run here."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from exubio.trust import quality as Q
from exubio.trust.checks import Evidence, judge
from exubio.calibration import SCALE_BOUNDS
from exubio.trust.evaluate import per_frame_residuals_mm, residual_statistics
from exubio.model.kinematics import Kinematics
from exubio.methods.common import tracked_points, unobserved_segments
from exubio.methods.poses import held_mask
from exubio.trust.mismatch import MismatchAssessment, assess_mismatch
from exubio.trust.observability import UNDETERMINED_TRIAL_FRACTION, AngleDeterminacy, AngleStatus, Determinacy, angle_determinacy, determinacy
from exubio.model.ranges import limit_report
from exubio.types import FrameStatus, MarkerTargets, Model, Protocol, Reconstruction


@dataclass(frozen=True)
class TrialAssessment:
    """Per method: determinacy, limit reports, quality; and the PF-LS agreement (deg RMSE on the
    frames where each coordinate is determined by both), the label findings, the solved mask.
    The calibration enters through assess_trial (its CalibrationReport and the label findings on
    the static trial) as reasons of the verdicts."""

    determinacy: Mapping[str, Determinacy]
    limits: Mapping[str, list]
    quality: Mapping[str, Q.Quality]
    agreement_deg: Mapping[str, float] | None
    labels: tuple
    not_solved: tuple[str, ...]
    angles: Mapping[str, AngleDeterminacy] | None = None  # per method: each anatomical angle's status per frame
    structural: Mapping[str, str] | None = None  # per anatomical angle: what the marker set can do (angle_status_of_protocol)
    mismatch: Mapping[str, MismatchAssessment] | None = None  # per method: model-mismatch evidence (exubio.trust.mismatch)


def trial_label_findings(model: Model, protocol: Protocol, targets: MarkerTargets, /, *, reference: Any = None,
                         expect: tuple[Model, Protocol] | None = None) -> tuple:
    """The label checks of exubio.trust.labels on a prepared trial, against what ``expect`` (the
    generic model and the protocol bound to it: exubio.run.inputs.Session) expects, since a
    calibration registers every marker where the static trial had it, right or wrong; without it,
    against ``model`` and ``protocol`` (a model that is not calibrated). ``reference``: the
    session's static trial's pair distances (exubio.trust.labels.pair_distances)."""
    from exubio.trust.labels import check_trial

    generic, gprot = expect if expect is not None else (model, protocol)
    return check_trial(targets, model=generic, protocol=gprot, ranges_rad=generic.coordinate_ranges_rad,
                       reference=reference)


def _same_finding(f: Any, findings: Sequence) -> bool:
    """A static-trial finding that the trial repeats (same kind and markers) is reported once."""
    kind, markers = Q.finding_field(f, "kind"), set(Q.finding_field(f, "markers", ()))
    return any(Q.finding_field(g, "kind") == kind and set(Q.finding_field(g, "markers", ())) == markers for g in findings)


def not_solved_mask(model: Model, protocol: Protocol, kin: Kinematics | None = None) -> np.ndarray:
    """(m,) True for coordinates neither method solves: held by the protocol, or of a segment no
    marker observes (locked)."""
    kin = kin or Kinematics(model)
    mask = held_mask(model, protocol).copy()
    for s in unobserved_segments(kin, tracked_points(kin, protocol)):
        mask[kin.joint_coordinate_indices(s)] = True
    return mask


def agreement_on_measured(model: Model, a: Reconstruction, da: AngleDeterminacy, b: Reconstruction,
                          db: AngleDeterminacy, /) -> dict[str, float]:
    """PF-LS RMSE (deg) of every anatomical angle over the frames where both measure it (NaN where
    none does)."""
    from exubio.model.angles import anatomical_table

    _, ta = anatomical_table(model, a.q_rad)
    _, tb = anatomical_table(model, b.q_rad)
    d = np.degrees(np.angle(np.exp(1j * (ta - tb))))
    ok = (da.status == AngleStatus.MEASURED) & (db.status == AngleStatus.MEASURED) & np.isfinite(d)
    return {n: (float(np.sqrt(np.mean(d[ok[:, j], j] ** 2))) if ok[:, j].any() else float("nan"))
            for j, n in enumerate(da.names)}


_POSTURES: dict[bytes, np.ndarray] = {}
_POSTURES_SIZE = 8


def reference_postures_of(model: Model, /) -> np.ndarray:
    """exubio.synth.simulate.reference_postures of the model (the q = 0 posture where its girdle cannot be
    driven on the rhythm), computed once per process for a given geometry (it takes ~0.3 s)."""
    from exubio.trust.digest import content_digest as _content_digest
    from exubio.synth.simulate import reference_postures

    try:
        key = _content_digest(model.segments, model.ellipsoid)
    except TypeError:
        key = None
    if key is not None and key in _POSTURES:
        return _POSTURES[key]
    try:
        q = reference_postures(model)
    except Exception:  # noqa: BLE001 - a model whose girdle the rhythm cannot drive: judge the reference posture
        q = np.zeros((1, model.n_coordinates))
    if key is not None:
        if len(_POSTURES) >= _POSTURES_SIZE:
            _POSTURES.pop(next(iter(_POSTURES)))
        _POSTURES[key] = q
    return q


def _scapula_calibrated(calibration: Any) -> bool:
    """The session's calibration fitted the thorax ellipsoid on a scapula trial (or several statics)."""
    if calibration is None:
        return False
    sc = (getattr(calibration, "functional", None) or {}).get("scapula") or {}
    return bool(sc.get("used")) or len(getattr(calibration, "ellipsoid_poses_mm", ()) or ()) > 1


def angle_determinacy_of_protocol(model: Model, protocol: Protocol, /, *, kin: Kinematics | None = None,
                                  bounded: bool = True) -> tuple[AngleDeterminacy, np.ndarray]:
    """(the AngleDeterminacy over the reference postures with every non-optional marker present,
    those postures' humerothoracic elevation (rad)): what angle_status_of_protocol summarises."""
    from exubio.model.angles import humerothoracic_elevation

    kin = kin or Kinematics(model)
    q = reference_postures_of(model)
    present = np.tile([not m.optional for m in protocol.markers], (q.shape[0], 1))
    held = held_mask(model, protocol)
    locked = not_solved_mask(model, protocol, kin) & ~held
    det = angle_determinacy(kin, tracked_points(kin, protocol), q, present, protocol.weights, held=held, locked=locked,
                            bounded=bounded)
    return det, humerothoracic_elevation(model, q, kinematics=kin)


def angle_status_of_protocol(model: Model, protocol: Protocol, /, *, kin: Kinematics | None = None,
                             bounded: bool = True) -> dict[str, str]:
    """What the protocol's markers can do for each anatomical angle, known before any trial: its
    status over the reference postures (exubio.synth.simulate.reference_postures: elevation in three
    planes, HT 10-120 deg) with every non-optional marker present: 'measured' (in every posture),
    'modelled', 'not measured', or 'partly ...' (in some postures). ``bounded=False``: what the markers
    determine alone, without the uncertainty bound and the gimbal margin (observability.angle_determinacy)."""
    return angle_determinacy_of_protocol(model, protocol, kin=kin, bounded=bounded)[0].trial_status()


def coordinates_not_measured_by_protocol(model: Model, protocol: Protocol, /, *,
                                         kin: Kinematics | None = None) -> tuple[str, ...]:
    """The model coordinates the protocol's markers leave undetermined (noise gain above the
    threshold) in most reference postures (exubio.synth.simulate.reference_postures), known before any
    trial: e.g. the clavicle's axial rotation seen by two markers near its axis."""
    kin = kin or Kinematics(model)
    q = reference_postures_of(model)
    present = np.tile([not m.optional for m in protocol.markers], (q.shape[0], 1))
    det = determinacy(kin, tracked_points(kin, protocol), q, present, protocol.weights,
                      excluded=not_solved_mask(model, protocol, kin))
    return tuple(det.trial_undetermined())


DETERMINACY_PERIOD_S = 0.05
"""The noise gains are computed every this many seconds (and copied to the frames between): a
posture changes by a few degrees at most in 50 ms, the gains by less, and it makes the checks
about 10x cheaper at 200 Hz."""


def assess_trial(model: Model, protocol: Protocol, targets: MarkerTargets, recons: Sequence[Reconstruction], /, *,
                 label_findings: Sequence = (), calibration: Any = None, static_labels: Sequence = (),
                 determinacy_every: int | None = None, session: Sequence = (),
                 static_name: str = "", dropped: Sequence[str] = (), partial_swaps: Sequence = (),
                 repaired: bool = False) -> TrialAssessment:
    """Assess the reconstructions ``recons`` of one trial (module docstring). ``session``: the
    segments whose markers look placed anew since the static (exubio.trust.session_check.placed_anew),
    named as a check on the static; ``static_name``: that static trial; ``dropped``: protocol markers
    the trial lacks, left out (exubio.trust.missing_markers): a check naming them; ``partial_swaps``: labels
    exchanged in part of the trial (exubio.trust.label_ranges): a fail, or with ``repaired`` a check that
    says where they were exchanged back. ``calibration``: the session's CalibrationReport
    (exubio.calibration), checked as the verdict's calibration reasons; ``static_labels``: the label
    findings on its static trial (one the trial repeats is named once)."""
    kin = Kinematics(model)
    if determinacy_every is None:
        dt = float(np.median(np.diff(targets.time_s))) if targets.n_frames > 1 else 1.0
        determinacy_every = max(1, int(round(DETERMINACY_PERIOD_S / dt)))
    points = tracked_points(kin, protocol)
    excluded = not_solved_mask(model, protocol, kin)
    names = model.coordinate_names
    not_solved = tuple(n for n, e in zip(names, excluded) if e)
    dets = {r.method: determinacy(kin, points, r.q_rad, targets.present, protocol.weights, excluded=excluded,
                                  every=determinacy_every) for r in recons}
    held = held_mask(model, protocol)
    angles = {r.method: angle_determinacy(kin, points, r.q_rad, targets.present, protocol.weights, held=held,
                                          locked=excluded & ~held, every=determinacy_every,
                                          residuals_m=r.residuals_m) for r in recons}
    structural = angle_status_of_protocol(model, protocol, kin=kin)
    unmeasurable = coordinates_not_measured_by_protocol(model, protocol, kin=kin)
    lims = {r.method: limit_report(r.q_rad, model.coordinate_ranges_rad, names, exclude=not_solved,
                                   ignore=dets[r.method].undetermined & dets[r.method].near_gimbal_lock)
            for r in recons}
    agreement = None
    by = {r.method: r for r in recons}
    if "pf" in by and "ls" in by:
        agreement = agreement_on_measured(model, by["pf"], angles["pf"], by["ls"], angles["ls"])
    off = Q.off_segment_markers(model, protocol) if calibration is not None else {}
    repeated = [f for f in static_labels if _same_finding(f, label_findings)]
    static_labels = [f for f in static_labels if not _same_finding(f, label_findings)]
    named = sorted({m for f in label_findings if Q.finding_field(f, "severity") not in ("info", "note")
                    for m in Q.finding_field(f, "markers", ())})  # their residuals are the label's, not the model's
    mismatch = {r.method: assess_mismatch(kin, points, r.q_rad, targets.positions_m, targets.time_s, skip_markers=named)
                for r in recons}
    quality = {}
    for r in recons:
        status = np.asarray(r.status)
        dt = float(np.median(np.diff(r.time_s))) if r.n_frames > 1 else 1.0
        evidence = Evidence(
            n_frames=r.n_frames, rate_hz=1.0 / dt, label_findings=tuple(label_findings),
            label_findings_in_static=tuple(repeated), static_label_findings=tuple(static_labels),
            calibration=calibration, scale_bounds=SCALE_BOUNDS, off_segment=off,
            accepted_offsets_mm={m.name: m.landmark_offset_mm for m in protocol.markers
                                 if m.landmark_offset_mm is not None},
            not_measured=tuple(unmeasurable), session_shifts=tuple(session), static_name=static_name,
            dropped_markers=tuple(dropped), partial_swaps=tuple(partial_swaps), repaired=repaired,
            residual_mm=residual_statistics(r), per_frame_residual_mm=per_frame_residuals_mm(r)[0],
            limits=[lim.to_dict() for lim in lims[r.method]], angle_status=angles[r.method].trial_status(),
            structural_status=structural, measured_fraction=angles[r.method].fraction(AngleStatus.MEASURED),
            undetermined_trial_fraction=UNDETERMINED_TRIAL_FRACTION, angle_causes=angles[r.method].causes(),
            frames={"not_converged": int((status == FrameStatus.NOT_CONVERGED).sum()),
                    "too_few_markers": int((status == FrameStatus.TOO_FEW_MARKERS).sum())},
            info=r.info, gaps=r.gaps, agreement_deg=agreement, mismatch=mismatch[r.method], protocol=protocol,
            scapula_calibrated=_scapula_calibrated(calibration))
        quality[r.method] = judge(evidence)
    return TrialAssessment(dets, lims, quality, agreement, tuple(label_findings), not_solved, angles, structural,
                           mismatch)
