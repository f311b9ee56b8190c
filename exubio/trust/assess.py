"""Everything measured about one trial's reconstructions to decide whether to trust them: which
coordinates the markers determine (exubio.trust.observability), frames at a range limit
(exubio.model.ranges), PF-LS agreement on determined coordinates, the label checks and the calibration;
turned into one quality verdict per method (exubio.trust.quality). No solver is run here."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from exubio.io.records import to_json
from exubio.trust import quality as Q
from exubio.trust.checks import Evidence, judge
from exubio.calibration import SCALE_BOUNDS
from exubio.trust.evaluate import per_frame_residuals_mm, residual_statistics
from exubio.protocol.bind import Binding
from exubio.trust.label_expectations import expectations_of
from exubio.trust.mismatch import MismatchAssessment, assess_mismatch
from exubio.trust.sta_amplitude import amplitude_of
from exubio.trust.observability import UNDETERMINED_TRIAL_FRACTION, AngleDeterminacy, AngleStatus, Determinacy, angle_determinacy, determinacy
from exubio.model.angles import anatomical_table
from exubio.model.ranges import AT_LIMIT_TOLERANCE_RAD, LimitReport, limit_report
from exubio.types import FrameStatus, MarkerTargets, Model, Reconstruction


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


@dataclass(frozen=True)
class TrialContext:
    """What the verdict weighs of a trial beside its reconstructions: ``label_findings`` (the label
    checks on the trial, trial_label_findings); ``calibration``: the session's CalibrationReport
    (exubio.calibration), checked as the verdict's calibration reasons, and ``static_labels``: the
    label findings on its static trial (one the trial repeats is named once); ``session``: the
    segments whose markers look placed anew since the static (exubio.trust.session_check.placed_anew),
    named as a check on the static ``static_name``; ``dropped``: protocol markers the trial lacks,
    left out (exubio.trust.missing_markers): a check naming them; ``partial_swaps``: labels exchanged
    in part of the trial (exubio.trust.label_ranges): a fail, or with ``repaired`` a check that says
    where they were exchanged back."""

    label_findings: tuple = ()
    calibration: Any = None
    static_labels: tuple = ()
    session: tuple = ()
    static_name: str = ""
    dropped: tuple[str, ...] = ()
    partial_swaps: tuple = ()
    repaired: bool = False


def trial_label_findings(expect: Binding, targets: MarkerTargets, /, *, reference: Any = None) -> tuple:
    """The label checks of exubio.trust.labels on a prepared trial, against what ``expect`` expects:
    the generic model and the protocol bound to it (exubio.run.inputs.Session.generic_binding), since
    a calibration registers every marker where the static trial had it, right or wrong (a model
    that is not calibrated: its own binding). ``reference``: the session's static trial's pair
    distances (exubio.trust.labels.pair_distances)."""
    from exubio.trust.labels import check_trial

    return check_trial(targets, model=expect.model, protocol=expect.protocol,
                       ranges_rad=expect.model.coordinate_ranges_rad, reference=reference,
                       expectations=expectations_of(expect))


def _same_finding(f: Any, findings: Sequence) -> bool:
    """A static-trial finding that the trial repeats (same kind and markers) is reported once."""
    kind, markers = Q.finding_field(f, "kind"), set(Q.finding_field(f, "markers", ()))
    return any(Q.finding_field(g, "kind") == kind and set(Q.finding_field(g, "markers", ())) == markers for g in findings)


def agreement_on_measured(ta: np.ndarray, da: AngleDeterminacy, tb: np.ndarray, db: AngleDeterminacy, /
                          ) -> dict[str, float]:
    """PF-LS RMSE (deg) of every anatomical angle (``ta``, ``tb``: (n, a) rad, the methods' angle
    tables) over the frames where both measure it (NaN where none does)."""
    d = np.degrees(np.angle(np.exp(1j * (ta - tb))))
    ok = (da.status == AngleStatus.MEASURED) & (db.status == AngleStatus.MEASURED) & np.isfinite(d)
    return {n: (float(np.sqrt(np.mean(d[ok[:, j], j] ** 2))) if ok[:, j].any() else float("nan"))
            for j, n in enumerate(da.names)}


def gh_elevation_limit(names: Sequence[str], table: np.ndarray, /) -> list[LimitReport]:
    """The glenohumeral bound the solver's coordinates cannot carry (exubio.trust.quality.GH_ELEVATION_MAX_DEG):
    frames whose GH elevation (``names``, ``table``: an anatomical angle table, rad) reaches it, as a
    limit report on the angle GH_X_elevation (signed as reported: negative is elevation)."""
    if "GH_X_elevation" not in names:
        return []
    e = np.abs(table[:, list(names).index("GH_X_elevation")])
    bound = np.radians(Q.GH_ELEVATION_MAX_DEG)
    at = np.isfinite(e) & (e >= bound - AT_LIMIT_TOLERANCE_RAD)
    if not at.any():
        return []
    beyond = float(np.degrees(np.max(e[at] - bound)))
    return [LimitReport("GH_X_elevation", (-Q.GH_ELEVATION_MAX_DEG, Q.GH_ELEVATION_MAX_DEG), int(at.sum()),
                        int(np.argmax(at)), max(beyond, 0.0))]


def _held(binding: Binding, key: tuple, compute: Any, /, *args: Any, of_model: bool = False) -> Any:
    """The fact ``key`` of the binding: computed here (``compute(binding, *args)``) on first use and
    left on the binding (exubio.protocol.bind.Binding.keep), read from it after."""
    key = (__name__, *key)
    value = binding.fact(key, of_model=of_model)
    return value if value is not None else binding.keep(key, compute(binding, *args), of_model=of_model)


def reference_postures_of(binding: Binding, /) -> np.ndarray:
    """exubio.synth.simulate.reference_postures of the binding's model (the q = 0 posture where its
    girdle cannot be driven on the rhythm), computed once and held by the binding (~0.15 s), shared
    with its model's other bindings (exubio.protocol.bind.Binding.rebound). Read-only."""
    return _held(binding, ("reference_postures",), _reference_postures, of_model=True)


def _reference_postures(binding: Binding) -> np.ndarray:
    from exubio.synth.simulate import reference_postures

    try:
        q = reference_postures(binding.model, kinematics=binding.kin)
    except Exception:  # noqa: BLE001 - a model whose girdle the rhythm cannot drive: judge the reference posture
        q = np.zeros((1, binding.model.n_coordinates))
    q.setflags(write=False)
    return q


def _scapula_calibrated(calibration: Any, model: Model) -> bool:
    """The session's calibration, or the one the model records, fitted the thorax ellipsoid on a scapula
    trial (or several statics): exubio.trust.angle_uncertainty.ellipsoid_from_skin, the rule u follows."""
    from exubio.trust.angle_uncertainty import ellipsoid_from_skin

    return ellipsoid_from_skin(calibration) or ellipsoid_from_skin((model.metadata or {}).get("calibration"))


def angle_determinacy_of_protocol(binding: Binding, /, *, bounded: bool = True) -> tuple[AngleDeterminacy, np.ndarray]:
    """(the AngleDeterminacy over the reference postures with every non-optional marker present,
    those postures' humerothoracic elevation (rad)): what angle_status_of_protocol summarises;
    computed once and held by the binding."""
    return _held(binding, ("angle_determinacy", bool(bounded)), _angle_determinacy_of_protocol, bool(bounded))


def _angle_determinacy_of_protocol(binding: Binding, bounded: bool) -> tuple[AngleDeterminacy, np.ndarray]:
    from exubio.model.angles import humerothoracic_elevation

    kin, protocol = binding.kin, binding.protocol
    q = reference_postures_of(binding)
    present = np.tile([not m.optional for m in protocol.markers], (q.shape[0], 1))
    det = angle_determinacy(kin, binding.points, q, present, protocol.weights, held=binding.held,
                            locked=binding.locked, bounded=bounded, amplitude=amplitude_of(binding) if bounded else None)
    return det, humerothoracic_elevation(binding.model, q, kinematics=kin)


def angle_status_of_protocol(binding: Binding, /, *, bounded: bool = True) -> dict[str, str]:
    """What the protocol's markers can do for each anatomical angle, known before any trial: its
    status over the reference postures (exubio.synth.simulate.reference_postures: elevation in three
    planes, HT 10-120 deg) with every non-optional marker present: 'measured' (in every posture),
    'modelled', 'not measured', or 'partly ...' (in some postures). ``bounded=False``: what the markers
    determine alone, without the uncertainty bound and the gimbal margin (observability.angle_determinacy)."""
    return dict(_held(binding, ("angle_status", bool(bounded)), _angle_status, bool(bounded)))


def _angle_status(binding: Binding, bounded: bool) -> dict[str, str]:
    return angle_determinacy_of_protocol(binding, bounded=bounded)[0].trial_status()


def coordinates_not_measured_by_protocol(binding: Binding, /) -> tuple[str, ...]:
    """The model coordinates the protocol's markers leave undetermined (noise gain above the
    threshold) in most reference postures (exubio.synth.simulate.reference_postures), known before any
    trial: e.g. the clavicle's axial rotation seen by two markers near its axis. Held by the binding."""
    return _held(binding, ("not_measured",), _not_measured)


def _not_measured(binding: Binding) -> tuple[str, ...]:
    q = reference_postures_of(binding)
    present = np.tile([not m.optional for m in binding.protocol.markers], (q.shape[0], 1))
    det = determinacy(binding.kin, binding.points, q, present, binding.protocol.weights, excluded=binding.not_solved)
    return tuple(det.trial_undetermined())


def known_before_trials(binding: Binding, /, *, expect: Binding | None = None) -> None:
    """Compute what the trials' checks read of the bindings alone: the structural angle status and
    the coordinates the markers cannot measure (of ``binding``), the label expectations (of
    ``expect``, the generic binding the labels are checked against; default ``binding``). A study
    does it once per session before its trials go to the workers, which then get them with the
    session instead of each computing them again."""
    angle_status_of_protocol(binding)
    coordinates_not_measured_by_protocol(binding)
    expectations_of(expect if expect is not None else binding)


DETERMINACY_PERIOD_S = 0.05
"""The noise gains are computed every this many seconds (and copied to the frames between): a
posture changes by a few degrees at most in 50 ms, the gains by less, and it makes the checks
about 10x cheaper at 200 Hz."""


def assess_trial(binding: Binding, targets: MarkerTargets, recons: Sequence[Reconstruction], /, *,
                 context: TrialContext = TrialContext(), determinacy_every: int | None = None) -> TrialAssessment:
    """Assess the reconstructions ``recons`` of one trial (module docstring) made with ``binding``
    (the model and protocol: exubio.protocol.bind); ``context``: what else the verdict weighs (the
    label findings, the session's calibration and static trial, markers dropped, labels exchanged:
    TrialContext)."""
    model, protocol, kin = binding.model, binding.protocol, binding.kin
    c = context
    if determinacy_every is None:
        dt = float(np.median(np.diff(targets.time_s))) if targets.n_frames > 1 else 1.0
        determinacy_every = max(1, int(round(DETERMINACY_PERIOD_S / dt)))
    points, excluded, held = binding.points, binding.not_solved, binding.held
    names = model.coordinate_names
    not_solved = binding.not_solved_names
    dets = {r.method: determinacy(kin, points, r.q_rad, targets.present, protocol.weights, excluded=excluded,
                                  every=determinacy_every) for r in recons}
    angles = {r.method: angle_determinacy(kin, points, r.q_rad, targets.present, protocol.weights, held=held,
                                          locked=binding.locked, every=determinacy_every, amplitude=amplitude_of(binding),
                                          residuals_m=r.residuals_m, marker_positions_m=targets.positions_m)
              for r in recons}
    structural = angle_status_of_protocol(binding)
    unmeasurable = coordinates_not_measured_by_protocol(binding)
    label_findings, calibration = c.label_findings, c.calibration
    tables = {r.method: anatomical_table(model, r.q_rad, kinematics=kin) for r in recons}
    lims = {r.method: limit_report(r.q_rad, model.coordinate_ranges_rad, names, exclude=not_solved,
                                   ignore=dets[r.method].undetermined & dets[r.method].near_gimbal_lock)
            + gh_elevation_limit(*tables[r.method])
            for r in recons}
    agreement = None
    if "pf" in tables and "ls" in tables:
        agreement = agreement_on_measured(tables["pf"][1], angles["pf"], tables["ls"][1], angles["ls"])
    off = Q.off_segment_markers(model, protocol) if calibration is not None else {}
    repeated = [f for f in c.static_labels if _same_finding(f, label_findings)]
    static_labels = [f for f in c.static_labels if not _same_finding(f, label_findings)]
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
            not_measured=tuple(unmeasurable), session_shifts=tuple(c.session), static_name=c.static_name,
            dropped_markers=tuple(c.dropped), partial_swaps=tuple(c.partial_swaps), repaired=c.repaired,
            residual_mm=residual_statistics(r), per_frame_residual_mm=per_frame_residuals_mm(r)[0],
            limits=to_json(lims[r.method]), angle_status=angles[r.method].trial_status(),
            structural_status=structural, measured_fraction=angles[r.method].fraction(AngleStatus.MEASURED),
            undetermined_trial_fraction=UNDETERMINED_TRIAL_FRACTION, angle_causes=angles[r.method].causes(),
            frames={"not_converged": int((status == FrameStatus.NOT_CONVERGED).sum()),
                    "too_few_markers": int((status == FrameStatus.TOO_FEW_MARKERS).sum())},
            info=r.info, gaps=r.gaps, agreement_deg=agreement, mismatch=mismatch[r.method], protocol=protocol,
            scapula_calibrated=_scapula_calibrated(calibration, model))
        quality[r.method] = judge(evidence)
    return TrialAssessment(dets, lims, quality, agreement, tuple(label_findings), not_solved, angles, structural,
                           mismatch)
