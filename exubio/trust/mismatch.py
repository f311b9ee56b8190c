"""Model mismatch from the residuals: does a segment's marker cluster say the model (its ellipsoid,
segment lengths, joint centres, marker places) is not the subject's?

Pure numpy on a reconstruction's joint coordinates and the targets it tracked (no solver). Per
segment with markers, from the residual e_k(t) = R_s(t)^T (M_k(t) - R_k(t)) of each of its markers
expressed in the segment's frame (mm):

* ``residual_rms_mm``: RMS of |e_k| over its markers and frames;
* ``bias_mm``: RMS over its markers of |mean_t e_k|, the part of the residual fixed on the segment
  over the whole trial (a marker the model places elsewhere than it is, or a pose the chain cannot
  reach in a consistent direction);
* ``pose_gap_deg`` (segments with >= 3 markers): RMS over frames of the rotation between the
  segment's orientation in the chain and the orientation its markers alone give it (a rigid
  least-squares fit of its model points onto its markers, Kabsch): how far the model's chain and
  constraints hold the segment from where its own markers put it;
* ``rigid_rms_mm``: the residual of that free rigid fit (what no rigid segment could remove: noise,
  skin motion between the markers, a marker placed wrong relative to the others);
* ``normal_mm`` (segments carrying an ellipsoid contact point): the mean residual of its markers
  along the ellipsoid's outward normal at the model point (+: the markers lie outside the model);
* ``contact_offset_mm`` (the same segments, >= 3 markers): RMS over frames and contact points of the
  signed distance from the thorax ellipsoid (along the ray from its centre, + outside) of the
  contact points (TS, AI) where the segment's own rigid fit puts them: the chain holds them on the
  ellipsoid, so this is how far the ellipsoid is from where the markers say the scapula glides;
  ``contact_offset_mean_mm`` its signed mean.

The decision (``mismatch_findings``) and its threshold are below, with the rates they were chosen
by (studies/model_mismatch.py; studies/README.md, "Model mismatch").
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from exubio.io.records import converted, decode, internal, to_json
from exubio.model.kinematics import Kinematics, PointSet

__all__ = ["MismatchAssessment", "MismatchFinding", "SegmentEvidence", "assess_mismatch", "mismatch_findings",
           "mismatch_reasons", "rigid_fit", "segment_evidence", "surface_distance_m", "unseen_mismatch_reasons",
           "UNSEEN_MISMATCH"]

MIN_RIGID_MARKERS = 3


@dataclass(frozen=True)
class SegmentEvidence:
    """What the residuals of one segment's markers say (see the module docstring; mm, deg). Written
    by exubio.io.records with its numbers to 3 decimals."""

    segment: str
    markers: tuple[str, ...]
    frames: int
    residual_rms_mm: float = converted(write=float, digits=3)
    bias_mm: float = converted(write=float, digits=3)
    worst_bias_marker: str
    worst_bias_mm: float = converted(write=float, digits=3)
    pose_gap_deg: float | None = converted(write=float, digits=3, default=None)
    pose_gap_p90_deg: float | None = converted(write=float, digits=3, default=None)
    rigid_rms_mm: float | None = converted(write=float, digits=3, default=None)
    normal_mm: float | None = converted(write=float, digits=3, default=None)
    contact_offset_mm: float | None = converted(write=float, digits=3, default=None)
    contact_offset_mean_mm: float | None = converted(write=float, digits=3, default=None)


def rigid_fit(local: np.ndarray, measured: np.ndarray, /) -> tuple[np.ndarray, np.ndarray]:
    """Rotations R (n, 3, 3) and translations t (n, 3) minimising sum |R local + t - measured|^2
    per frame; local (k, 3), measured (n, k, 3)."""
    cl = local.mean(axis=0)
    cm = measured.mean(axis=1)
    H = np.einsum("ki,nkj->nij", local - cl, measured - cm[:, None, :])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros_like(H)
    D[:, 0, 0] = 1.0
    D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)
    t = cm - np.einsum("nij,j->ni", R, cl)
    return R, t


def _rotation_angle(R: np.ndarray) -> np.ndarray:
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    return np.arccos(c)


def surface_distance_m(centre_m: np.ndarray, radii_m: np.ndarray, points_m: np.ndarray, /) -> np.ndarray:
    """Signed distance (m) of points (..., 3) from the ellipsoid along the ray from its centre
    (positive outside); the same measure as exubio.calibration.ellipsoid.surface_distance."""
    d = np.asarray(points_m, dtype=float) - np.asarray(centre_m, dtype=float)
    f = np.sqrt(((d / np.asarray(radii_m, dtype=float)) ** 2).sum(axis=-1))
    return np.linalg.norm(d, axis=-1) * (1.0 - 1.0 / f)


def segment_evidence(kin: Kinematics, points: PointSet, q: np.ndarray, measured_m: np.ndarray, /, *,
                     segments: Sequence[int] | None = None) -> dict[str, SegmentEvidence]:
    """Per segment carrying markers (the fixed root excluded): its SegmentEvidence.

    points: the tracked model points (``exubio.methods.common.tracked_points``); q (n, m) rad;
    measured_m (n, k, 3) the targets in the thorax frame, NaN in gaps. ``segments``: only these
    segment indices. Frames where a segment lacks a marker are left out of its rigid fit."""
    model = kin.model
    q = np.asarray(q, dtype=float)
    meas = np.asarray(measured_m, dtype=float)
    fr = kin.frames(q)
    model_pts = kin.points(q, points, frames=fr)
    seg_idx = np.asarray(points.segment_index)
    names = points.names or tuple(f"marker{i}" for i in range(seg_idx.size))
    ell = model.ellipsoid
    contact_segments = {model.segment_index(s) for s, _ in ell.contact_points}
    wanted = sorted(set(int(s) for s in seg_idx) - {0}) if segments is None else list(segments)
    out: dict[str, SegmentEvidence] = {}
    for s in wanted:
        cols = np.flatnonzero(seg_idx == s)
        if cols.size == 0:
            continue
        Rs = fr.R[:, s]
        e = np.einsum("nji,nkj->nki", Rs, meas[:, cols] - model_pts[:, cols]) * 1e3  # segment frame, mm
        ok = np.isfinite(e).all(axis=2)
        if not ok.any():
            continue
        mag2 = np.where(ok, np.sum(np.where(ok[..., None], e, 0.0) ** 2, axis=2), np.nan)
        rms = float(np.sqrt(np.nanmean(mag2)))
        with np.errstate(invalid="ignore"):
            mean_e = np.array([np.nanmean(e[ok[:, i], i], axis=0) if ok[:, i].any() else np.full(3, np.nan)
                               for i in range(cols.size)])
        bias_each = np.linalg.norm(mean_e, axis=1)
        worst = int(np.nanargmax(bias_each))
        ev = dict(segment=model.segments[s].name, markers=tuple(names[c] for c in cols), frames=int(ok.all(axis=1).sum()),
                  residual_rms_mm=rms, bias_mm=float(np.sqrt(np.nanmean(bias_each ** 2))),
                  worst_bias_marker=names[cols[worst]], worst_bias_mm=float(bias_each[worst]))
        full = ok.all(axis=1)
        if cols.size >= MIN_RIGID_MARKERS and full.sum() >= 1:
            local = points.local_m[cols]
            Rf, tf = rigid_fit(local, meas[full][:, cols])
            gap = np.degrees(_rotation_angle(np.swapaxes(Rs[full], -1, -2) @ Rf))
            fit = np.einsum("nij,kj->nki", Rf, local) + tf[:, None, :]
            ev.update(pose_gap_deg=float(np.sqrt(np.mean(gap ** 2))), pose_gap_p90_deg=float(np.percentile(gap, 90)),
                      rigid_rms_mm=float(np.sqrt(np.mean(np.sum((meas[full][:, cols] - fit) ** 2, axis=2))) * 1e3))
            contacts = [np.asarray(model.segments[s].points[p], dtype=float) for seg, p in ell.contact_points
                        if model.segment_index(seg) == s]
            if contacts:
                c = np.einsum("nij,kj->nki", Rf, np.array(contacts)) + tf[:, None, :]
                dist = surface_distance_m(ell.centre_m, ell.radii_m, c) * 1e3
                ev.update(contact_offset_mm=float(np.sqrt(np.mean(dist ** 2))), contact_offset_mean_mm=float(np.mean(dist)))
        if s in contact_segments:
            r = model_pts[:, cols] - ell.centre_m
            nrm = r * ell.a_diag
            nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
            along = np.sum((meas[:, cols] - model_pts[:, cols]) * nrm, axis=-1) * 1e3
            ev["normal_mm"] = float(np.nanmean(along))
        out[ev["segment"]] = SegmentEvidence(**ev)
    return out


def evidence_table(evidence: Mapping[str, SegmentEvidence], /) -> list[dict]:
    """The evidence as plain rows (for JSON and tables)."""
    return to_json(list(evidence.values()))


# ----------------------------------------------------------------------------- the decision
# Thresholds from studies/model_mismatch.py (grid: 19 perturbations x abduction, flexion,
# scaption x {clean; 1 mm noise + 10 mm STA; 1 mm noise + 20 mm STA}, 3 realisations; 5 s at 50 Hz,
# LS, the generic model) and every real trial of ../shared/data (studies/trust_real_trials.py);
# the figures are in studies/README.md, "Model mismatch".

CONTACT_OFFSET_MM = 6.0
"""Scapula: the signed mean distance from the thorax ellipsoid of the contact points (TS, AI) where
the scapula's own markers put them (``contact_offset_mean_mm``) beyond this OUTSIDE the ellipsoid, or
beyond CONTACT_INSIDE_MM inside it: check.
Measured: no mismatch, noise and STA up to 20 mm: at most 2.2 mm; real C3D trials: at most 4.0 mm
(martin_dynamique; the others 0.0-1.0 mm); an ellipsoid 10 mm more posterior, or 8 % larger, or
5 mm + 4 % (each costs 5.8-7.3 deg RMSE on a measured angle): 7.9-11.4 mm; 10 mm + 8 % either way:
15.1-20.2 mm. (The TRC trials: 7.3 and 11.9 mm; an ellipsoid refitted through these contact points
halves their residual and moves their ST angles by 6-15 deg: a real mismatch, see studies/README.md.)"""

CONTACT_INSIDE_MM = 12.0
"""... inside: the skin over the scapula, sliding as the bone-pin trials show (the cluster lags the
bone's upward rotation: exubio simulate --sta bone), puts the contact points 2.9-9.3 mm inside the
ellipsoid on average with no mismatch at all (30 simulated abductions, flexions and scaptions,
studies/verdict_false_alarms.py); 6 mm there gave a check on every one of them. An ellipsoid
10 mm more anterior or 8 % smaller, with that artefact: 12.5-13.7 mm inside (caught); with the
per-marker artefact 6.8-7.8 mm (a note now, no longer a check: the skin can do as much)."""

CONTACT_OFFSET_RMS_MM = 20.0
"""Scapula: the RMS of that distance beyond this: check (an ellipsoid wrong in a way whose mean
cancels over the trial). No mismatch: at most 3.7 mm with the per-marker artefact, 10.2-15.8 mm
with the bone-pin artefact (9 mm, the rule's first value, flagged all 30); real C3D trials: at most
6.3 mm; an ellipsoid 10 mm posterior and 8 % larger: 20.2-20.3 mm."""

CONTACT_NOTE_MM = (6.0, 9.0)
"""(mean, RMS) beyond which a contact offset that stays under the check's limits is said as a note
(within what the skin's sliding gives)."""

SCAPULA_TRIAL_CAVEAT = (
    "a scapula trial (`--scapula-trial`) is no remedy: it fits the ellipsoid to skin that slides over the scapula, "
    "which on bone pins took ST upward rotation 1-10 deg farther from the bone (docs/calibration.md, step 5)")
"""What the bone pins showed of the functional scapula calibration (studies/scapula_trial_bone.py): the
model follows its skin markers better, and the bone worse; said wherever exubio names it."""

BIAS_MM = 8.0
"""Clavicle, ulna, radius, hand: the RMS over a segment's markers of the trial mean of its residual
in the segment's frame (``bias_mm``) beyond this: check. No mismatch: at most 5.4 mm (ulna, 20 mm
STA); real trials with their labels right: at most 6.6 mm; a clavicle 10 % longer or shorter:
8.7-12.2 mm on the clavicle (costs 8.7-20 deg); a humerus 10 % longer or shorter: 14.8-23.4 mm on
the ulna (costs 7-20 deg)."""

BIAS_SEGMENTS = ("clavicle", "ulna", "radius", "hand")
"""Where the bias rule applies. Not the humerus: skin over the deltoid moves its markers (20 mm STA:
a bias up to 11 mm with no mismatch); not the scapula: the contact-point rule above is specific to
its ellipsoid, and its skin markers keep a 10-11 mm bias on every real C3D trial that no refitted
ellipsoid removes (studies/model_mismatch.py --real-refit)."""

EVIDENCE_EVERY_S = 0.05
"""The evidence is computed on frames this far apart (statistics over the trial; at 200 Hz every
10th frame), so a long trial costs little and no per-marker array of the whole trial is built."""


@dataclass(frozen=True)
class MismatchFinding:
    """One segment the residuals say the model does not fit: what and how much. Written by
    exubio.io.records (pose gap and normal offset to 2 decimals; the contact offsets, in the
    evidence beside it, are not repeated)."""

    segment: str
    evidence: str  # the sentence of the verdict's reason
    level: str = "check"  # "note": evidence within what the skin alone gives
    pose_gap_deg: float | None = converted(digits=2, default=None)
    normal_mm: float | None = converted(digits=2, default=None)
    contact_offset_mm: float | None = internal(default=None)
    contact_offset_mean_mm: float | None = internal(default=None)


@dataclass(frozen=True)
class MismatchAssessment:
    """The evidence per segment and what the detector makes of it."""

    evidence: Mapping[str, SegmentEvidence]
    findings: tuple[MismatchFinding, ...]

    def to_dict(self) -> dict:
        """Kept by hand (exubio.io.records' documented exception): the file leads with the
        detector's definition (its thresholds, not a field) and gives the evidence as a list."""
        return {"definition": (f"check when the scapula's contact points, where its own markers put them, lie more "
                               f"than {CONTACT_OFFSET_MM:g} mm off the thorax ellipsoid on average (or {CONTACT_OFFSET_RMS_MM:g} "
                               f"mm RMS), or the markers of the {', '.join(BIAS_SEGMENTS)} sit more than {BIAS_MM:g} mm "
                               "from their model points on average over the trial (segment frame)"),
                "findings": to_json(self.findings), "evidence": evidence_table(self.evidence)}

    @staticmethod
    def from_dict(data: Mapping, /) -> "MismatchAssessment":
        """The assessment ``to_dict`` wrote (its numbers as rounded there)."""
        evidence = decode(tuple[SegmentEvidence, ...], data["evidence"])
        return MismatchAssessment({e.segment: e for e in evidence}, decode(tuple[MismatchFinding, ...], data["findings"]))


def mismatch_findings(evidence: Mapping[str, SegmentEvidence], /, *, skip_segments: Sequence[str] = ()
                      ) -> tuple[MismatchFinding, ...]:
    """The segments whose evidence crosses a threshold (CONTACT_OFFSET_MM, CONTACT_OFFSET_RMS_MM,
    BIAS_MM), except ``skip_segments``."""
    out = []
    notes: list[MismatchFinding] = []
    for seg, ev in evidence.items():
        if seg in skip_segments:
            continue
        parts = []
        mean, rms = ev.contact_offset_mean_mm, ev.contact_offset_mm
        where = (f"where its own markers ({', '.join(ev.markers)}) put it, its contact points lie "
                 f"{abs(mean or 0.0):.1f} mm {'outside' if (mean or 0.0) > 0 else 'inside'} the thorax ellipsoid on "
                 f"average (RMS {rms or 0.0:.1f} mm")
        if mean is not None and (mean > CONTACT_OFFSET_MM or mean < -CONTACT_INSIDE_MM or rms > CONTACT_OFFSET_RMS_MM):
            parts.append(f"{where}; check above {CONTACT_OFFSET_MM:g} mm outside, {CONTACT_INSIDE_MM:g} mm inside, RMS "
                         f"{CONTACT_OFFSET_RMS_MM:g} mm), while the model holds them on it: the ellipsoid does not fit "
                         f"this subject")
        elif mean is not None and (abs(mean) > CONTACT_NOTE_MM[0] or rms > CONTACT_NOTE_MM[1]):
            notes.append(MismatchFinding(seg, f"{where}): within what the skin sliding over the scapula gives "
                                              f"(bone-pin artefact: up to 9 mm inside, RMS 16 mm), not a check; "
                                              f"a mismatched ellipsoid can look the same",
                                         level="note", pose_gap_deg=ev.pose_gap_deg, normal_mm=ev.normal_mm))
        if seg in BIAS_SEGMENTS and ev.bias_mm > BIAS_MM:
            parts.append(f"its markers sit {ev.bias_mm:.1f} mm (RMS over {', '.join(ev.markers)}; {ev.worst_bias_marker} "
                         f"{ev.worst_bias_mm:.1f} mm) from their model points on average over the trial, always in the "
                         f"same direction on the segment (check above {BIAS_MM:g} mm): the length of this segment or "
                         f"of one proximal to it, a joint centre or a marker's place does not fit this subject")
        if parts:
            out.append(MismatchFinding(seg, "; ".join(parts), pose_gap_deg=ev.pose_gap_deg, normal_mm=ev.normal_mm))
    return tuple(out) + tuple(n for n in notes if n.segment not in {f.segment for f in out})


def assess_mismatch(kin: Kinematics, points: PointSet, q: np.ndarray, measured_m: np.ndarray, time_s: np.ndarray,
                    /, *, skip_markers: Sequence[str] = ()) -> MismatchAssessment:
    """segment_evidence on frames EVIDENCE_EVERY_S apart, and its findings (mismatch_findings).
    ``skip_markers``: markers a label finding names (a swap explains their residuals): their
    segments and every segment they carry are not judged."""
    seg_of = dict(zip(points.names, (int(i) for i in points.segment_index)))
    skipped = {seg_of[m] for m in skip_markers if m in seg_of}
    for s in range(kin.n_segments):  # parents come first: a segment below a skipped one is skipped
        if int(kin.parent_index[s]) in skipped:
            skipped.add(s)
    n = q.shape[0]
    dt = float(np.median(np.diff(time_s))) if n > 1 else 1.0
    step = max(1, int(round(EVIDENCE_EVERY_S / dt)))
    ev = segment_evidence(kin, points, q[::step], measured_m[::step])
    return MismatchAssessment(ev, mismatch_findings(ev, skip_segments=[kin.model.segments[i].name for i in skipped]))


def _advice(finding: "MismatchFinding", calibrated: bool) -> str:
    """What a lab can do about a finding: which segment, which marker, which calibration."""
    if "ellipsoid" in finding.evidence:
        return (("what to do: check that the scapula markers stayed where the static had them (re-placed, fallen, "
                 "another session's static?)" if calibrated else
                 "what to do: calibrate on a static of this session (`--static STATIC`: the ellipsoid through the "
                 "scapula's contact points at rest)") + "; " + SCAPULA_TRIAL_CAVEAT)
    marker = finding.evidence.split("; ")[0]
    worst = marker.split(" mm)")[0].split("; ")[-1].split(" ")[0] if "; " in marker else ""
    if calibrated:
        return (f"what to do: the calibration registered the markers where its static had them, so the static and "
                f"this trial disagree: check that {worst or 'the markers'} stayed where they were (re-placed, "
                f"fallen, another session's static?) and calibrate with a static of this trial's session")
    return (f"what to do: calibrate with a static of this session (`--static STATIC`: it scales the segments and "
            f"registers every marker where it sits), and check {worst or 'the named markers'} against the protocol "
            f"(`exubio protocols PROTOCOL --static STATIC` names markers declared elsewhere than they are)")


def mismatch_reasons(assessment: MismatchAssessment | None, /, *, calibrated: bool = False) -> list:
    """The verdict's reasons (exubio.trust.quality.Reason, code "model_mismatch", level check), each
    with what a lab can do (``calibrated``: the model came from a static of the session)."""
    from exubio.trust.quality import Reason

    if assessment is None:
        return []
    out = []
    for f in assessment.findings:
        if f.level == "note":
            out.append(Reason("model_mismatch", "note", f"the {f.segment}: {f.evidence}; {_advice(f, calibrated)}"))
        else:
            out.append(Reason("model_mismatch", "check", f"model mismatch on the {f.segment}: {f.evidence}; in "
                              f"simulations this much costs more than 5 deg on a measured angle; {_advice(f, calibrated)}"))
    return out


UNSEEN_MISMATCH = (
    "not seen by any check, and possible in any trial: a thorax ellipsoid that sits too high or is stretched "
    "vertically for this subject leaves the residuals and the contact points as they are while the GH angles in "
    "ISB's Y-X'-Y'' move by up to 10 deg (studies/README.md, Model mismatch); the skin over the scapula "
    "sliding as a whole leaves small residuals too (that part is in each angle's uncertainty, <angle>_u_deg). "
    "Read GH in Phadke's sequence")

SKIN_ELLIPSOID = (
    "this model's thorax ellipsoid was fitted through the scapula poses its skin markers gave away from rest (a "
    "scapula trial or several statics): it follows the skin's sliding over the scapula, so each ST and GH angle's "
    "uncertainty carries the scapula cluster's whole sliding (on bone pins such a fit took ST upward rotation 1-10 "
    "deg farther from the bone than the static calibration alone: studies/README.md, 'A scapula trial against "
    "bone'); the unseen mismatch of a rest-calibrated ellipsoid (a surface too high or stretched) is fitted away")


def unseen_mismatch_reasons(protocol, /, *, scapula_calibrated: bool = False) -> list:
    """A note, in every trial whose markers measure the scapula, of the mismatch no check can see
    (UNSEEN_MISMATCH), or, when the ellipsoid was fitted on the skin's scapula poses (a scapula trial,
    several statics), of what that fit does (SKIN_ELLIPSOID)."""
    from exubio.trust.quality import Reason

    if not any(m.segment == "scapula" for m in protocol.markers):
        return []
    return [Reason("unseen_mismatch", "note", SKIN_ELLIPSOID if scapula_calibrated else UNSEEN_MISMATCH)]
