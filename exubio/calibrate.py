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
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from exubio.errors import InputError, ModelError, ProtocolError
from exubio.kinematics import Kinematics, PointSet
from exubio.methods.common import tracked_points
from exubio.methods.ls import Limits, LSOptions, solve_positions
from exubio.ranges import AT_LIMIT_TOLERANCE_RAD, DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD, violation
from exubio.preprocess import isb_landmarks, prepare_targets, thorax_frame, to_thorax_frame, valid_runs
from exubio.protocol import resolve_labels
from exubio.types import Ellipsoid, MarkerTargets, Model, Protocol, Trajectories

__all__ = [
    "CalibrationReport",
    "MarkerCalibration",
    "DEFAULT_SCALE_GROUPS",
    "calibrate_file",
    "calibrate_model",
    "calibrated_protocol",
    "find_still_frames",
    "format_report",
    "joint_centre_points",
    "marker_point_names",
    "fit_ellipsoid",
    "parse_frames",
    "scale_model",
]

log = logging.getLogger(__name__)

DEFAULT_SCALE_GROUPS: Mapping[str, str] = {"ulna": "forearm", "radius": "forearm"}
"""Segments that share one scale factor (group name); every other segment is its own group."""

STILL_SPEED_M_S = 0.05
"""Automatic static window: every marker slower than this (filtered spline velocity)."""
MIN_STILL_S = 0.2
ROBUST_SCALE_M = 0.02  # Cauchy weight 1 / (1 + (d / ROBUST_SCALE_M)^2) in the anatomical fit
SCALE_BOUNDS = (0.7, 1.4)
SCALE_PRIOR_M2 = 1e-4  # cost of (s - 1)^2, in m^2: 10 % costs like 1 mm of one marker
GIRDLE_PRIOR_M2_PER_RAD2 = 1e-4  # clavicle/scapula angles: 10 deg costs like 1.7 mm of one marker
GIRDLE_SEGMENTS = ("clavicle", "scapula")
ARM_PRIOR_M2_PER_RAD2 = 1e-7  # the other coordinates: only breaks ties where nothing is observed
ELLIPSOID_RADIUS_WEIGHT_M = 0.3  # in the ellipsoid fit, 10 % of radius costs like 30 mm of centre
MAX_REWEIGHTING = 50  # iterations of the robust reweighting (stop: weights change < 1e-3)
RESIDUAL_FRAMES = 60  # the calibration residual is measured on at most this many frames


def _nanmean(a: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmean without the warning for all-NaN slices (they stay NaN)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(a, axis=axis)


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MarkerCalibration:
    """One protocol marker's calibration.

    point: the model point (on ``segment``) that now holds the marker's registered position.
    local_position_m: (3,) that position in the calibrated segment frame (m).
    registered: False when the marker had no sample in the calibration frames (optional marker):
        it keeps its scaled generic position and has no residual.
    residual_mm: RMS over the calibration frames of |model point - marker| on the calibrated
        model, each frame solved with the constrained LS (NaN when not registered).
    generic_offset_mm: |registered - scaled generic position| (the scaled generic model's static
        residual). fit_weight: the marker's robust weight in the anatomical fit (0..1].
    """

    name: str
    segment: str
    point: str
    local_position_m: np.ndarray
    registered: bool
    residual_mm: float
    generic_offset_mm: float
    fit_weight: float


@dataclass(frozen=True)
class CalibrationReport:
    """What a calibration fitted and how well (see the module docstring).

    frames: (start, stop, step) of the frames whose mean is the static pose.
    scale_factors: segment -> isotropic scale factor (segments of a group share it).
    static_q_rad: (m,) the static pose. ellipsoid_scale: the fitted common radii factor (after
    the thorax scale). constraint_abs: max |g| at the static pose (the ellipsoid fit's residual).
    """

    source: str
    frames: tuple[int, int, int]
    frames_chosen_automatically: bool
    rate_hz: float
    body_mass_kg: float
    generic_model: str
    protocol: str
    scale_factors: Mapping[str, float]
    thorax_scale_measured: bool
    static_q_rad: np.ndarray
    coordinate_names: tuple[str, ...]
    ellipsoid_centre_m: np.ndarray
    ellipsoid_radii_m: np.ndarray
    ellipsoid_scale: float
    constraint_abs: float
    markers: tuple[MarkerCalibration, ...]
    fit_iterations: int
    window_motion_mm: Mapping[str, float] = dataclasses.field(default_factory=dict)  # RMS motion of
    # each marker about its mean over the calibration frames: a "static" window that moves
    static_pose_at_limit_deg: Mapping[str, float] = dataclasses.field(default_factory=dict)  # coordinate ->
    # its static value (deg) where that lies at (within AT_LIMIT_TOLERANCE_RAD of) or beyond its range

    @property
    def residual_mm(self) -> dict[str, float]:
        """Calibration residual per registered marker (mm)."""
        return {m.name: m.residual_mm for m in self.markers if m.registered}

    @property
    def mean_residual_mm(self) -> float:
        vals = list(self.residual_mm.values())
        return float(np.mean(vals)) if vals else float("nan")

    @property
    def generic_offset_mm(self) -> dict[str, float]:
        return {m.name: m.generic_offset_mm for m in self.markers if m.registered}

    def to_dict(self) -> dict[str, Any]:
        """Plain data (mm, deg) for the model file's ``calibration`` section and JSON."""
        reg = [m for m in self.markers if m.registered]
        res = np.array([m.residual_mm for m in reg])
        off = np.array([m.generic_offset_mm for m in reg])
        worst = reg[int(np.argmax(res))].name if reg else None
        return {
            "method": "exubio.calibrate: anatomical fit (pose + segment scales, robust) -> registration -> ellipsoid",
            "source": self.source,
            "frames": {"start": self.frames[0], "stop": self.frames[1], "step": self.frames[2],
                       "n_frames": len(range(*self.frames)), "chosen_automatically": self.frames_chosen_automatically,
                       "rate_hz": self.rate_hz},
            "body_mass_kg": self.body_mass_kg,
            "generic_model": self.generic_model,
            "protocol": self.protocol,
            "scale_factors": {k: round(float(v), 6) for k, v in self.scale_factors.items()},
            "thorax_scale_measured": self.thorax_scale_measured,
            "static_pose_deg": {n: round(float(np.degrees(v)), 4)
                                for n, v in zip(self.coordinate_names, self.static_q_rad)},
            "ellipsoid": {"centre_mm": [round(float(v) * 1000, 4) for v in self.ellipsoid_centre_m],
                          "radii_mm": [round(float(v) * 1000, 4) for v in self.ellipsoid_radii_m],
                          "radii_scale_fitted": round(float(self.ellipsoid_scale), 6),
                          "max_abs_g_at_static_pose": float(self.constraint_abs)},
            "residual_mm": {
                "definition": "RMS over the calibration frames of |model point - marker|, calibrated model, "
                              "constrained LS per frame",
                "mean": float(res.mean()) if reg else None,
                "max": float(res.max()) if reg else None,
                "max_marker": worst,
            },
            "generic_offset_mm": {
                "definition": "|registered - scaled generic model point| at the static pose "
                              "(the scaled generic model's static residual)",
                "mean": float(off.mean()) if reg else None,
                "max": float(off.max()) if reg else None,
            },
            "markers": {
                m.name: {
                    "segment": m.segment,
                    "point": m.point,
                    "registered": m.registered,
                    "residual_mm": None if not m.registered else round(float(m.residual_mm), 3),
                    "generic_offset_mm": None if not m.registered else round(float(m.generic_offset_mm), 3),
                    "fit_weight": round(float(m.fit_weight), 4),
                    "local_position_mm": [round(float(v) * 1000, 4) for v in m.local_position_m],
                }
                for m in self.markers
            },
            "fit_iterations": self.fit_iterations,
            "window_motion_mm": {k: round(float(v), 3) for k, v in self.window_motion_mm.items()},
            "static_pose_at_limit_deg": {k: round(float(v), 3) for k, v in self.static_pose_at_limit_deg.items()},
        }


# --------------------------------------------------------------------------------------------
# Frames
# --------------------------------------------------------------------------------------------
def parse_frames(text: str | None, /) -> slice | None:
    """``"A:B"`` (or ``"A:"``, ``":B"``, ``"A:B:S"``) -> slice; None or "" -> None (automatic)."""
    if text is None or not str(text).strip():
        return None
    parts = str(text).strip().split(":")
    if len(parts) not in (2, 3):
        raise InputError(f"--static-frames '{text}': expected START:STOP (frame numbers, 0-based, STOP excluded)")
    try:
        vals = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise InputError(f"--static-frames '{text}': expected whole frame numbers like 0:50") from None
    if len(vals) == 3 and vals[2] is not None and vals[2] <= 0:
        raise InputError(f"--static-frames '{text}': the step must be > 0")
    return slice(*vals)


def find_still_frames(targets: MarkerTargets, /, *, max_speed_m_s: float = STILL_SPEED_M_S,
                      min_duration_s: float = MIN_STILL_S) -> slice:
    """The longest run of frames in which every present marker moves slower than
    ``max_speed_m_s`` (filtered spline velocities). If no run lasts ``min_duration_s``: the
    stretch of that length whose fastest marker is slowest on average (logged)."""
    n = targets.n_frames
    speed = np.linalg.norm(targets.velocities_m_s, axis=2)
    fastest = np.max(np.where(np.isnan(speed), -np.inf, speed), axis=1)  # the fastest marker per frame
    fastest[~np.isfinite(fastest)] = np.inf  # no marker at all: not still
    dt = float(np.median(np.diff(targets.time_s))) if n > 1 else 1.0
    min_len = max(2, min(n, int(round(min_duration_s / dt))))
    runs = valid_runs(fastest < max_speed_m_s)
    if runs:
        a, b = max(runs, key=lambda r: r[1] - r[0])
        if b - a >= min_len:
            return slice(a, b)
    sums = np.convolve(np.minimum(fastest, 1e9), np.ones(min_len), mode="valid")
    a = int(np.argmin(sums))
    log.warning("%s: no still stretch of %.2f s (markers < %.0f mm/s); calibrating on frames %d:%d, the stillest %d frames",
                targets.source or "trial", min_duration_s, max_speed_m_s * 1000, a, a + min_len, min_len)
    return slice(a, a + min_len)


# --------------------------------------------------------------------------------------------
# Scaling
# --------------------------------------------------------------------------------------------
def _groups(model: Model, groups: Mapping[str, str]) -> dict[str, str]:
    return {s.name: groups.get(s.name, s.name) for s in model.segments}


def scale_model(model: Model, factors: Mapping[str, float], /) -> Model:
    """The model with each segment scaled isotropically about its origin by ``factors[segment]``
    (missing segments: 1): its points, centre of mass and the joint-centre offsets of its children
    scale, its inertia scales with the square (same mass, radii of gyration scale with length);
    the thorax factor also scales the ellipsoid's centre and radii."""
    segs = []
    for seg in model.segments:
        s = float(factors.get(seg.name, 1.0))
        joint = seg.joint
        if joint is not None:
            sp = float(factors.get(seg.parent, 1.0))
            joint = dataclasses.replace(joint, centre_m=np.asarray(joint.centre_m, dtype=float) * sp)
        segs.append(dataclasses.replace(
            seg, joint=joint, com_m=np.asarray(seg.com_m, dtype=float) * s,
            inertia_kgm2=np.asarray(seg.inertia_kgm2, dtype=float) * s * s,
            points={k: np.asarray(v, dtype=float) * s for k, v in seg.points.items()}))
    st = float(factors.get(model.segments[0].name, 1.0))
    ell = dataclasses.replace(model.ellipsoid, centre_m=np.asarray(model.ellipsoid.centre_m) * st,
                              radii_m=np.asarray(model.ellipsoid.radii_m) * st)
    return dataclasses.replace(model, segments=tuple(segs), ellipsoid=ell)


def _thorax_scale(model: Model, protocol: Protocol, traj: Trajectories, frames: range) -> float | None:
    """Measured / model distances between the thorax-frame landmarks (least-squares ratio)."""
    frame = protocol.thorax_frame
    if frame.is_identity:
        return None
    thorax = model.segments[0]
    match = resolve_labels(protocol, traj.labels, source=traj.source)
    keys = frame.keys
    if "c7" not in keys:
        return None  # only the two midpoints: no landmark distances to scale the thorax with
    isb = {"ij": "IJ", "px": "PX", "c7": "C7", "t8": "T8"}
    lab = {k: traj.positions_m[list(frames), match.thorax_columns[k]] for k in keys}
    rot, origin = thorax_frame(*isb_landmarks(lab))
    measured, modelled = {}, {}
    for k in keys:
        label = getattr(frame, k)
        name = label if label in thorax.points else isb[k] if isb[k] in thorax.points else None
        if name is None:
            continue
        local = _nanmean(to_thorax_frame(lab[k][:, None, :], rot, origin)[:, 0], axis=0)
        if np.all(np.isfinite(local)):
            measured[k], modelled[k] = local, np.asarray(thorax.points[name], dtype=float)
    ks = sorted(measured)
    dm, dg = [], []
    for i in range(len(ks)):
        for j in range(i + 1, len(ks)):
            dm.append(np.linalg.norm(measured[ks[i]] - measured[ks[j]]))
            dg.append(np.linalg.norm(modelled[ks[i]] - modelled[ks[j]]))
    if len(dm) < 1 or np.dot(dg, dg) <= 0:
        return None
    return float(np.clip(np.dot(dm, dg) / np.dot(dg, dg), *SCALE_BOUNDS))


def _scale_design(model: Model, fr, seg_index: np.ndarray, local_generic: np.ndarray, group_of: dict[str, str],
                  group_names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """For the rotations of ``fr`` (frames of the unscaled ``model`` at some q), the linear maps
    from the group scale factors s to the marker points, V (k, 3, n_groups): r_i = V_i @ s, and
    to the segment origins, O (n_seg, 3, n_groups): p_seg = O_seg @ s (a segment's factor scales
    its points and its children's joint-centre offsets)."""
    names = model.segment_names
    col = {g: j for j, g in enumerate(group_names)}
    O = np.zeros((len(names), 3, len(group_names)))
    for i, seg in enumerate(model.segments):
        if seg.parent is not None:
            par = names.index(seg.parent)
            O[i] = O[par]
            O[i, :, col[group_of[seg.parent]]] += fr.R[par] @ np.asarray(seg.joint.centre_m, dtype=float)
    V = O[seg_index].copy()
    for i, s in enumerate(seg_index):
        V[i, :, col[group_of[names[s]]]] += fr.R[s] @ local_generic[i]
    return V, O


# --------------------------------------------------------------------------------------------
# Anatomical fit (pose without the ellipsoid constraint, robust weights)
# --------------------------------------------------------------------------------------------
def _start_postures(model: Model) -> np.ndarray:
    names = model.coordinate_names
    starts = []
    arm = [{}, {"gh_abduction": 45}, {"gh_abduction": 90}, {"gh_abduction": 135},
           {"gh_flexion": 45}, {"gh_flexion": 90},
           {"gh_abduction": 90, "gh_internal_rotation": 90}, {"gh_abduction": 90, "gh_internal_rotation": -90},
           {"gh_flexion": 90, "gh_internal_rotation": 90}, {"gh_flexion": 90, "gh_internal_rotation": -90}]
    for a in arm:
        for elbow in (0.0, 90.0):
            q = np.zeros(len(names))
            for c, v in {**a, "elbow_flexion": elbow}.items():
                if c in names:
                    q[names.index(c)] = np.radians(v)
            starts.append(q)
    return np.unique(np.array(starts), axis=0)


def _fit_pose(kin: Kinematics, points: PointSet, target: np.ndarray, w: np.ndarray, q_starts: np.ndarray,
              prior: np.ndarray, *, limits: Limits | None = None, max_iterations: int = 300,
              tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """min_q sum w_i |r_i(q) - m_i|^2 + sum_j prior_j q_j^2 + kappa sum_j v_j(q)^2 (the joint
    ranges, exubio.ranges) for every start (S, m) at once, Levenberg-Marquardt; returns (q (S, m),
    cost (S,))."""
    q = np.array(q_starts, dtype=float)
    S, m = q.shape
    tgt = np.where(np.isnan(target), 0.0, target)

    def evaluate(qq):
        e = (kin.points(qq, points) - tgt) * (w[:, None] > 0)
        return e, np.einsum("k,skc->s", w, e * e) + (prior * qq * qq).sum(axis=1) + _range_cost(qq, limits)

    e, cost = evaluate(q)
    mu = np.full(S, 1e-4)
    active = np.ones(S, dtype=bool)
    for _ in range(max_iterations):
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        J = kin.point_jacobian(q[a], points)  # (A, k, 3, m)
        Jw = J * w[None, :, None, None]
        H = np.einsum("akcm,akcn->amn", Jw, J) + np.eye(m) * prior
        grad = np.einsum("akcm,akc->am", Jw, e[a]) + prior * q[a]
        if limits is not None:
            v = violation(q[a], limits.ranges_rad)
            H = H + limits.kappa * (v != 0)[..., :, None] * np.eye(m)
            grad = grad + limits.kappa * v
        dq = -np.linalg.solve(H + mu[a, None, None] * np.eye(m), grad[..., None])[..., 0]
        big = np.abs(dq).max(axis=1)
        dq *= np.minimum(1.0, 0.3 / np.maximum(big, 1e-300))[:, None]
        e_t, c_t = evaluate(q[a] + dq)
        ok = c_t <= cost[a]
        idx = a[ok]
        q[idx] += dq[ok]
        e[idx], cost[idx] = e_t[ok], c_t[ok]
        mu[a] = np.where(ok, np.maximum(mu[a] / 3, 1e-9), mu[a] * 10)
        done = (ok & (np.abs(dq).max(axis=1) < tol)) | (mu[a] > 1e8)
        active[a[done]] = False
    return q, cost


def _at_limit(q: np.ndarray, model: Model) -> dict[str, float]:
    rng = model.coordinate_ranges_rad
    at = (q <= rng[:, 0] + AT_LIMIT_TOLERANCE_RAD) | (q >= rng[:, 1] - AT_LIMIT_TOLERANCE_RAD)
    return {n: float(np.degrees(v)) for n, v, a in zip(model.coordinate_names, q, at) if a}


def _range_cost(q: np.ndarray, limits: Limits | None) -> np.ndarray | float:
    if limits is None:
        return 0.0
    v = violation(q, limits.ranges_rad)
    return limits.kappa * (v * v).sum(axis=-1)


@dataclass
class _Anchor:
    """The anatomical-fit problem: the generic model, its marker points, scale groups, weights."""

    model: Model
    seg_index: np.ndarray  # (k,) segment of each marker
    local_generic: np.ndarray  # (k, 3) generic local positions
    target: np.ndarray  # (k, 3) static markers (NaN: absent)
    groups: list[str]  # scale groups, in order
    group_of: dict[str, str]  # segment -> group
    fixed: dict[str, float]  # groups whose factor is not fitted
    prior_q: np.ndarray  # (m,) m^2/rad^2
    limits: Limits | None = None  # the joint ranges (the static pose must respect them too)

    def __post_init__(self) -> None:
        self.kin = Kinematics(self.model)

    @property
    def free(self) -> list[str]:
        return [g for g in self.groups if g not in self.fixed]

    def segment_factors(self, s: Mapping[str, float]) -> dict[str, float]:
        return {seg: float(s[g]) for seg, g in self.group_of.items()}

    def points(self, s: Mapping[str, float]) -> tuple[Kinematics, PointSet]:
        f = self.segment_factors(s)
        kin = Kinematics(scale_model(self.model, f))
        names = self.model.segment_names
        scale = np.array([f[names[i]] for i in self.seg_index])[:, None]
        return kin, PointSet(self.seg_index, self.local_generic * scale)

    def evaluate(self, q: np.ndarray, s: Mapping[str, float], w: np.ndarray, *, jacobian: bool):
        """Weighted cost (with the priors), residual vectors e (k, 3), and the Jacobian
        [dr/dq, dr/ds_free] (k, 3, m + f) if asked. Rotations do not depend on the scale
        factors, so one Kinematics of the unscaled model serves every s: r = V(q) s."""
        fr = self.kin.frames(q)
        s_all = np.array([s[g] for g in self.groups])
        V, O = _scale_design(self.model, fr, self.seg_index, self.local_generic, self.group_of, self.groups)
        r = V @ s_all
        e = np.where(np.isnan(self.target), 0.0, r - np.where(np.isnan(self.target), 0.0, self.target))
        s_free = np.array([s[g] for g in self.free])
        cost = float(np.einsum("k,kc->", w, e * e) + (self.prior_q * q * q).sum()
                     + SCALE_PRIOR_M2 * ((s_free - 1.0) ** 2).sum() + _range_cost(q, self.limits))
        if not jacobian:
            return cost, e, None
        pivots = (O @ s_all)[self.kin.coordinate_segment]  # (m, 3): each coordinate turns about its joint centre
        cols = np.cross(fr.axes[None, :, :], r[:, None, :] - pivots[None, :, :])  # (k, m, 3)
        Jq = np.swapaxes(cols * self.kin.affects[self.seg_index][:, :, None], 1, 2)
        Js = V[:, :, [self.groups.index(g) for g in self.free]]
        return cost, e, np.concatenate([Jq, Js], axis=2)

    def fit(self, q: np.ndarray, s: dict[str, float], w: np.ndarray, *, max_iterations: int = 200,
            tol: float = 1e-10) -> tuple[np.ndarray, dict[str, float], float]:
        """Joint Levenberg-Marquardt over the pose and the free scale factors (bounded)."""
        m, free = q.size, self.free
        cost, e, J = self.evaluate(q, s, w, jacobian=True)
        mu = 1e-4
        prior = np.concatenate([self.prior_q, np.full(len(free), SCALE_PRIOR_M2)])
        for _ in range(max_iterations):
            x_dev = np.concatenate([q, [s[g] - 1.0 for g in free]])
            Jw = J * w[:, None, None]
            H = np.einsum("kcm,kcn->mn", Jw, J) + np.diag(prior)
            grad = np.einsum("kcm,kc->m", Jw, e) + prior * x_dev
            if self.limits is not None:
                v = violation(q, self.limits.ranges_rad)
                H[:m, :m] += self.limits.kappa * np.diag((v != 0).astype(float))
                grad[:m] += self.limits.kappa * v
            dx = -np.linalg.solve(H + mu * np.eye(H.shape[0]), grad)
            dx *= min(1.0, 0.3 / max(np.abs(dx).max(), 1e-300))
            q_t = q + dx[:m]
            s_t = dict(s)
            s_t.update({g: float(np.clip(s[g] + d, *SCALE_BOUNDS)) for g, d in zip(free, dx[m:])})
            c_t, e_t, _ = self.evaluate(q_t, s_t, w, jacobian=False)
            if c_t <= cost:
                q, s = q_t, s_t
                cost, e, J = self.evaluate(q, s, w, jacobian=True)
                mu = max(mu / 3, 1e-9)
                if np.abs(dx).max() < tol:
                    break
            else:
                mu *= 10
                if mu > 1e8:
                    break
        return q, s, cost


# --------------------------------------------------------------------------------------------
# Ellipsoid
# --------------------------------------------------------------------------------------------
def fit_ellipsoid(ellipsoid: Ellipsoid, contacts_m: np.ndarray, /, *, tol: float = 1e-13,
                  max_iterations: int = 60) -> tuple[Ellipsoid, float]:
    """Move the centre in its sagittal plane (x, y) and scale the radii by a common factor k so
    that both contact points (2, 3) lie on the ellipsoid, with the least weighted change
    (|dc|^2 + (ELLIPSOID_RADIUS_WEIGHT_M * d ln k)^2). Returns the new ellipsoid and k. ModelError if no such
    ellipsoid is found near the given one."""
    x = np.asarray(contacts_m, dtype=float)
    radii0 = np.asarray(ellipsoid.radii_m, dtype=float)
    c = np.array(ellipsoid.centre_m, dtype=float)
    logk = 0.0
    Minv = np.diag([1.0, 1.0, 1.0 / ELLIPSOID_RADIUS_WEIGHT_M**2])
    g = None
    for _ in range(max_iterations):
        rr = radii0 * math.exp(logk)
        d = x - c
        g = (d * d / rr**2).sum(axis=1) - 1.0
        if np.abs(g).max() < tol:
            break
        Jg = np.column_stack([-2 * d[:, 0] / rr[0] ** 2, -2 * d[:, 1] / rr[1] ** 2, -2 * (d * d / rr**2).sum(axis=1)])
        step = -Minv @ Jg.T @ np.linalg.solve(Jg @ Minv @ Jg.T, g)
        c[0] += step[0]
        c[1] += step[1]
        logk += float(np.clip(step[2], -0.5, 0.5))
    if g is None or not np.abs(g).max() < 1e-10:
        raise ModelError(f"no thorax ellipsoid near the generic one passes through both contact points "
                         f"{np.round(x * 1000, 1).tolist()} mm (|g| = {np.abs(g).max():.2e})")
    return dataclasses.replace(ellipsoid, centre_m=c, radii_m=radii0 * math.exp(logk)), math.exp(logk)


# --------------------------------------------------------------------------------------------
# Marker <-> model point
# --------------------------------------------------------------------------------------------
def _declared_points(protocol: Protocol) -> dict[str, str]:
    """marker -> the ``point:`` its protocol file names (markers given by position: absent)."""
    src = Path(protocol.source) if protocol.source else None
    if src is None or not src.is_file():
        return {}
    from exubio.protocol import read_protocol_mapping

    try:  # a session file's markers may come from the protocol it extends
        raw = read_protocol_mapping(src).get("markers", {}) or {}
    except ProtocolError:
        return {}
    return {name: spec["point"] for name, spec in raw.items()
            if isinstance(spec, Mapping) and isinstance(spec.get("point"), str)}


def joint_centre_points(model: Model, segment: str, /) -> set[str]:
    """The points of ``segment`` that are joint centres: its own origin (local zero) and the
    joint centres of its children. Registration never moves them."""
    seg = model.segment(segment)
    out = {n for n, v in seg.points.items() if seg.parent is not None and np.linalg.norm(v) < 1e-12}
    for child in model.segments:
        if child.parent == segment:
            out |= {n for n, v in seg.points.items() if np.linalg.norm(v - child.joint.centre_m) < 1e-12}
    return out


def marker_point_names(protocol: Protocol, model: Model, /) -> dict[str, str]:
    """The model point each protocol marker is registered under: the ``point:`` its protocol
    file names (else a point of its segment at exactly its local position, else the marker's own
    name), except that a joint centre is never overwritten: a marker tied to one is registered as a
    point named after the marker (``<marker>_marker`` if the segment already has that name)."""
    declared = _declared_points(protocol)
    out = {}
    for m in protocol.markers:
        seg = model.segment(m.segment)
        if m.name in declared:
            name = declared[m.name]
        else:
            same = [n for n, v in seg.points.items() if np.allclose(v, m.local_position_m, rtol=0, atol=1e-12)]
            name = m.name if m.name in same or not same else same[0]
        if name in joint_centre_points(model, m.segment):
            name = m.name if m.name not in seg.points else f"{m.name}_marker"
        out[m.name] = name
    return out


def calibrated_protocol(protocol: Protocol, model: Model, /, *, point_names: Mapping[str, str] | None = None) -> Protocol:
    """``protocol`` with every marker's local position taken from the calibrated ``model``: from
    the point it was registered under (recorded in ``model.metadata["calibration"]``, else
    ``point_names``, else as ``marker_point_names`` finds it). Markers whose point the model lacks
    keep their position. Reconstructions with a calibrated model need it for the markers the
    protocol gives by ``local_position_mm`` and those tied to a joint centre (a protocol loaded
    with the calibrated model's points already has the others); it is idempotent."""
    if point_names is None:
        recorded = (model.metadata.get("calibration") or {}).get("markers") or {}
        point_names = {name: spec["point"] for name, spec in recorded.items()
                       if isinstance(spec, Mapping) and isinstance(spec.get("point"), str)}
        if not point_names:
            point_names = marker_point_names(protocol, model)
    markers = []
    for m in protocol.markers:
        pts = model.segment(m.segment).points
        p = point_names.get(m.name, m.name)
        markers.append(dataclasses.replace(m, local_position_m=np.array(pts[p], dtype=float)) if p in pts else m)
    return dataclasses.replace(protocol, markers=tuple(markers))


def _register(model: Model, q: np.ndarray, registrations: Sequence[tuple[str, str, np.ndarray]]) -> Model:
    """Set each named point (segment, point, global position at pose q) to that position, as a
    local position on its segment: l = R_seg(q)^T (x - p_seg(q)). Joints, other points and
    inertia are unchanged."""
    fr = Kinematics(model).frames(q)
    new_points = {s.name: dict(s.points) for s in model.segments}
    for seg_name, point, x in registrations:
        i = model.segment_index(seg_name)
        new_points[seg_name][point] = fr.R[i].T @ (np.asarray(x, dtype=float) - fr.p[i])
    return dataclasses.replace(model, segments=tuple(
        dataclasses.replace(s, points=new_points[s.name]) for s in model.segments))


# --------------------------------------------------------------------------------------------
# The calibration
# --------------------------------------------------------------------------------------------
def _window(targets: MarkerTargets, frames: slice | None) -> tuple[range, bool]:
    if frames is None:
        sl = find_still_frames(targets)
        return range(targets.n_frames)[sl], True
    rng = range(targets.n_frames)[frames]
    past = [v for v in (frames.start, frames.stop) if v is not None and abs(v) > targets.n_frames]
    if past:
        raise InputError(f"{targets.source or 'trial'}: the calibration frames {frames.start}:{frames.stop} reach past "
                         f"the trial, which has {targets.n_frames} frames (0:{targets.n_frames}); nothing is clipped")
    if len(rng) == 0:
        raise InputError(f"{targets.source or 'trial'}: the calibration frames {frames.start}:{frames.stop} select no "
                         f"frame of the {targets.n_frames} in the trial")
    return rng, False


def calibrate_model(model: Model, protocol: Protocol, trajectories: Trajectories, /, *,
                    frames: slice | None = None, scale_groups: Mapping[str, str] = DEFAULT_SCALE_GROUPS,
                    targets: MarkerTargets | None = None) -> tuple[Model, CalibrationReport]:
    """Calibrate ``model`` (generic) to the subject of ``trajectories`` (see the module docstring).

    frames: the frames of the trial that hold the static pose (their mean is used); None = the
        longest still stretch. targets: the trial's prepared targets, if already computed with
        ``prepare_targets(trajectories, protocol)``.
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
    w_protocol = np.where(present, protocol.weights, 0.0)
    coord_segment = Kinematics(model).coordinate_segment
    prior = np.array([GIRDLE_PRIOR_M2_PER_RAD2 if names[coord_segment[j]] in GIRDLE_SEGMENTS else ARM_PRIOR_M2_PER_RAD2
                      for j in range(model.n_coordinates)])

    limits = Limits.of(model, protocol, DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD)
    anchor = _Anchor(model=model, seg_index=seg_index, local_generic=local_generic, target=static,
                     groups=list(dict.fromkeys(group_of.values())), group_of=group_of, fixed=fixed, prior_q=prior,
                     limits=limits)
    factors = {g: fixed.get(g, 1.0) for g in anchor.groups}
    # start posture: several at once, pose only, generic scale factors
    kin, pts = anchor.points(factors)
    qs, cost = _fit_pose(kin, pts, static, w_protocol, _start_postures(model), prior, limits=limits)
    q = qs[int(np.argmin(cost))]
    # iteratively reweighted joint fit; the robust scale is annealed from 100 mm to ROBUST_SCALE_M so
    # that the first, rough poses do not discard markers a better pose would fit
    robust = np.ones(len(protocol.markers))
    it = 0
    for it in range(1, MAX_REWEIGHTING + 1):
        q, factors, cost = anchor.fit(q, factors, w_protocol * robust)
        kin, pts = anchor.points(factors)
        d = np.linalg.norm(kin.points(q, pts) - np.where(np.isnan(static), 0, static), axis=1)
        c = max(ROBUST_SCALE_M, 0.1 * 0.7 ** (it - 1))
        new = 1.0 / (1.0 + (d / c) ** 2)
        log.debug("calibration fit %d: cost %.4g, robust scale %.0f mm, scales %s", it, cost, c * 1000,
                  {g: round(v, 4) for g, v in factors.items()})
        change = float(np.abs(new - robust).max())
        robust = new
        if c == ROBUST_SCALE_M and change < 1e-3:
            break
    else:
        log.warning("%s: the robust weights of the anatomical fit still changed by %.1e after %d iterations",
                    src, change, MAX_REWEIGHTING)
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
    ellipsoid, k_ell = fit_ellipsoid(calibrated.ellipsoid, contacts)
    calibrated = dataclasses.replace(calibrated, ellipsoid=ellipsoid)
    kin_c = Kinematics(calibrated)
    g_abs = float(np.abs(kin_c.g(q)).max())

    cal_protocol = calibrated_protocol(protocol, calibrated, point_names=point_names)
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
        ellipsoid_scale=k_ell, constraint_abs=g_abs, markers=tuple(markers), fit_iterations=it,
        window_motion_mm={m.name: float(spread[j] * 1000) for j, m in enumerate(protocol.markers) if present[j]},
        static_pose_at_limit_deg=_at_limit(q, model))
    stem = Path(trajectories.source).stem if trajectories.source else "subject"
    calibrated = dataclasses.replace(
        calibrated, name=f"{model.name}_calibrated_{stem}",
        source=f"{model.source or model.name} calibrated on {src} frames {window.start}:{window.stop}",
        metadata={**dict(model.metadata), "calibration": report.to_dict(), "generic_source": model.source})
    log.info("%s: calibrated on frames %d:%d; residual mean %.2f mm; generic offsets mean %.1f mm",
             src, window.start, window.stop, report.mean_residual_mm,
             float(np.mean(list(report.generic_offset_mm.values()))))
    return calibrated, report


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
    q, _, _ = solve_positions(kin, pts, tgt, protocol.weights, q_start=q_static, options=LSOptions(), frame_dt=dt)
    d = np.linalg.norm(kin.points(q, pts) - tgt, axis=2) * 1000.0
    return np.sqrt(_nanmean(d * d, axis=0))


def calibrate_file(static_path: str | Path, /, *, protocol_path: str | Path | None = None,
                   model_path: str | Path | None = None, body_mass_kg: float | None = None,
                   frames: slice | None = None, out_path: str | Path | None = None,
                   overwrite: bool = False) -> tuple[Model, Protocol, CalibrationReport]:
    """Everything ``exubio calibrate`` does: read the trial, the generic model and the protocol,
    calibrate, and (with ``out_path``) write the calibrated model YAML. Returns the calibrated
    model, the protocol bound to it and the report. An existing ``out_path`` is replaced only
    with ``overwrite``."""
    from exubio.io.trial import read_trial
    from exubio.model import save_model
    from exubio.pipeline import load_model_and_protocol

    if out_path is not None and Path(out_path).exists() and not overwrite:
        raise InputError(f"{out_path}: the model file already exists; pass --overwrite to replace it")
    model, protocol = load_model_and_protocol(model_path=model_path, protocol_path=protocol_path,
                                              body_mass_kg=body_mass_kg)
    traj = read_trial(static_path)
    calibrated, report = calibrate_model(model, protocol, traj, frames=frames)
    if out_path is not None:
        save_model(calibrated, out_path, calibration=report.to_dict())
    return calibrated, calibrated_protocol(protocol, calibrated), report


def format_report(report: CalibrationReport, /) -> str:
    """A short text table of the calibration for the terminal."""
    lines = [f"calibration of {report.source or 'trial'}, frames {report.frames[0]}:{report.frames[1]}"
             + (" (still stretch found automatically)" if report.frames_chosen_automatically else "")]
    lines.append("scale factors: " + ", ".join(f"{k} {v:.3f}" for k, v in report.scale_factors.items()))
    lines.append(f"ellipsoid: centre {np.round(report.ellipsoid_centre_m * 1000, 1).tolist()} mm, radii "
                 f"{np.round(report.ellipsoid_radii_m * 1000, 1).tolist()} mm, |g| at the static pose "
                 f"{report.constraint_abs:.1e}")
    lines.append(f"{'marker':<12} {'segment':<9} {'residual mm':>11} {'generic offset mm':>18} {'fit weight':>10}")
    for m in report.markers:
        if m.registered:
            lines.append(f"{m.name:<12} {m.segment:<9} {m.residual_mm:>11.2f} {m.generic_offset_mm:>18.1f} {m.fit_weight:>10.2f}")
        else:
            lines.append(f"{m.name:<12} {m.segment:<9} {'not in the calibration frames: scaled generic position':>41}")
    lines.append(f"calibration residual: mean {report.mean_residual_mm:.2f} mm (RMS over the calibration frames, "
                 f"calibrated model, constrained LS per frame)")
    return "\n".join(lines)
