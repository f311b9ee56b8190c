"""Calibrate a generic model to a subject from a static pose: segment scaling, model-point
registration and the thorax ellipsoid.

Input: a trial (a static trial, or a chosen frame range of any trial when the lab has no static
trial), the protocol and the generic model. The static pose is the mean of the chosen frames of
the protocol markers in the ISB thorax frame (``prepare_targets``: same labels, thorax frame and
filter as a reconstruction). Without ``frames`` the longest still stretch of the trial is used
(every marker slower than ``STILL_SPEED_M_S``).

Algorithm
---------
1. Thorax scale: the ratio of the measured to the model distances between the thorax landmarks
   that build the thorax frame (least squares over the six pairs). Not measurable when the
   protocol's thorax frame is the identity: then 1.
2. Anatomical fit of the scaled generic model (the anchor). The generic model points of the
   markers, scaled with their segments, are fitted to the static markers over the static pose q
   (all 13 coordinates; the ellipsoid constraint is *off*, so that the generic ellipsoid does not
   bias the girdle) and one isotropic scale factor per scale group (clavicle, scapula, humerus,
   forearm = ulna + radius, hand; a group without markers keeps 1). First q alone from several
   start postures at once (arm down, abducted, flexed, rotated; elbow extended or flexed), then q
   and the scale factors together by Levenberg-Marquardt (for fixed rotations a model point is
   linear in the scale factors: a segment's factor scales its points and its children's
   joint-centre offsets, which gives that part of the Jacobian exactly). Weak priors keep the
   scale factors near 1 (bounded to 0.7-1.4) and the clavicle/scapula angles near the reference
   posture where the markers leave them undetermined. The weights are the protocol weights times
   robust Cauchy weights 1 / (1 + (d / 20 mm)^2) of each marker's residual d, iterated
   (iteratively reweighted least squares, the 20 mm reached by annealing from 100 mm so that a
   rough first pose discards nothing): a marker that the lab placed (or labelled) differently
   from the generic model, e.g. an acromion-cluster marker, is down-weighted instead of dragging
   the pose. Only this step decides the static pose, i.e. where the anatomical segment frames
   are: the registration below cannot, since a freely registered marker fits any pose.
3. Registration: every marker present in the chosen frames gets its static position as its local
   position on its segment, l = R_seg(q)^T (m - p_seg(q)), under the model point its protocol
   entry names (``point:``), or, for markers given by ``local_position_mm``, under the marker's
   own name. Joint centres are never moved: the skeleton is what step 2 fitted, and a marker tied
   to a joint centre (e.g. a virtual glenohumeral-centre marker on point GH) is registered as a
   point named after the marker. A marker tied to an ellipsoid contact point moves the contact
   point (the ellipsoid is fitted to it next). ``calibrated_protocol`` binds a protocol to the
   registered points (the model file records which point each marker was registered under).
4. Ellipsoid: centre and radii scale with the thorax; then its centre moves in the sagittal plane
   and its radii scale by a common factor (keeping their ratios), with the least change (10 % of
   radius weighted like 30 mm of centre: a thorax of another depth moves the surface rather than
   inflating it), until both contact points lie on it at the static pose (Newton, |g| < 1e-12).

What is reported (and stored under ``calibration`` in the written model), per marker:

* ``residual_mm`` -- the calibration residual: the RMS over the calibration frames of the
  distance between the marker and its model point on the calibrated model, each frame solved
  with the constrained least-squares method. It says how well the calibrated model, rigid and
  on its ellipsoid, reproduces the calibration frames (noise, sway, skin motion within them). It
  is not a validation of the registration: registered at the mean pose, it is small by
  construction; the residuals of the dynamic trials are that validation.
* ``generic_offset_mm`` -- the distance from the scaled generic model point to the registered
  one: the residual of the scaled generic model at the static pose (step 2, what OpenSim's scale
  tool reports as its marker error). Large values flag markers placed or labelled differently from
  the generic model; ``fit_weight`` is the robust weight the marker had in step 2.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from exubio.calibration.ellipsoid import fit_ellipsoid, fit_ellipsoid_poses, surface_distance
from exubio.calibration.joint_centres import functional_gh, gh_joint
from exubio.calibration.posefit import (ARM_PRIOR_M2_PER_RAD2, GIRDLE_PRIOR_M2_PER_RAD2, GIRDLE_SEGMENTS,
    MAX_REWEIGHTING, ROBUST_SCALE_M, _Anchor, _at_limit, _fit_pose, _start_postures, best_start)
from exubio.calibration.registration import _register, calibrated_protocol, marker_point_names
from exubio.calibration.report import CalibrationReport, MarkerCalibration
from exubio.calibration.scaling import DEFAULT_SCALE_GROUPS, _groups, _thorax_scale, scale_model
from exubio.calibration.window import _nanmean, _window
from exubio.errors import InputError, ReconstructionError
from exubio.model.kinematics import Kinematics
from exubio.types import StopReason
from exubio.protocol.bind import tracked_points
from exubio.methods.poses import Limits, LSOptions, solve_positions
from exubio.prep.targets import prepare_targets
from exubio.model.ranges import DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD
from exubio.types import MarkerTargets, Model, Protocol, Trajectories

log = logging.getLogger(__name__)

RESIDUAL_FRAMES = 60  # the calibration residual is measured on at most this many frames



TECHNICAL_POSE_WEIGHT = 1.0
"""Relative weight in the static-pose fit of a marker that is not placed over a bony landmark
(protocol key ``landmark``), when the protocol declares landmarks; the members of a rigid cluster
(key ``cluster``) share it, the cluster counting as one marker. 1: every marker counts alike (with
its robust weight). A landmark-driven pose (0.1: technical markers only break ties) was measured
and is worse on every real trial: same-session LS residual F0_boire_05 6.3 -> 10.2 mm,
martin_dynamique 8.3 -> 9.4, kinova dent 8.2 -> 8.5, tete 6.4 -> 6.7 (the landmark markers are skin
markers too, and two or three of them per segment leave the pose to their own placement errors)."""


FUNCTIONAL_MAX_SHIFT_M = 0.03
"""A functional (SCoRE) glenohumeral centre farther than this from the one the anatomical fit
places from the scapula and humerus markers is not used (it is reported, with the reason). Each
estimate is good to about 10-20 mm with skin markers (regressions and functional methods alike:
the TRC subject's SCoRE centre is 3-9 mm from its own model's, the anatomical fit's 7-8 mm,
studies/calibration_trc_vs_tsm.py); 30 mm apart, one of them is wrong, and a functional centre
from skin clusters that slide over the deltoid (SCoRE RMS 10 mm on martin_dynamique, 50 mm away)
is the likelier one."""


FUNCTIONAL_MAX_PASSES = 10
FUNCTIONAL_TOL_M = 1e-4  # the calibrated centre within 0.1 mm of the functional one at the static pose


def pose_weights(protocol: Protocol, /) -> np.ndarray:
    """Each protocol marker's relative weight in the static-pose fit: 1 for landmark markers,
    TECHNICAL_POSE_WEIGHT for the others, split among a cluster's members; all 1 when the
    protocol declares no landmark."""
    markers = protocol.markers
    if not any(m.landmark for m in markers):
        return np.ones(len(markers))
    size = {}
    for m in markers:
        if m.cluster:
            size[m.cluster] = size.get(m.cluster, 0) + 1
    return np.array([1.0 if m.landmark else TECHNICAL_POSE_WEIGHT / size.get(m.cluster, 1) for m in markers])


@dataclasses.dataclass(frozen=True)
class _FitOutcome:
    """How the anatomical fit ended: the reweighting iterations, why the last joint fit of pose
    and scales stopped (exubio.types.StopReason), and whether the robust weights settled
    (CONVERGED) or still changed after MAX_REWEIGHTING iterations (MAX_ITERATIONS)."""

    iterations: int
    final_fit: StopReason
    reweighting: StopReason


def _robust_fit(anchor: _Anchor, q: np.ndarray, factors: dict[str, float], w: np.ndarray, static: np.ndarray,
                src: str) -> tuple[np.ndarray, dict[str, float], np.ndarray, _FitOutcome]:
    """Iteratively reweighted joint fit of pose and scales; the robust scale is annealed from
    100 mm to ROBUST_SCALE_M so that the first, rough poses do not discard markers a better pose
    would fit. Returns (q, factors, robust weights, how it ended)."""
    robust = np.ones(len(w))
    it, change, stop, settled = 0, 0.0, StopReason.MAX_ITERATIONS, StopReason.CONVERGED
    for it in range(1, MAX_REWEIGHTING + 1):
        q, factors, cost, stop = anchor.fit(q, factors, w * robust)
        kin, pts = anchor.points(factors)
        d = np.linalg.norm(kin.points(q, pts) - np.where(np.isnan(static), 0, static), axis=1)
        c = max(ROBUST_SCALE_M, 0.1 * 0.7 ** (it - 1))
        new = 1.0 / (1.0 + (d / c) ** 2)
        log.debug("calibration fit %d: cost %.4g (%s), robust scale %.0f mm, scales %s", it, cost, stop.label,
                  c * 1000, {g: round(v, 4) for g, v in factors.items()})
        change = float(np.abs(new - robust).max())
        robust = new
        if c == ROBUST_SCALE_M and change < 1e-3:
            break
    else:
        log.warning("%s: the robust weights of the anatomical fit still changed by %.1e after %d iterations",
                    src, change, MAX_REWEIGHTING)
        settled = StopReason.MAX_ITERATIONS
    if not stop.converged:
        log.warning("%s: the final fit of the static pose and the scale factors stopped before converging (%s)",
                    src, stop.label)
    return q, factors, robust, _FitOutcome(it, stop, settled)


def _use_functional_gh(anchor: _Anchor, model: Model, protocol: Protocol, functional: MarkerTargets,
                       static: np.ndarray, q: np.ndarray, factors: dict[str, float], w: np.ndarray, src: str,
                       robust: np.ndarray, outcome: _FitOutcome):
    """Put the model's glenohumeral centre where SCoRE finds it in the functional trial (at the
    static pose, relative to the scapula of the anatomical fit) and fit pose and scales again.
    A functional trial whose motion does not determine the centre is reported and not used."""
    fsrc = functional.source or "functional trial"
    try:
        gh_static, fc = functional_gh(model, protocol, functional, static)
    except InputError as exc:
        log.warning("%s", exc)
        return q, factors, robust, outcome, anchor, model, {"gh": {"used": False, "trial": fsrc, "reason": str(exc)}}
    humerus = gh_joint(model)
    seg_factors = anchor.segment_factors(factors)
    scaled = scale_model(model, seg_factors)
    fr = Kinematics(scaled).frames(q)
    ih, ip = model.segment_index(humerus), model.segment_index(model.segment(humerus).parent)
    gh_fit = fr.p[ih].copy()
    shift = float(np.linalg.norm(gh_static - gh_fit))
    if shift > FUNCTIONAL_MAX_SHIFT_M:
        reason = (f"{fsrc}: SCoRE puts the glenohumeral centre {shift * 1000:.0f} mm from where the scapula and "
                  f"humerus markers put it (more than {FUNCTIONAL_MAX_SHIFT_M * 1000:.0f} mm; SCoRE RMS "
                  f"{fc.rms_m * 1000:.1f} mm): skin motion of the cluster markers, or too little motion; not used")
        log.warning("%s", reason)
        return q, factors, robust, outcome, anchor, model, {"gh": {"used": False, "trial": fsrc, "reason": reason,
                                                              **fc.to_dict(), "shift_from_marker_fit_mm": round(shift * 1000, 2)}}
    # the centre is fixed to the scapula where the static pose puts it; refitting the pose moves the
    # scapula a little, so place it again until it stays where SCoRE found it (fixed point)
    miss = math.inf
    for _ in range(FUNCTIONAL_MAX_PASSES):
        local = fr.R[ip].T @ (gh_static - fr.p[ip]) / seg_factors[model.segments[ip].name]
        model = dataclasses.replace(model, segments=tuple(
            dataclasses.replace(s, joint=dataclasses.replace(s.joint, centre_m=local)) if s.name == humerus else s
            for s in model.segments))
        anchor = dataclasses.replace(anchor, model=model)
        q, factors, robust, outcome = _robust_fit(anchor, q, factors, w, static, src)
        seg_factors = anchor.segment_factors(factors)
        fr = Kinematics(scale_model(model, seg_factors)).frames(q)
        miss = float(np.linalg.norm(fr.p[ih] - gh_static))
        if miss < FUNCTIONAL_TOL_M:
            break
    info = {"gh": {"used": True, "trial": fsrc, **fc.to_dict(), "final_miss_mm": round(miss * 1000, 3),
                   "centre_static_mm": [round(float(v) * 1000, 2) for v in gh_static],
                   "shift_from_marker_fit_mm": round(float(np.linalg.norm(gh_static - gh_fit)) * 1000, 2)}}
    log.info("%s: glenohumeral centre from SCoRE on %s, %.1f mm from the marker fit's", src, fsrc,
             info["gh"]["shift_from_marker_fit_mm"])
    return q, factors, robust, outcome, anchor, model, info


def calibrate_model(model: Model, protocol: Protocol, trajectories: Trajectories, /, *,
                    frames: slice | None = None, scale_groups: Mapping[str, str] = DEFAULT_SCALE_GROUPS,
                    targets: MarkerTargets | None = None, functional: MarkerTargets | None = None,
                    more_statics: Sequence[MarkerTargets] = (),
                    scapula_motion: MarkerTargets | Sequence[MarkerTargets] | None = None
                    ) -> tuple[Model, CalibrationReport]:
    """Calibrate ``model`` (generic) to the subject of ``trajectories`` (see the module docstring).

    frames: the frames of the trial that hold the static pose (their mean is used); None = the
        longest still stretch. targets: the trial's prepared targets, if already computed with
        ``prepare_targets(trajectories, protocol)``. functional: the prepared targets of a
        movement trial of the same session (same protocol): the glenohumeral centre is then
        found by SCoRE (``exubio.calibration.joint_centres``) instead of from the generic
        model's place relative to the scapula markers; a trial whose motion does not determine
        it is reported (``report.functional``) and not used. more_statics: the prepared targets of
        further static poses of the session (e.g. arm raised; each one's longest still stretch is
        used): the thorax ellipsoid is then fitted through the scapula contact points of every
        pose (least squares) instead of through the main static's alone
        (``report.ellipsoid_poses_mm``: each pose's largest contact-point distance from it).
        scapula_motion: the prepared targets of a movement trial of the session (the arm raised in
        one or more planes): the thorax ellipsoid is then fitted through the scapula contact points
        of the static pose(s) and of every posture of the movement
        (``exubio.calibration.scapula_motion``; ``report.functional["scapula"]``: what was fitted,
        residuals, coverage); a movement that cannot determine it is reported there with the
        reason and the static ellipsoid is kept. Several movement trials: their postures pooled.
    Returns the calibrated model (its ``metadata["calibration"]`` holds ``report.to_dict()``) and
    the report. The protocol's markers must reference the model (segment names); reconstruct with
    ``calibrated_protocol(protocol, calibrated)`` or reload the protocol with the calibrated
    model's points.
    """
    src = trajectories.source or "trial"
    if targets is None:
        targets = prepare_targets(trajectories, protocol)
    window, auto = _window(targets, frames)
    idx = list(window)
    static = _nanmean(targets.positions_m[idx], axis=0)  # (k, 3) the static pose
    with np.errstate(invalid="ignore"):  # how much each marker moves within the window (RMS, m)
        spread = np.sqrt(_nanmean(((targets.positions_m[idx] - static) ** 2).sum(axis=2), axis=0))
    present = np.isfinite(static).all(axis=1)
    for j, m in enumerate(protocol.markers):
        if not present[j] and not m.optional:
            raise InputError(f"{src}: marker '{m.name}' has no sample in the calibration frames "
                             f"{window.start}:{window.stop}; choose other frames")
    _refuse_mostly_missing(targets, protocol, idx, src)
    if present.sum() < 5:
        raise InputError(f"{src}: only {int(present.sum())} protocol markers in the calibration frames; need at least 5")

    group_of = _groups(model, scale_groups)
    thorax_name = model.segments[0].name
    st = _thorax_scale(model, protocol, trajectories, window)
    fixed = {group_of[thorax_name]: 1.0 if st is None else st}
    # groups without a marker (or a child carrying one) are not measured: they keep factor 1
    names = model.segment_names
    seg_index = np.array([names.index(m.segment) for m in protocol.markers])
    carriers = set()
    for s in seg_index[present]:
        carriers.add(group_of[names[s]])
    for g in set(group_of.values()):
        if g not in carriers:
            fixed.setdefault(g, 1.0)
    local_generic = np.array([np.asarray(m.local_position_m, dtype=float) for m in protocol.markers])
    w_protocol = np.where(present, protocol.weights, 0.0) * pose_weights(protocol)
    coord_segment = Kinematics(model).coordinate_segment
    prior = np.array([GIRDLE_PRIOR_M2_PER_RAD2 if names[coord_segment[j]] in GIRDLE_SEGMENTS else ARM_PRIOR_M2_PER_RAD2
                      for j in range(model.n_coordinates)])

    limits = Limits.of(model, protocol, DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD)
    held = np.array([n in protocol.held_coordinates for n in model.coordinate_names], dtype=bool)
    anchor = _Anchor(model=model, seg_index=seg_index, local_generic=local_generic, target=static,
                     groups=list(dict.fromkeys(group_of.values())), group_of=group_of, fixed=fixed, prior_q=prior,
                     limits=limits, held=held)
    factors = {g: fixed.get(g, 1.0) for g in anchor.groups}
    # start posture: several at once, pose only, generic scale factors
    kin, pts = anchor.points(factors)
    q, start_stop = best_start(_fit_pose(kin, pts, static, w_protocol, _start_postures(model), prior, limits=limits,
                                         held=held))
    q, factors, robust, outcome = _robust_fit(anchor, q, factors, w_protocol, static, src)
    functional_info: dict = {}
    if functional is not None:
        q, factors, robust, outcome, anchor, model, functional_info = _use_functional_gh(
            anchor, model, protocol, functional, static, q, factors, w_protocol, src, robust, outcome)
    kin, pts = anchor.points(factors)
    seg_factors = anchor.segment_factors(factors)
    scaled = scale_model(model, seg_factors)
    generic_at_static = kin.points(q, pts)
    point_names = marker_point_names(protocol, model)

    # registered: the static marker; absent (optional) markers keep their scaled generic position,
    # written under their point name when the model has no such point yet
    regs = [(m.segment, point_names[m.name], static[j] if present[j] else generic_at_static[j])
            for j, m in enumerate(protocol.markers)
            if present[j] or point_names[m.name] not in model.segment(m.segment).points]
    calibrated = _register(scaled, q, regs)

    kin_c = Kinematics(calibrated)
    contacts = kin_c.points(q, kin_c.contacts)
    cal_protocol = calibrated_protocol(protocol, calibrated, point_names=point_names)
    pose_contacts, pose_sources = [contacts], [src]
    fit_stop = {"start_pose": start_stop.label, "pose_and_scales": outcome.final_fit.label,
                "reweighting": outcome.reweighting.label}
    static_poses = [static]
    for extra in more_statics:
        q_k, stop_k = _extra_static_pose(kin_c, cal_protocol, extra, prior, limits, held)
        static_poses.append(_nanmean(extra.positions_m[list(_window(extra, None)[0])], axis=0))
        pose_contacts.append(kin_c.points(q_k, kin_c.contacts))
        name = extra.source or "static pose"  # two statics of one name (or none) stay two poses of the report
        pose_sources.append(name if name not in pose_sources else f"{name} ({len(pose_sources) + 1})")
        fit_stop[f"pose of {pose_sources[-1]}"] = stop_k.label
    if len(pose_contacts) == 1:
        ellipsoid, k_ell = fit_ellipsoid(calibrated.ellipsoid, contacts)
    else:
        ellipsoid, k_ell = fit_ellipsoid_poses(calibrated.ellipsoid, np.concatenate(pose_contacts))
    calibrated = dataclasses.replace(calibrated, ellipsoid=ellipsoid)
    if scapula_motion is not None:
        ellipsoid, functional_info = _use_scapula_motion(calibrated, cal_protocol, static_poses, scapula_motion,
                                                         functional_info)
        calibrated = dataclasses.replace(calibrated, ellipsoid=ellipsoid)
    kin_c = Kinematics(calibrated)
    g_abs = float(np.abs(kin_c.g(q)).max())
    ellipsoid_poses = {name: round(float(np.abs(surface_distance(ellipsoid, c)).max() * 1000), 3)
                       for name, c in zip(pose_sources, pose_contacts)}

    residual = _calibration_residuals(kin_c, cal_protocol, targets, idx, q)
    markers = []
    for j, m in enumerate(protocol.markers):
        p = point_names[m.name]
        local = np.array(calibrated.segment(m.segment).points[p], dtype=float)
        markers.append(MarkerCalibration(
            name=m.name, segment=m.segment, point=p, local_position_m=local, registered=bool(present[j]),
            residual_mm=float(residual[j]) if present[j] else float("nan"),
            generic_offset_mm=float(np.linalg.norm(generic_at_static[j] - static[j]) * 1000) if present[j] else float("nan"),
            fit_weight=float(robust[j]) if present[j] else 0.0))
    report = CalibrationReport(
        source=trajectories.source, frames=(window.start, window.stop, window.step), frames_chosen_automatically=auto,
        rate_hz=float(trajectories.rate_hz), body_mass_kg=float(model.body_mass_kg), generic_model=model.source or model.name,
        protocol=protocol.source or protocol.name,
        scale_factors={s: float(v) for s, v in seg_factors.items()}, thorax_scale_measured=st is not None,
        static_q_rad=q.copy(), coordinate_names=model.coordinate_names,
        ellipsoid_centre_m=np.array(ellipsoid.centre_m), ellipsoid_radii_m=np.array(ellipsoid.radii_m),
        ellipsoid_scale=k_ell, constraint_abs=g_abs, markers=tuple(markers), fit_iterations=outcome.iterations,
        fit_stop=fit_stop,
        ellipsoid_poses_mm=ellipsoid_poses,
        window_motion_mm={m.name: float(spread[j] * 1000) for j, m in enumerate(protocol.markers) if present[j]},
        static_pose_at_limit_deg=_at_limit(q, model),
        functional=functional_info, joint_centres_mm=_joint_centres_mm(calibrated, q),
        landmark_offsets_mm=_landmark_offsets_mm(calibrated, protocol, point_names, present))
    _check_finite(report, f"{src} frames {window.start}:{window.stop}")
    stem = Path(trajectories.source).stem if trajectories.source else "subject"
    calibrated = dataclasses.replace(
        calibrated, name=f"{model.name}_calibrated_{stem}",
        source=f"{model.source or model.name} calibrated on {src} frames {window.start}:{window.stop}",
        metadata={**dict(model.metadata), "calibration": report.to_dict(), "generic_source": model.source})
    log.info("%s: calibrated on frames %d:%d; residual mean %.2f mm; generic offsets mean %.1f mm",
             src, window.start, window.stop, report.mean_residual_mm,
             float(np.mean(list(report.generic_offset_mm.values()))))
    return calibrated, report


def _check_finite(report: CalibrationReport, where: str, /) -> None:
    """Raise ReconstructionError naming the first number of the calibration that is not finite (a
    NaN carried on into every reconstruction of the session: PF diverged at t = 0 on one whose
    residual printed "mean nan mm"): the static pose, scale factors, joint centres, ellipsoid, each
    registered marker's place and residual."""
    checks: list[tuple[str, object]] = []
    checks += [(f"static pose coordinate {n}", v) for n, v in zip(report.coordinate_names, report.static_q_rad)]
    checks += [(f"scale factor of {s}", v) for s, v in report.scale_factors.items()]
    checks += [(f"joint centre {j}", v) for j, v in report.joint_centres_mm.items()]
    checks += [("ellipsoid centre", report.ellipsoid_centre_m), ("ellipsoid radii", report.ellipsoid_radii_m),
               ("ellipsoid scale", report.ellipsoid_scale), ("constraint residual |g|", report.constraint_abs)]
    for m in report.markers:
        if m.registered:
            checks += [(f"marker {m.name}'s registered position on the {m.segment}", m.local_position_m),
                       (f"marker {m.name}'s calibration residual", m.residual_mm),
                       (f"marker {m.name}'s offset from its generic place", m.generic_offset_mm)]
    for what, value in checks:
        values = np.asarray(value, dtype=float)
        if not np.isfinite(values).all():
            raise ReconstructionError(
                f"calibration on {where}: the {what} is not a finite number ({np.round(values, 6).tolist()}); the "
                f"calibration cannot be used (markers missing or degenerate in those frames? choose other frames "
                f"with --static-frames)")


def _use_scapula_motion(model: Model, protocol: Protocol, statics: list[np.ndarray],
                        movement: MarkerTargets | Sequence[MarkerTargets], functional_info: dict):
    """The ellipsoid fitted through the scapula postures of ``movement`` and the static pose(s)
    (exubio.calibration.scapula_motion), and ``functional_info`` with its summary under "scapula";
    a movement that cannot determine it keeps the model's ellipsoid, with the reason."""
    from exubio.calibration.scapula_motion import fit_scapula_motion

    info = dict(functional_info)
    try:
        fit = fit_scapula_motion(model, protocol, statics, movement)
    except InputError as exc:
        log.warning("%s; the thorax ellipsoid stays the static calibration's", exc)
        sources = [movement] if isinstance(movement, MarkerTargets) else list(movement)
        info["scapula"] = {"used": False, "trial": " + ".join(t.source or "scapula trial" for t in sources),
                           "reason": str(exc)}
        return model.ellipsoid, info
    info["scapula"] = fit.to_dict()
    return fit.ellipsoid, info


def _extra_static_pose(kin: Kinematics, protocol: Protocol, targets: MarkerTargets, prior: np.ndarray,
                       limits, held: np.ndarray) -> tuple[np.ndarray, StopReason]:
    """The pose of a further static trial on the calibrated model (its registered points, no
    ellipsoid constraint, inside the ranges, held coordinates at 0), from the usual start postures,
    and why its fit stopped."""
    window, _ = _window(targets, None)
    static = _nanmean(targets.positions_m[list(window)], axis=0)
    present = np.isfinite(static).all(axis=1)
    if present.sum() < 5:
        raise InputError(f"{targets.source or 'static pose'}: only {int(present.sum())} protocol markers in its still "
                         f"frames; need at least 5")
    w = np.where(present, protocol.weights, 0.0)
    return best_start(_fit_pose(kin, tracked_points(kin, protocol), static, w, _start_postures(kin.model), prior,
                                limits=limits, held=held))


def _joint_centres_mm(model: Model, q: np.ndarray) -> dict[str, list[float]]:
    """Every joint centre (named by its joint) in the thorax frame at the static pose (mm)."""
    p = Kinematics(model).frames(q).p
    return {s.joint.name: [round(float(v) * 1000, 2) for v in p[i]] for i, s in enumerate(model.segments)
            if s.joint is not None}


def _landmark_offsets_mm(model: Model, protocol: Protocol, point_names: Mapping[str, str],
                         present: np.ndarray) -> dict[str, float]:
    """Distance (mm) of each registered landmark marker from the landmark it is placed over, on the
    calibrated model: skin, soft tissue and the marker's radius (about 10-20 mm), unless the
    marker is misplaced or the static pose is wrong."""
    out = {}
    for j, m in enumerate(protocol.markers):
        if m.landmark and present[j]:
            pts = model.segment(m.segment).points
            if m.landmark in pts and point_names[m.name] in pts:
                out[m.name] = round(float(np.linalg.norm(np.asarray(pts[point_names[m.name]]) - pts[m.landmark])) * 1000, 2)
    return out


def _calibration_residuals(kin: Kinematics, protocol: Protocol, targets: MarkerTargets, idx: list[int],
                           q_static: np.ndarray) -> np.ndarray:
    """Per-marker RMS (mm) over (at most RESIDUAL_FRAMES of) the calibration frames, each frame
    solved with the constrained LS on the calibrated model."""
    sel = np.array(idx)
    if sel.size > RESIDUAL_FRAMES:
        sel = sel[np.unique(np.linspace(0, sel.size - 1, RESIDUAL_FRAMES).round().astype(int))]
    pts = tracked_points(kin, protocol)
    tgt = targets.positions_m[sel]
    dt = float(np.median(np.diff(targets.time_s))) if targets.n_frames > 1 else 1.0
    q = solve_positions(kin, pts, tgt, protocol.weights, q_start=q_static, options=LSOptions(), frame_dt=dt)[0]
    d = np.linalg.norm(kin.points(q, pts) - tgt, axis=2) * 1000.0
    return np.sqrt(_nanmean(d * d, axis=0))



MOSTLY_MISSING_SHARE = 0.5
"""A marker with a sample in fewer than this share of the calibration frames is refused as missing:
its static place would rest on a few samples (a static whose marker had 3 samples in 272 frames
gave a calibration residual of "nan")."""


def _refuse_mostly_missing(targets: MarkerTargets, protocol: Protocol, idx: Sequence[int], src: str, /) -> None:
    """InputError naming a non-optional marker that the calibration frames mostly lack, with the
    frames of the whole trial where it is there."""
    have = targets.present[list(idx)].sum(axis=0)
    for j, m in enumerate(protocol.markers):
        if m.optional or have[j] >= MOSTLY_MISSING_SHARE * len(idx):
            continue
        where = np.flatnonzero(targets.present[:, j])
        shown = ", ".join(str(int(f)) for f in where[:5]) + (", ..." if where.size > 5 else "")
        raise InputError(
            f"{src}: marker '{m.name}' is missing: it has a sample in {int(have[j])} of the {len(idx)} calibration "
            f"frames {idx[0]}:{idx[-1] + 1} ({where.size} of the trial's {targets.n_frames} frames: {shown}); a "
            f"static place cannot rest on so few samples. Check its label in the static (a typo, a marker labelled "
            f"only in a few frames), or calibrate on frames where it is present (--static-frames A:B)")
