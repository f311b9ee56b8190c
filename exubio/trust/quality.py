"""The quality verdict of a reconstruction: ``ok``, ``check`` or ``fail`` with the reasons.

A wrong result must never look right: every criterion below is measured, every threshold lives
here with the reason for its value, and each reason names the marker, coordinate or frame it is
about. ``fail``: the result is wrong or meaningless as it stands (a label swap, markers far from
any posture of the model, a calibration on a marker that is not on its segment); the CLI exits
with code 1. ``check``: the result may be right but something a reader must look at first.
``note``: reported, does not change the verdict. Pure numpy on results; no solver.
"""
from __future__ import annotations

from functools import partial

from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from exubio.types import Severity, StopReason, Verdict

# ---------------------------------------------------------------------------------- thresholds
RESIDUAL_MEAN_MM = (20.0, 40.0)
"""Trial mean marker residual (check, fail). Skin-marker models of the shoulder fit real trials
with mean residuals of about 5-15 mm (the paper's Table 1: 8-18 mm per frame with a generic model;
OpenSim IK 8-9 mm RMS on the TRC trials); twice that means the model or the labels are wrong."""

MARKER_RMSE_MM = (30.0, 60.0)
"""One marker's RMSE over the trial (check, fail). Soft-tissue artefact of shoulder and arm
markers reaches 10-30 mm (Cappozzo et al. 1996; Matsui et al. 2006, J Biomech 39:1190); beyond 30
mm the marker is misplaced or mislabelled, beyond 60 mm it cannot be on its segment."""

FRAME_RESIDUAL_MM = 30.0
FRAME_RESIDUAL_FRACTION = 0.05
"""Frames whose mean residual exceeds FRAME_RESIDUAL_MM: more than this fraction of the trial is a
'check' (a stretch the model cannot follow: a marker falling off, a label swap mid-trial)."""

AGREEMENT_DEG = (2.0, 10.0)
"""PF-LS RMSE on a determined coordinate (frames where it is determined), when both ran (check,
fail). Both methods minimise the same spring potential; on correct data they agree within about
1 deg (noise, PF's inertial lag); a larger difference means one of them followed another local
minimum or the coordinate is poorly determined."""

LIMIT_BEYOND_DEG = 5.0
"""A solved coordinate at its range limit is a 'check'; pushed more than this beyond it (the limit
potential overpowered by the markers) is a 'fail': the markers describe an impossible posture."""

GH_ELEVATION_MAX_DEG = 150.0
"""The glenohumeral joint's bound, on the one angle that carries one whatever the sequence: GH elevation,
the angle between the scapula's and the humerus's long axes (the middle angle of ISB's Y-X'-Y'').
The solver's gh_abduction and gh_flexion have no range (models/upper_extremity.yaml, note [13]: near
the X-Y'-Z'' sequence's gimbal lock at +-90 deg of axial rotation they take any value in physiological
postures). Bone pins reach 120-130 deg at maximal arm elevation (Ludewig et al. 2009); the bound adds
the model's margin for skin artefact and for the reference posture, as the coordinates' upper limit
had it (150). Reached: a 'check'; more than LIMIT_BEYOND_DEG beyond: a 'fail' (the markers describe a
humerus no shoulder can hold: a label, or a marker on the wrong segment)."""

NOT_CONVERGED_FRACTION = (0.01, 0.10)
"""Frames not converged or with too few markers (check, fail)."""

WINDOW_MOTION_MM = 5.0
"""Calibration window: a marker moving more than this RMS about its mean means the 'static'
window moves (quiet standing sways 1-3 mm), so the calibrated geometry is smeared."""

SCALE_AT_BOUND = 0.01
"""A calibration scale factor within this of its bound (exubio.calibration.SCALE_BOUNDS) means the
subject does not fit the model: another subject's static, or a swapped label."""

OFF_SEGMENT_MARGIN_M = 0.06
"""A marker registered farther than this (skin, soft tissue and marker base) outside the sphere
that holds its segment's anatomical points cannot be on that segment: a mislabelled marker."""

LANDMARK_ACCEPT_MARGIN_MM = 15.0
"""Above a protocol's accepted landmark distance (``landmark_offset_mm``), the margin before the
calibration names the marker again: subjects and placements of one lab vary by about 10-15 mm (the
clavicle marker of the shared C3D subject: 64-71 mm over its trials)."""

LANDMARK_OFFSET_MM = 40.0
"""A marker declared over a bony landmark (protocol key ``landmark``) registered farther than this
from the calibrated landmark: skin, soft tissue and the marker's radius put it 10-25 mm away, the
generic landmark's place on a scaled segment up to ~15 mm more; beyond, the marker is misplaced,
mislabelled, or the static pose is wrong."""

GAP_NOTE_FRACTION = 0.05
"""A marker missing in more than this fraction of the frames is named on page 1 (a note: the
gap is handled, its spring or LS term is off there, and the determinacy check says whether the
remaining markers still determine every coordinate)."""

FIT_SETTLED = tuple(r.label for r in StopReason if r.converged)  # ("converged", "stalled")
"""Stop reasons (exubio.types.StopReason labels, the calibration report's ``fit_stop``) of a fit
that reached its optimum. Any other on the final fit of the static pose and scales, on the robust
reweighting or on a further static's pose (max_iterations, damping_exhausted, not_finite) is a
'check': the calibrated geometry rests on a pose that is not the optimum. The fits of the start
postures only seed the final fit and are not judged."""

LEVELS = tuple(s.value for s in Severity)  # "note", "check", "fail": the order of weight


@dataclass(frozen=True)
class Reason:
    """One reason of a verdict; written and read by exubio.io.records ({"code", "level", "message"})."""

    code: str  # e.g. "residual", "marker_residual", "label", "limit", "undetermined", ...
    level: Severity  # given as the enum or its value ("note", "check", "fail")
    message: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "level", Severity(self.level))


@dataclass(frozen=True)
class Quality:
    """A verdict and its reasons; a summary.json's ``quality`` is ``records.to_json`` of it and
    reads back with ``records.decode(Quality, data)``."""

    verdict: Verdict
    reasons: tuple[Reason, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        object.__setattr__(self, "verdict", Verdict(self.verdict))

    def with_reasons(self, more: Iterable[Reason], /) -> "Quality":
        """The same judgement with ``more`` reasons added (notes leave the verdict as it is)."""
        return Quality.of((*self.reasons, *more))

    @staticmethod
    def of(reasons: Iterable[Reason]) -> "Quality":
        reasons = tuple(sorted(reasons, key=lambda r: -r.level.rank))
        worst = max((r.level.rank for r in reasons), default=0)
        return Quality((Verdict.OK, Verdict.CHECK, Verdict.FAIL)[worst], reasons)


def _level(value: float, bounds: tuple[float, float]) -> str | None:
    if value > bounds[1]:
        return "fail"
    if value > bounds[0]:
        return "check"
    return None


# ---------------------------------------------------------------------------------- criteria
def residual_reasons(residual_mm: Mapping[str, Any], per_frame_mean_mm: np.ndarray) -> list[Reason]:
    out = []
    mean = residual_mm.get("mean")
    if mean is not None:
        lvl = _level(mean, RESIDUAL_MEAN_MM)
        if lvl:
            out.append(Reason("residual", lvl, f"mean marker residual {mean:.1f} mm (check above "
                              f"{RESIDUAL_MEAN_MM[0]:.0f} mm, fail above {RESIDUAL_MEAN_MM[1]:.0f} mm)"))
    for name, rmse in (residual_mm.get("per_marker_rmse") or {}).items():
        if rmse is None:
            continue
        lvl = _level(rmse, MARKER_RMSE_MM)
        if lvl:
            out.append(Reason("marker_residual", lvl, f"marker {name}: RMSE {rmse:.1f} mm from its model point "
                              f"(check above {MARKER_RMSE_MM[0]:.0f} mm, fail above {MARKER_RMSE_MM[1]:.0f} mm)"))
    pf = np.asarray(per_frame_mean_mm, dtype=float)
    if pf.size:
        with np.errstate(invalid="ignore"):
            bad = pf > FRAME_RESIDUAL_MM
        if bad.mean() > FRAME_RESIDUAL_FRACTION:
            out.append(Reason("frame_residual", "check", f"{int(bad.sum())} of {pf.size} frames have a mean residual "
                              f"above {FRAME_RESIDUAL_MM:.0f} mm (first: frame {int(np.argmax(bad))})"))
    return out


def agreement_reasons(agreement_deg: Mapping[str, float] | None, undetermined: Sequence[str]) -> list[Reason]:
    out = []
    for name, rmse in (agreement_deg or {}).items():
        if name in undetermined or rmse is None or not np.isfinite(rmse):
            continue
        lvl = _level(rmse, AGREEMENT_DEG)
        if lvl:
            out.append(Reason("pf_ls_agreement", lvl, f"{name}: PF and LS differ by {rmse:.1f} deg RMSE where both "
                              f"measure it (check above {AGREEMENT_DEG[0]:.0f}, fail above {AGREEMENT_DEG[1]:.0f})"))
    return out


def limit_reasons(limits: Sequence[Mapping[str, Any]], n_frames: int, *, not_measured: Sequence[str] = ()) -> list[Reason]:
    """The checks on a calibration (``cal``: exubio.calibration.CalibrationReport, or None).
    ``not_measured``: coordinates the marker set cannot determine: at a limit, the limit is what
    holds them (a note naming it), not markers asking for an implausible posture."""
    out = []
    for lim in limits:
        lo, hi = lim["range_deg"]
        if lim["coordinate"] in not_measured:
            out.append(Reason("limit", "note", f"{lim['coordinate']} (not measured by this marker set) rests on its "
                              f"range limit [{lo:.0f}, {hi:.0f}] deg in {lim['frames_at_limit']} of {n_frames} frames"))
            continue
        lvl = "fail" if lim["max_beyond_deg"] > LIMIT_BEYOND_DEG else "check"
        out.append(Reason("limit", lvl, f"{lim['coordinate']} at its range limit [{lo:.0f}, {hi:.0f}] deg in "
                          f"{lim['frames_at_limit']} of {n_frames} frames (first: frame {lim['first_frame']}; "
                          f"at most {lim['max_beyond_deg']:.1f} deg beyond)"))
    return out


def partial_swap_reasons(swaps: Sequence[Any], repaired: bool) -> list[Reason]:
    """Labels exchanged in part of the trial: a fail while they stand (every angle of those frames
    rests on the wrong markers), a check once repaired (the frames were exchanged back)."""
    if repaired:
        return [Reason("label_repaired", "check", f"repaired on request (--repair-labels): {s.describe()}; "
                       f"exchanged back in those frames") for s in swaps]
    return [Reason("partial_swap", "fail", f"{s.describe()}; rerun with --repair-labels to exchange them back in "
                   f"those frames") for s in swaps]


def dropped_reasons(dropped: Sequence[str]) -> list[Reason]:
    """Protocol markers the trial lacks, left out because the others still measure every angle."""
    if not dropped:
        return []
    return [Reason("missing_marker", "check", f"marker(s) {', '.join(dropped)} of the protocol missing from the trial "
                   f"(a label typo? a marker that fell off?): left out; the other markers still measure every angle "
                   f"this marker set measures")]


def session_reasons(shifts: Sequence[Any], static_name: str) -> list[Reason]:
    """Segments whose markers look placed anew between the static and this trial
    (exubio.trust.session_check): the static may be of another session: a check with the evidence."""
    if not shifts:
        return []
    what = "; ".join(s.describe() for s in shifts)
    return [Reason("session", "check", f"the static trial {static_name or ''} may not belong to this trial's session: "
                   f"the markers look placed anew on {len(shifts)} segments ({what}); calibrate on this session's "
                   f"static, or check the session's file list")]


def _cause_text(causes: Mapping[str, Any] | None, name: str) -> tuple[str, str]:
    """(why, main cause) of an angle's not-measured frames (AngleDeterminacy.causes)."""
    if not causes or name not in causes:
        return "", "markers"
    from exubio.trust.angle_uncertainty import GIMBAL_MARGIN_DEG, U_BOUND_DEG

    c = causes[name]
    n = {k: int(np.asarray(v).sum()) for k, v in c.items()}
    main = max(n, key=n.get) if any(n.values()) else "markers"
    parts = []
    if n.get("gimbal"):
        parts.append(f"within {GIMBAL_MARGIN_DEG:g} deg of its sequence's gimbal lock in {n['gimbal']} frames (the angle is "
                     "not defined there" + ("; read GH in Phadke's sequence)" if name.startswith("GH_") else ")"))
    if n.get("uncertainty"):
        parts.append(f"its standard uncertainty above {U_BOUND_DEG:g} deg in {n['uncertainty']} frames (with the arm raised: "
                     "the bone-pin artefact and what the model's girdle cannot follow of the bones, which no marker "
                     "set removes; or the model's misfit where residuals are large: a static of this session reduces "
                     "the misfit)")
    if n.get("markers"):
        parts.append(f"not determined by the markers present in {n['markers']} frames")
    return "; ".join(parts), main


def angle_reasons(status: Mapping[str, str], structural: Mapping[str, str], measured_fraction: Mapping[str, float],
                  undetermined_trial_fraction: float, causes: Mapping[str, Any] | None = None) -> list[Reason]:
    """The anatomical angles the trial does not measure. What the marker set cannot measure in any
    posture (``structural``, known before the trial) is one note, said once; an angle the set
    measures but this trial does not (gaps, postures) is a check when it is not measured in more
    than ``undetermined_trial_fraction`` of the frames, else a note (its frames are marked)."""
    out = []
    never = [n for n, s in structural.items() if s == "not measured"]
    modelled = [n for n, s in structural.items() if s == "modelled"]
    if never or modelled:
        parts = []
        if never:
            parts.append("not measured (the markers do not determine them in any reference posture): " + ", ".join(never))
        if modelled:
            parts.append("modelled by the protocol's hold: " + ", ".join(modelled))
        out.append(Reason("protocol_angles", "note", "this marker set: " + "; ".join(parts)))
    for name, s in status.items():
        known = structural.get(name, "measured")
        if known in ("not measured", "modelled") or s == "measured":
            continue
        frac = 1.0 - float(measured_fraction.get(name, 0.0))
        why, main = _cause_text(causes, name)
        lvl = ("check" if frac > undetermined_trial_fraction and not known.startswith("partly") and main != "gimbal"
               else "note")
        out.append(Reason("angle_not_measured", lvl, f"{name}: not measured in {100 * frac:.0f} % of the frames "
                          f"(this marker set measures it{' in some postures' if known.startswith('partly') else ''}; "
                          f"the frames are marked)" + (f": {why}" if why else "")))
    return out


def gap_reasons(gaps: Sequence[Any], n_frames: int, rate_hz: float) -> list[Reason]:
    out = []
    by_marker: dict[str, list] = {}
    for g in gaps:
        by_marker.setdefault(g.marker, []).append(g)
    for marker, gs in by_marker.items():
        missing = sum(g.n_frames for g in gs)
        if missing >= n_frames:
            continue  # an optional marker absent from the trial: listed as such in summary.json
        if missing > GAP_NOTE_FRACTION * n_frames:
            longest = max(gs, key=lambda g: g.n_frames)
            out.append(Reason("gap", "note", f"marker {marker} missing in {100 * missing / n_frames:.0f} % of the "
                              f"frames (longest gap {longest.n_frames / rate_hz:.2f} s from frame {longest.start}); "
                              f"handled: left out where missing (PF spring off, no LS term)"))
    return out


def convergence_reasons(frames: Mapping[str, int], n_frames: int) -> list[Reason]:
    bad = int(frames.get("not_converged", 0)) + int(frames.get("too_few_markers", 0))
    lvl = _level(bad / max(n_frames, 1), NOT_CONVERGED_FRACTION)
    if not lvl:
        return []
    return [Reason("convergence", lvl, f"{bad} of {n_frames} frames not converged or with too few markers")]


def fallback_reasons(info: Mapping[str, Any]) -> list[Reason]:
    """PF's fallback (exubio.methods.pf.PFOptions.fallback): its first run stopped and the result is
    its second, with lighter segments and full Newton; said, not a fault of the result."""
    fb = info.get("fallback") if info else None
    if not fb:
        return []
    opts = ", ".join(f"{k} {v}" for k, v in (fb.get("options") or {}).items())
    first = str(fb.get("first_run", "?"))  # "<trial>: the PF run diverged at t = ...; ...": its first clause here,
    first = first.split(": ", 1)[-1].split("; ", 1)[0]  # the whole of it in summary.json (info.fallback)
    return [Reason("solver_fallback", "note", f"the result is PF's second run ({opts}): its first, with the "
                   f"options asked for, stopped ({first}; summary.json info.fallback has the whole reason)")]


def finding_field(f: Any, key: str, default: Any = None) -> Any:
    """A finding's field, whether the finding is typed (exubio.trust.labels.LabelFinding, ...) or read
    from a file."""
    return f.get(key, default) if isinstance(f, Mapping) else getattr(f, key, default)


def label_reasons(findings: Iterable[Any], *, prefix: str = "", in_static: Iterable[Any] = ()) -> list[Reason]:
    """A reason per label finding, with the relabel that fixes it; ``in_static``: the same findings
    on the session's static trial: a swap seen in both gets one fix for both (--relabel and
    --static-relabel together: fixing the trial alone against a swapped static makes it worse)."""
    statics = list(in_static)
    out = []
    for f in findings:
        get = partial(finding_field, f)
        lvl = {"error": "fail", "fail": "fail", "warning": "check", "check": "check", "info": "note",
               "note": "note"}.get(get("severity"), "check")
        relabel = get("relabel") or {}
        fix = ""
        same = next((g for g in statics if finding_field(g, "kind") == get("kind")
                     and set(finding_field(g, "markers", ())) == set(get("markers"))), None)
        static_relabel = (finding_field(same, "relabel") or {}) if same is not None else {}
        if relabel and static_relabel:
            words = lambda r: ",".join(f"{a}={b}" for a, b in r.items())  # noqa: E731
            fix = (f"; seen in the static trial too: to fix both: --relabel {words(relabel)} --static-relabel "
                   f"{words(static_relabel)} (every trial of the session: relabel: "
                   f"{{{', '.join(f'{a}: {b}' for a, b in relabel.items())}}} in the protocol)")
        elif relabel:
            option = "--static-relabel" if prefix.startswith("static") else "--relabel"
            fix = f"; to fix: {option} {','.join(f'{a}={b}' for a, b in relabel.items())}"
        out.append(Reason("label", lvl, f"{prefix}{get('kind')} ({', '.join(get('markers'))}): {get('evidence')}{fix}"))
    return out


def calibration_reasons(cal: Any, *, scale_bounds: tuple[float, float],
                        off_segment: Mapping[str, float] | None = None,
                        not_measured: Sequence[str] = (),
                        accepted_offsets_mm: Mapping[str, float] | None = None) -> list[Reason]:
    """The checks on a calibration (``cal``: exubio.calibration.CalibrationReport, or None).
    ``not_measured``: coordinates the marker set cannot determine (exubio.trust.assess): their range
    limit holds them, which is a note, not an implausible posture the markers ask for.
    ``accepted_offsets_mm``: per marker, the landmark distance the protocol accepts as the lab's
    placement (``landmark_offset_mm``), instead of LANDMARK_OFFSET_MM."""
    if cal is None:
        return []
    out = []
    src = cal.source or "the static trial"
    for name, value in cal.static_pose_at_limit_deg.items():
        if name in not_measured:
            out.append(Reason("calibration_pose", "note", f"calibration ({src}): the static pose leaves {name}, which "
                              f"this marker set does not measure, at its range limit ({value:.1f} deg)"))
            continue
        out.append(Reason("calibration_pose", "check", f"calibration ({src}): the static pose puts {name} at its "
                          f"range limit ({value:.1f} deg): the markers ask for an implausible posture"))
    for seg, s in cal.scale_factors.items():
        if min(abs(s - scale_bounds[0]), abs(s - scale_bounds[1])) < SCALE_AT_BOUND:
            out.append(Reason("calibration_scale", "check", f"calibration ({src}): {seg} scale factor {s:.2f} at its "
                              f"bound {scale_bounds}: the subject does not fit the model (another subject's static? a label?)"))
    motion = dict(cal.window_motion_mm)
    if motion:
        worst = max(motion, key=motion.get)
        if motion[worst] > WINDOW_MOTION_MM:
            out.append(Reason("calibration_motion", "check", f"calibration ({src}): the static window moves: {worst} "
                              f"{motion[worst]:.1f} mm RMS about its mean (above {WINDOW_MOTION_MM:.0f} mm)"))
    for fit, stop in cal.fit_stop.items():
        if fit != "start_pose" and stop not in FIT_SETTLED:  # the start pose only seeds the final fit
            what = {"pose_and_scales": "the final fit of the static pose and the scale factors",
                    "reweighting": "the robust reweighting of the static-pose fit"}.get(fit, f"the fit of the {fit}")
            out.append(Reason("calibration_fit", "check", f"calibration ({src}): {what} stopped before converging "
                              f"({stop.replace('_', ' ')}): the calibrated geometry may rest on a pose that is not "
                              f"the optimum"))
    gh = cal.functional.get("gh") or {}
    if gh and not gh.get("used"):
        out.append(Reason("calibration_functional", "note", f"calibration ({src}): functional glenohumeral centre "
                          f"not used: {gh.get('reason')}"))
    accepted = dict(accepted_offsets_mm or {})
    for name, d in cal.landmark_offsets_mm.items():
        limit = max(LANDMARK_OFFSET_MM, accepted.get(name, 0.0) + LANDMARK_ACCEPT_MARGIN_MM) if name in accepted \
            else LANDMARK_OFFSET_MM
        if d > limit:
            why = (f"the protocol accepts {accepted[name]:.0f} mm (+{LANDMARK_ACCEPT_MARGIN_MM:.0f})" if name in accepted
                   else f"above {LANDMARK_OFFSET_MM:.0f} mm")
            out.append(Reason("calibration_landmark", "check", f"calibration ({src}): marker {name} is {d:.0f} mm from the "
                              f"landmark it is declared over ({why}): misplaced, mislabelled, or a wrong static pose; "
                              f"if it is where your lab always puts it, accept it once in the protocol "
                              f"(markers.{name}.landmark_offset_mm)"))
    for name, d in (off_segment or {}).items():
        out.append(Reason("calibration_off_segment", "fail", f"calibration ({src}): marker {name} was registered "
                          f"{d * 1000:.0f} mm outside its segment: it is not on that segment (mislabelled?)"))
    return out


def off_segment_markers(model, protocol, /) -> dict[str, float]:
    """Markers of a calibrated model registered outside their segment: distance (m) beyond the
    sphere around the segment's anatomical points (every point that is not a protocol marker) plus
    OFF_SEGMENT_MARGIN_M."""
    names = set(protocol.marker_names)
    out = {}
    for spec in protocol.markers:
        seg = model.segment(spec.segment)
        anat = np.array([p for n, p in seg.points.items() if n not in names])
        if seg.joint is not None:
            anat = np.vstack([anat, np.zeros((1, 3))]) if anat.size else np.zeros((1, 3))
        if len(anat) < 2:
            continue
        centre = 0.5 * (anat.min(axis=0) + anat.max(axis=0))
        radius = float(np.linalg.norm(anat - centre, axis=1).max())
        d = float(np.linalg.norm(np.asarray(spec.local_position_m) - centre)) - radius - OFF_SEGMENT_MARGIN_M
        if d > 0:
            out[spec.name] = d
    return out
