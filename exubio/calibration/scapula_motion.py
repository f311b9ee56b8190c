"""Functional scapula calibration: the subject's thorax ellipsoid fitted through the scapula
contact points of every posture of a movement trial, together with the static pose(s).

Why: a thorax ellipsoid calibrated at rest only (``exubio.calibration.ellipsoid.fit_ellipsoid``:
moved and scaled least so that TS and AI lie on it at the static pose) is right at rest and
wrong at elevation: on the thoracoscapular TRC subject the registered scapula, fitted rigidly to
each frame's aa/ts/ai, leaves ts/ai 25 mm RMS off it (max 60 mm), so the constrained model
departs from the data by 15-29 deg of ST rotation at HT 120 (issue 21). The paper fitted its
ellipsoid through several static elevations; a movement trial of the session (the arm raised in
one or more planes) gives hundreds of postures.

Algorithm (pure: arrays and a Model in, an Ellipsoid and a typed report out)
---------------------------------------------------------------------------
1. The scapula's pose in every used frame of the movement from its markers: the rigid
   least-squares fit (Kabsch, ``exubio.calibration.cluster.cluster_poses``) of the markers'
   registered local positions on the calibrated scapula to the frame's markers. Every protocol
   marker on the scapula that the static trial registered takes part (the reconstruction sees the
   scapula through all of them too); at least 3, not collinear. The fit's RMS per frame and per
   marker says how well the static registration carries the movement (skin sliding over the
   scapula shows here; rigid marker triangles fit to round-off).
2. The contact points (TS, AI) of the registered scapula in those poses, and of the static
   pose(s) (each static pose weighted like ``STATIC_WEIGHT_POSTURES`` postures of the movement:
   the pose the markers were registered in).
3. The ellipsoid (thorax-axis-aligned, as the model's: centre 3 + radii 3) that brings all these
   points closest to its surface (radial distance, ``ellipsoid.surface_distance``; soft-L1 weights
   of scale ``ROBUST_SCALE_M``, iteratively reweighted, so that a few badly fitted frames do not
   drag it), with a weak
   Gaussian prior on the change from the static calibration's ellipsoid (``PRIOR_CENTRE_SD_M``,
   ``PRIOR_LOG_RADIUS_SD``) that keeps what the postures leave open (a one-sided scapula covers a
   patch of the surface: its centre's lateral position and lateral radius trade off).
4. Coverage: how far the postures determine each parameter, from the linearised posterior at
   the solution (data noise: the fit's own residual RMS, at least ``MIN_CONTACT_SD_M``):
   ``determined`` = 1 - posterior SD / prior SD per parameter (1: the data alone fix it; 0: the
   prior does), the number of parameter directions the data fix at least 4 times better than
   the prior, the scapula's rotation range over the movement and the extent of each contact
   point's path on the surface.

Refusals (``InputError`` with the reason; the calibration then keeps the static ellipsoid and
reports why, as a functional GH trial that cannot determine the centre): fewer than 3 scapula
markers (or collinear ones); fewer than ``MIN_POSTURES`` frames with them; a scapula that turns
less than ``MIN_ROTATION_DEG`` over the movement (the contact points then barely leave the
static pose's patch: no new information); fewer than ``MIN_DETERMINED_DIRECTIONS`` parameter
directions determined; a degenerate fit (a radius below ``MIN_RADIUS_M`` or above
``MAX_RADIUS_M``: a point- or plane-like surface). None of these thresholds comes from one
trial: they state what a surface fit needs.

Double calibration of an acromion marker cluster (Cereatti et al.; van Andel et al. 2009: the
cluster-to-scapula registration interpolated with elevation, from landmarks palpated at two or
more arm postures) needs static trials at several elevations with palpated landmarks. The
shipped data have none: the TRC subject's aa/ts/ai are a rigid triangle (distances constant to
0.01 mm over both trials: landmark positions already derived from one registration, not a cluster
with separately palpated landmarks), and each C3D session has one static trial (arm down). What
this module does with a cluster protocol is the single-registration version: the cluster's
static registration carries the scapula through the movement, and the fit's per-marker RMS shows
how far the skin landmarks (e.g. SCAP_IA) drift from it with elevation.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from exubio.calibration.ellipsoid import surface_distance
from exubio.calibration.cluster import cluster_poses
from exubio.errors import InputError
from exubio.types import Ellipsoid, MarkerTargets, Model, Protocol

log = logging.getLogger(__name__)

__all__ = ["MAX_POSTURES", "MIN_POSTURES", "MIN_ROTATION_DEG", "ScapulaMotionFit", "contact_points_over_motion",
           "fit_scapula_motion", "scapula_markers"]

MIN_POSTURES = 20  # frames with every scapula marker: fewer cannot show a surface
MAX_POSTURES = 400  # at most this many frames, evenly spread over the used ones (the fit's cost)
MIN_ROTATION_DEG = 15.0  # the scapula must turn at least this much from the static pose
MIN_DETERMINED_DIRECTIONS = 3  # of the 6 parameters' directions, at least this many fixed by the data
DETERMINED_INFORMATION_RATIO = 4.0  # a direction is determined when the data give >= 4x the prior's information
STATIC_WEIGHT_POSTURES = 10.0  # a static pose counts like this many postures of the movement
PRIOR_CENTRE_SD_M = 0.02  # prior SD of each centre coordinate's change from the static ellipsoid
PRIOR_LOG_RADIUS_SD = 0.15  # prior SD of each radius's relative change (15 %)
ROBUST_SCALE_M = 0.005  # soft-L1 scale of the surface distances
ROBUST_ITERATIONS = 20  # reweighting passes at most
MIN_CONTACT_SD_M = 0.001  # noise floor of a contact point's distance in the coverage estimate
MIN_RADIUS_M = 0.03  # a fitted radius outside [MIN_RADIUS_M, MAX_RADIUS_M] is a degenerate fit (a point-like
MAX_RADIUS_M = 0.5  # or a plane-like surface, not a thorax): refused
PARAMETERS = ("centre_x", "centre_y", "centre_z", "radius_x", "radius_y", "radius_z")


@dataclass(frozen=True)
class ScapulaMotionFit:
    """What the functional scapula calibration fitted and how well (lengths in m inside;
    ``to_dict`` gives mm and deg).

    ellipsoid: the fitted thorax ellipsoid (contact points as the model's).
    trial: the movement trial; frames_used / frames_with_pose / frames_total: postures in the fit,
    frames where the scapula's pose could be fitted, frames of the trial.
    markers: the scapula markers that placed the scapula; rigid_rms_m: per marker, the RMS over
    the used frames of its distance from the rigidly fitted registration; rigid_frame_rms_m:
    (median, max) over frames of the per-frame fit RMS.
    before_m / after_m: surface distances of the contact points from the static calibration's /
    the fitted ellipsoid: {"movement": (rms, max), "static": (rms, max)} per contact point name and
    "all". centre_shift_m (3), radius_scale (3): the change from the static ellipsoid.
    posterior_sd: per parameter (m for the centre, relative for the radii); determined: 1 -
    posterior SD / prior SD per parameter; determined_directions: parameter directions the data
    fix (>= DETERMINED_INFORMATION_RATIO x the prior's information).
    rotation_range_deg: the scapula's largest rotation from the static pose over the movement;
    path_extent_m: per contact point, the extent of its path (the two largest principal extents,
    2 x SD, m).
    """

    ellipsoid: Ellipsoid
    trial: str
    frames_used: int
    frames_with_pose: int
    frames_total: int
    markers: tuple[str, ...]
    rigid_rms_m: dict[str, float]
    rigid_frame_rms_m: tuple[float, float]
    before_m: dict[str, dict[str, tuple[float, float]]]
    after_m: dict[str, dict[str, tuple[float, float]]]
    centre_shift_m: np.ndarray
    radius_scale: np.ndarray
    posterior_sd: dict[str, float]
    determined: dict[str, float]
    determined_directions: int
    rotation_range_deg: float
    path_extent_m: dict[str, tuple[float, float]]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (mm, deg) for the calibration report and the model file. Kept by hand
        (exubio.io.records' exception): fixed keys ("used", the units), fields regrouped and
        converted per key (the centre's posterior SD in mm, the radii's relative)."""
        def mm(x: float) -> float:
            return round(float(x) * 1000.0, 2)

        def dist(d: dict[str, dict[str, tuple[float, float]]]) -> dict[str, Any]:
            return {part: {k: {"rms": mm(v[0]), "max": mm(v[1])} for k, v in per.items()} for part, per in d.items()}

        return {
            "used": True, "trial": self.trial, "frames_used": self.frames_used, "frames_with_pose": self.frames_with_pose,
            "frames_total": self.frames_total, "markers": list(self.markers),
            "ellipsoid_centre_mm": [mm(v) for v in self.ellipsoid.centre_m],
            "ellipsoid_radii_mm": [mm(v) for v in self.ellipsoid.radii_m],
            "centre_shift_mm": [mm(v) for v in self.centre_shift_m],
            "radius_scale": [round(float(v), 4) for v in self.radius_scale],
            "rigid_fit_rms_mm": {k: mm(v) for k, v in self.rigid_rms_m.items()},
            "rigid_fit_frame_rms_mm": {"median": mm(self.rigid_frame_rms_m[0]), "max": mm(self.rigid_frame_rms_m[1])},
            "contact_distance_before_mm": dist(self.before_m), "contact_distance_after_mm": dist(self.after_m),
            "posterior_sd": {k: (mm(v) if k.startswith("centre") else round(float(v), 4))
                             for k, v in self.posterior_sd.items()},
            "posterior_sd_units": "mm for the centre, relative for the radii",
            "determined": {k: round(float(v), 3) for k, v in self.determined.items()},
            "determined_directions": self.determined_directions,
            "scapula_rotation_range_deg": round(self.rotation_range_deg, 1),
            "contact_path_extent_mm": {k: [mm(v[0]), mm(v[1])] for k, v in self.path_extent_m.items()},
        }


def scapula_markers(model: Model, protocol: Protocol, static_m: np.ndarray, /) -> list[int]:
    """Indices of the protocol markers on the contact segment (the scapula) present in the static
    pose ``static_m`` (k, 3). InputError when fewer than 3, or collinear."""
    segment = model.ellipsoid.contact_points[0][0]
    idx = [j for j, m in enumerate(protocol.markers) if m.segment == segment and np.isfinite(static_m[j]).all()]
    names = [protocol.markers[j].name for j in idx]
    if len(idx) < 3:
        raise InputError(f"a functional scapula calibration needs 3 markers on the {segment} registered in the static "
                         f"pose; the protocol gives {names or 'none'}")
    local = np.array([protocol.markers[j].local_position_m for j in idx], dtype=float)
    s = np.linalg.svd(local - local.mean(axis=0), compute_uv=False)
    if s[1] < 1e-3 * s[0] or s[0] <= 0:
        raise InputError(f"a functional scapula calibration needs {segment} markers spanning a plane; {names} are "
                         f"collinear")
    return idx


def contact_points_over_motion(model: Model, protocol: Protocol, markers: np.ndarray, idx: Sequence[int], /
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The contact points (n, 2, 3) of the registered scapula rigidly fitted to ``markers``
    (n, k, 3; the protocol's markers, thorax frame) through its markers ``idx``, with the fit's
    rotations (n, 3, 3), per-frame RMS (n,) and per-frame per-marker distances (n, len(idx)).
    ``protocol`` must be bound to the calibrated ``model`` (its local positions are the
    registration). Frames missing one of the markers are NaN."""
    segment = model.ellipsoid.contact_points[0][0]
    pts = model.segment(segment).points
    local = np.array([protocol.markers[j].local_position_m for j in idx], dtype=float)
    contact_local = np.array([pts[name] for _, name in model.ellipsoid.contact_points], dtype=float)
    m = np.asarray(markers, dtype=float)[:, list(idx)]
    complete = np.isfinite(m).all(axis=(1, 2))
    m = np.where(complete[:, None, None], m, np.nan)  # a pose only from all the markers (one registration)
    R, t, rms = cluster_poses(local, m)
    contacts = np.einsum("nab,kb->nka", R, contact_local) + t[:, None, :]
    fitted = np.einsum("nab,kb->nka", R, local) + t[:, None, :]
    per_marker = np.linalg.norm(fitted - m, axis=2)
    return contacts, R, rms, per_marker


def _ellipsoid_of(base: Ellipsoid, p: np.ndarray) -> Ellipsoid:
    return dataclasses.replace(base, centre_m=np.asarray(base.centre_m, dtype=float) + p[:3],
                               radii_m=np.asarray(base.radii_m, dtype=float) * np.exp(p[3:]))


def _distances(ell: Ellipsoid, points: np.ndarray, names: Sequence[str]) -> dict[str, tuple[float, float]]:
    d = surface_distance(ell, points)  # (n, 2)
    out = {name: (float(np.sqrt(np.mean(d[:, i] ** 2))), float(np.abs(d[:, i]).max())) for i, name in enumerate(names)}
    out["all"] = (float(np.sqrt(np.mean(d**2))), float(np.abs(d).max()))
    return out


def _rotation_angle_deg(R: np.ndarray, R0: np.ndarray) -> np.ndarray:
    rel = np.einsum("nba,bc->nac", R, R0)  # R^T R0
    c = (np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def fit_scapula_motion(model: Model, protocol: Protocol, static_m: np.ndarray | Sequence[np.ndarray],
                       movement: MarkerTargets | Sequence[MarkerTargets], /) -> ScapulaMotionFit:
    """Fit the thorax ellipsoid through the scapula contact points of the static pose(s) and of
    every posture of ``movement`` (see the module docstring).

    model: the calibrated model (registered points, the static calibration's ellipsoid);
    protocol: bound to it (``calibrated_protocol``); static_m: the static pose's protocol markers
    (k, 3) (or several static poses), thorax frame, m; movement: the movement trial's prepared
    targets (same protocol, thorax frame), or several movement trials (their postures pooled).
    Returns the fit; InputError (naming the trial and the
    reason) when the movement cannot determine the ellipsoid."""
    from scipy.optimize import least_squares

    trials = [movement] if isinstance(movement, MarkerTargets) else list(movement)
    if not trials:
        raise InputError("a functional scapula calibration needs a movement trial; none given")
    src = " + ".join(t.source or "scapula trial" for t in trials)
    statics = [np.asarray(static_m, dtype=float)] if np.ndim(static_m) == 2 else [np.asarray(s, dtype=float)
                                                                                  for s in static_m]
    try:
        idx = scapula_markers(model, protocol, statics[0])
    except InputError as exc:
        raise InputError(f"{src}: {exc}") from None
    names = tuple(protocol.markers[j].name for j in idx)
    contact_names = tuple(name for _, name in model.ellipsoid.contact_points)
    pos = np.concatenate([t.positions_m for t in trials], axis=0)
    contacts, R, rms, per_marker = contact_points_over_motion(model, protocol, pos, idx)
    with_pose = np.flatnonzero(np.isfinite(rms))
    if with_pose.size < MIN_POSTURES:
        raise InputError(f"{src}: only {with_pose.size} frames have all scapula markers {list(names)}; a functional "
                         f"scapula calibration needs at least {MIN_POSTURES}")
    used = with_pose[np.unique(np.linspace(0, with_pose.size - 1, min(MAX_POSTURES, with_pose.size)).round().astype(int))]
    static_contacts, static_R = [], []
    for s in statics:
        c_s, R_s, _, _ = contact_points_over_motion(model, protocol, s[None], idx)
        if not np.isfinite(c_s).all():
            raise InputError(f"{src}: a static pose misses one of the scapula markers {list(names)}")
        static_contacts.append(c_s[0])
        static_R.append(R_s[0])
    rot = _rotation_angle_deg(R[with_pose], static_R[0])
    rot_range = float(np.nanmax(rot))
    if rot_range < MIN_ROTATION_DEG:
        raise InputError(f"{src}: the scapula turns at most {rot_range:.1f} deg from the static pose over the movement "
                         f"(a functional scapula calibration needs >= {MIN_ROTATION_DEG:g} deg: raise the arm well above "
                         f"the static pose, in one or more planes)")
    move = contacts[used]  # (u, 2, 3)
    stat = np.array(static_contacts)  # (s, 2, 3)
    w_static = np.sqrt(STATIC_WEIGHT_POSTURES)
    base = model.ellipsoid
    prior_sd = np.array([PRIOR_CENTRE_SD_M] * 3 + [PRIOR_LOG_RADIUS_SD] * 3)

    def data_residual(p: np.ndarray) -> np.ndarray:
        ell = _ellipsoid_of(base, p)
        return np.concatenate([surface_distance(ell, move).ravel(), w_static * surface_distance(ell, stat).ravel()])

    # iteratively reweighted least squares: soft-L1 weights on the data (scale ROBUST_SCALE_M), the
    # prior quadratic (a Gaussian prior; scipy's loss would make it robust too)
    weights = np.ones(move.size // 3 + stat.size // 3)
    p = np.zeros(6)
    for _ in range(ROBUST_ITERATIONS):
        def resid(x: np.ndarray, w=weights) -> np.ndarray:
            return np.concatenate([w * data_residual(x) / ROBUST_SCALE_M, x / prior_sd])

        sol = least_squares(resid, p, xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
        if not sol.success:
            raise InputError(f"{src}: the ellipsoid fit through the scapula contact points did not converge: "
                             f"{sol.message}")
        step, p = float(np.abs(sol.x - p).max()), sol.x
        z = (data_residual(p) / ROBUST_SCALE_M) ** 2
        weights = (1.0 + z) ** -0.25  # w^2 = rho'(z) of soft-L1: 1 / sqrt(1 + z)
        if step < 1e-7:
            break
    fitted = _ellipsoid_of(base, p)
    shift = p[:3]
    scale = np.exp(p[3:])
    radii = np.asarray(fitted.radii_m)
    if np.any(radii < MIN_RADIUS_M) or np.any(radii > MAX_RADIUS_M):
        raise InputError(f"{src}: the surface through the scapula contact points of the movement is degenerate "
                         f"(radii {np.round(radii * 1000).astype(int).tolist()} mm, outside "
                         f"{MIN_RADIUS_M * 1000:.0f}-{MAX_RADIUS_M * 1000:.0f} mm): the postures fit a plane or a "
                         f"point, not a thorax; the scapula markers may not follow the scapula")
    # coverage: linearised posterior with the fit's own residual as the data noise
    r_data = data_residual(p)[: move.size // 3]
    sigma = max(float(np.sqrt(np.mean(r_data**2))), MIN_CONTACT_SD_M)
    eps = 1e-6
    J = np.column_stack([(data_residual(p + eps * e) - data_residual(p - eps * e)) / (2 * eps) for e in np.eye(6)])
    info_data = J.T @ J / sigma**2
    info_prior = np.diag(1.0 / prior_sd**2)
    cov = np.linalg.inv(info_data + info_prior)
    post_sd = np.sqrt(np.diag(cov))
    # directions: generalized eigenvalues of the data's information relative to the prior's
    Ls = np.diag(prior_sd)
    ev = np.linalg.eigvalsh(Ls @ info_data @ Ls)
    directions = int(np.sum(ev >= DETERMINED_INFORMATION_RATIO))
    if directions < MIN_DETERMINED_DIRECTIONS:
        raise InputError(f"{src}: the movement's scapula postures determine only {directions} of the ellipsoid's 6 "
                         f"parameter directions (need {MIN_DETERMINED_DIRECTIONS}): the contact points cover too "
                         f"small a patch of the thorax surface (scapula rotation range {rot_range:.0f} deg)")
    extent = {}
    for i, name in enumerate(contact_names):
        c = contacts[with_pose, i]
        s = np.linalg.svd(c - c.mean(axis=0), compute_uv=False) / np.sqrt(len(c))
        extent[name] = (float(2 * s[0]), float(2 * s[1]))
    rigid = {name: float(np.sqrt(np.nanmean(per_marker[used, i] ** 2))) for i, name in enumerate(names)}
    fit = ScapulaMotionFit(
        ellipsoid=fitted, trial=src, frames_used=int(used.size), frames_with_pose=int(with_pose.size),
        frames_total=int(pos.shape[0]), markers=names, rigid_rms_m=rigid,
        rigid_frame_rms_m=(float(np.median(rms[used])), float(np.max(rms[used]))),
        before_m={"movement": _distances(base, move, contact_names), "static": _distances(base, stat, contact_names)},
        after_m={"movement": _distances(fitted, move, contact_names), "static": _distances(fitted, stat, contact_names)},
        centre_shift_m=shift.copy(), radius_scale=scale.copy(),
        posterior_sd=dict(zip(PARAMETERS, post_sd.tolist())),
        determined=dict(zip(PARAMETERS, (1.0 - post_sd / prior_sd).tolist())),
        determined_directions=directions, rotation_range_deg=rot_range, path_extent_m=extent)
    log.info("%s: thorax ellipsoid from %d scapula postures (+%d static): contact points %.1f -> %.1f mm RMS off it; "
             "centre moved %s mm, radii x %s; %d of 6 directions determined", src, used.size, len(statics),
             fit.before_m["movement"]["all"][0] * 1000, fit.after_m["movement"]["all"][0] * 1000,
             np.round(shift * 1000, 1).tolist(), np.round(scale, 3).tolist(), directions)
    return fit
