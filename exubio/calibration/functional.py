"""Functional joint centres and axes from the poses of two segments (pure numpy/scipy; the poses
of marker clusters: exubio.calibration.cluster).

* ``score``: symmetrical centre of rotation estimation (Ehrig, Taylor, Duda, Heller 2006,
  J Biomech 39:2798). Finds c1 (segment 1's frame) and c2 (segment 2's) minimising
  sum_i |R1_i c1 + t1_i - R2_i c2 - t2_i|^2; neither segment has to stay still.
* ``sara``: symmetrical axis of rotation approach (Ehrig et al. 2007, J Biomech 40:2150). The
  same stacked system [R1_i, -R2_i] x = t2_i - t1_i; for a hinge it has a one-dimensional
  (near) null space, whose right singular vector (a1, a2) gives the axis direction in each
  segment's frame; the minimum-norm solution of the other five gives a point on it.
* ``path_axis``: the fixed axis about which points of the distal body turn, from their paths
  expressed in the proximal segment's frame (plane normal and circle centre). Meant for a
  distal body with too few markers for a pose, e.g. the ulna carrying only the ulnar styloid
  marker, which lies on the pronation-supination axis and so is unaffected by pronation.

Conditioning. With M = mean_i R1_i^T R2_i, the singular values of the stacked (3n x 6) matrix
are exactly sqrt(n (1 +- sigma_k(M))). Hence for SCoRE s_min/s_max = tan(phi/2) with
cos(phi) = sigma_max(M): phi is (for small angles, exactly) the rms rotation about the axes
perpendicular to the main axis of the relative rotation. phi = 0 for a pure hinge motion, where
the centre is undetermined along the hinge axis. For SARA the axis is well defined when
s6/s5 = sqrt((1 - sigma_1)/(1 - sigma_2)) is small (one dominant rotation axis).

Thresholds (defaults, each a keyword argument):

* ``SCORE_MIN_RANGE_DEG = 20``: Ehrig et al. (2006, abstract): most methods are within 3 mm
  of the true centre from a 45 deg range of motion, SCoRE within about 1.2 mm at 20 deg under
  their most stringent noise condition; 20 deg is the smallest range their claim covers. Own
  simulation (4-marker clusters 5-15 cm from the centre, 1 mm noise per coordinate, 500
  frames): centre error 2.4 mm (median) at an 18 deg range, 0.75 mm at 33 deg, 0.3 mm at 64 deg.
  Less than 20 deg of relative rotation raises InputError.
* ``SCORE_MIN_SPREAD_DEG = 5``: rotation off the main axis (phi above). Same simulation with
  60 deg about the main axis: a pure hinge already shows 1.5 deg (pose noise), with centre
  errors up to 4 mm that depend on the noise only; at 4.3 deg the error is 0.4 mm median,
  1.4 mm worst of 10 seeds; 5 deg keeps clear of the noise floor.
* ``SARA_MIN_RANGE_DEG = 20``: rotation range about the fitted axis. Simulation (hinge, same
  clusters and noise, proximal segment still or moving): at 14 deg range the direction is off by
  3-5 deg and the point by 4-6 mm; at 23 deg 1-1.7 deg and 1.3-2.2 mm; at 42 deg 0.4-0.7 deg and
  0.5-0.9 mm. Ehrig et al. (2007, abstract): at 5 deg the best method was still about 12 mm off.
* ``SARA_MAX_CONDITION = 0.5``: s6/s5 above it means the motion is not about one axis (a
  ball-joint motion with 60 deg about one axis and +-20 deg about the two others gives 0.44,
  +-30 deg gives 0.63; a hinge gives 0.05-0.26 from 120 deg down to 23 deg of range), and the
  "axis" is a compromise between axes.
* ``PATH_MIN_RANGE_DEG = 60``: arc covered by the paths in ``path_axis``. A single point 25 cm
  from the axis, 1 mm noise, 400 frames: the direction is good from 40 deg of arc (< 1 deg) but
  the circle centre needs more: 7-13 mm off at 45 deg, 2-6 mm at 60 deg, 0.5-2 mm at 90 deg.

Frames where either pose is NaN are left out and counted. Everything here is in SI units
(m, rad); ``to_dict`` gives mm and deg for reports.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from exubio.errors import InputError

SCORE_MIN_RANGE_DEG = 20.0
SCORE_MIN_SPREAD_DEG = 5.0
SARA_MIN_RANGE_DEG = 20.0
SARA_MAX_CONDITION = 0.5
PATH_MIN_RANGE_DEG = 60.0
MIN_FRAMES = 3
_RANGE_MAX_SAMPLES = 2000  # frames used (evenly spaced) for the pairwise rotation range

__all__ = [
    "FunctionalAxis",
    "FunctionalCentre",
    "path_axis",
    "relative_rotation_range_deg",
    "sara",
    "score",
]


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
def _mm(v: np.ndarray) -> list[float] | None:
    v = np.asarray(v, dtype=float)
    return None if not np.all(np.isfinite(v)) else [round(float(x) * 1e3, 3) for x in v]


@dataclass(frozen=True)
class FunctionalCentre:
    """SCoRE joint centre.

    centre_local1 / centre_local2: (3,) the centre in segment 1's / segment 2's frame (m).
    centre_global: (n, 3) per frame, the midpoint of R1 c1 + t1 and R2 c2 + t2 (NaN in skipped
                   frames).
    rms_m:         rms over the frames used of |R1 c1 + t1 - R2 c2 - t2| (m).
    max_mismatch_m: the largest of those distances (m).
    n_frames_used / n_frames_skipped: frames in / left out (a NaN pose of either segment).
    rotation_range_deg: largest angle between two relative orientations R1^T R2 (deg).
    spread_deg:    rotation off the main relative-rotation axis, 2 atan(condition) (deg).
    condition:     smallest over largest singular value of the stacked system.
    singular_values: (6,) of the stacked system, descending.
    """

    centre_local1: np.ndarray
    centre_local2: np.ndarray
    centre_global: np.ndarray
    rms_m: float
    max_mismatch_m: float
    n_frames_used: int
    n_frames_skipped: int
    rotation_range_deg: float
    spread_deg: float
    condition: float
    singular_values: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """Summary for reports (mm, deg); the per-frame centre is left out. Kept by hand
        (exubio.io.records' exception): a fixed method name, a vector with a non-finite value
        written as null, the condition to 4 significant digits; a summary, not read back."""
        return {
            "method": "SCoRE",
            "centre_local1_mm": _mm(self.centre_local1),
            "centre_local2_mm": _mm(self.centre_local2),
            "rms_mm": round(self.rms_m * 1e3, 3),
            "max_mismatch_mm": round(self.max_mismatch_m * 1e3, 3),
            "n_frames_used": self.n_frames_used,
            "n_frames_skipped": self.n_frames_skipped,
            "rotation_range_deg": round(self.rotation_range_deg, 2),
            "spread_deg": round(self.spread_deg, 2),
            "condition": float(f"{self.condition:.4g}"),
        }


@dataclass(frozen=True)
class FunctionalAxis:
    """Functional joint axis (SARA, or ``path_axis``).

    direction_local1 / direction_local2: (3,) unit direction in segment 1's / 2's frame
                   (``path_axis``: direction_local2 and point_local2 are NaN).
    point_local1 / point_local2: (3,) a point on the axis in each frame (m). SARA: the point of
                   least |p1|^2 + |p2|^2 on the axis; ``path_axis``: the point nearest to the
                   frame origin.
    point_global / direction_global: (n, 3) per frame (midpoint of both segments' images; NaN in
                   skipped frames).
    rms_m:         SARA: rms of |R1 p1 + t1 - R2 p2 - t2|; path_axis: rms distance of the points
                   from their fitted circles (m).
    direction_rms_deg: SARA: rms angle between R1 a1 and R2 a2; path_axis: rms angle of the
                   points out of their planes as seen from the circle centre (deg).
    range_deg:     range of rotation about the axis (deg).
    off_axis_rms_deg: SARA: rms rotation about axes perpendicular to the axis (swing of the
                   relative rotation from its mean); path_axis: NaN.
    condition:     SARA: s6/s5; path_axis: smallest / middle eigenvalue of the pooled scatter,
                   square-rooted.
    n_frames_used / n_frames_skipped: frames in / left out.
    method:        "SARA" or "path".
    """

    direction_local1: np.ndarray
    point_local1: np.ndarray
    direction_local2: np.ndarray
    point_local2: np.ndarray
    point_global: np.ndarray
    direction_global: np.ndarray
    rms_m: float
    direction_rms_deg: float
    range_deg: float
    off_axis_rms_deg: float
    condition: float
    n_frames_used: int
    n_frames_skipped: int
    method: str = "SARA"

    def to_dict(self) -> dict[str, Any]:
        """Summary for reports (mm, deg); per-frame arrays are left out. Kept by hand (as
        FunctionalCentre's): keys in another order than the fields, non-finite values as null."""

        def _unit(v: np.ndarray) -> list[float] | None:
            return None if not np.all(np.isfinite(v)) else [round(float(x), 5) for x in v]

        def _num(x: float, nd: int) -> float | None:
            return None if not math.isfinite(x) else round(float(x), nd)

        return {
            "method": self.method,
            "direction_local1": _unit(self.direction_local1),
            "point_local1_mm": _mm(self.point_local1),
            "direction_local2": _unit(self.direction_local2),
            "point_local2_mm": _mm(self.point_local2),
            "rms_mm": round(self.rms_m * 1e3, 3),
            "direction_rms_deg": _num(self.direction_rms_deg, 3),
            "range_deg": round(self.range_deg, 2),
            "off_axis_rms_deg": _num(self.off_axis_rms_deg, 2),
            "condition": float(f"{self.condition:.4g}"),
            "n_frames_used": self.n_frames_used,
            "n_frames_skipped": self.n_frames_skipped,
        }


# --------------------------------------------------------------------------------------------
# Shared pieces
# --------------------------------------------------------------------------------------------
def _check_poses(who: str, R1, t1, R2, t2) -> tuple[np.ndarray, ...]:
    R1, t1, R2, t2 = (np.asarray(a, dtype=float) for a in (R1, t1, R2, t2))
    n = R1.shape[0] if R1.ndim == 3 else -1
    if R1.shape != (n, 3, 3) or R2.shape != (n, 3, 3) or t1.shape != (n, 3) or t2.shape != (n, 3):
        raise InputError(f"{who}: poses must be R1, R2 (n, 3, 3) and t1, t2 (n, 3) with the same n; got "
                         f"{R1.shape}, {t1.shape}, {R2.shape}, {t2.shape}")
    ok = (np.isfinite(R1).all(axis=(1, 2)) & np.isfinite(R2).all(axis=(1, 2))
          & np.isfinite(t1).all(axis=1) & np.isfinite(t2).all(axis=1))
    for name, R in (("R1", R1), ("R2", R2)):
        Rk = R[ok]
        err = np.abs(np.einsum("nji,njk->nik", Rk, Rk) - np.eye(3)).max(axis=(1, 2)) if Rk.size else np.zeros(0)
        det = np.linalg.det(Rk) if Rk.size else np.zeros(0)
        bad = np.flatnonzero((err > 1e-6) | (det < 0))
        if bad.size:
            i = int(np.flatnonzero(ok)[bad[0]])
            raise InputError(f"{who}: {name} is not a rotation matrix in {bad.size} frame(s) (first: {i})")
    used = int(ok.sum())
    if used < MIN_FRAMES:
        raise InputError(f"{who}: only {used} of {n} frames have both segment poses; need at least {MIN_FRAMES}")
    return R1, t1, R2, t2, ok


def _stacked(R1, t1, R2, t2) -> tuple[np.ndarray, np.ndarray]:
    """A (3n, 6) = [R1_i, -R2_i] stacked and b (3n,) = t2_i - t1_i."""
    n = R1.shape[0]
    A = np.concatenate([R1, -R2], axis=2).reshape(3 * n, 6)
    b = (t2 - t1).reshape(3 * n)
    return A, b


def relative_rotation_range_deg(R1: np.ndarray, R2: np.ndarray, /) -> float:
    """Largest angle (deg) between two relative orientations R1_i^T R2_i over the finite frames
    (at most 2000 evenly spaced frames are compared pairwise)."""
    R1 = np.asarray(R1, dtype=float)
    R2 = np.asarray(R2, dtype=float)
    ok = np.isfinite(R1).all(axis=(1, 2)) & np.isfinite(R2).all(axis=(1, 2))
    Q = np.einsum("nji,njk->nik", R1[ok], R2[ok])
    if Q.shape[0] < 2:
        return 0.0
    if Q.shape[0] > _RANGE_MAX_SAMPLES:
        Q = Q[np.linspace(0, Q.shape[0] - 1, _RANGE_MAX_SAMPLES).round().astype(int)]
    q = Rotation.from_matrix(Q).as_quat()
    best = 1.0
    for start in range(0, q.shape[0], 500):
        dots = np.abs(q[start:start + 500] @ q.T)
        best = min(best, float(dots.min()))
    return math.degrees(2.0 * math.acos(min(1.0, best)))


def _fmt_deg(x: float) -> str:
    return f"{x:.1f} deg"


# --------------------------------------------------------------------------------------------
# SCoRE
# --------------------------------------------------------------------------------------------
def score(R1: np.ndarray, t1: np.ndarray, R2: np.ndarray, t2: np.ndarray, /, *,
          min_range_deg: float = SCORE_MIN_RANGE_DEG,
          min_spread_deg: float = SCORE_MIN_SPREAD_DEG) -> FunctionalCentre:
    """Symmetrical centre of rotation estimation (Ehrig et al. 2006).

    R1, R2: (n, 3, 3) rotations local -> lab of segments 1 and 2; t1, t2: (n, 3) their origins
    (m). Frames with a NaN in either pose are skipped (counted). Raises InputError when fewer than
    3 frames remain, when the relative rotation range is below ``min_range_deg`` or when the
    rotation off the main axis (``spread_deg``) is below ``min_spread_deg`` (nearly planar
    motion: the centre is then undetermined along that axis). Pass 0 to disable a check.
    """
    who = "SCoRE"
    R1, t1, R2, t2, ok = _check_poses(who, R1, t1, R2, t2)
    n_all = ok.size
    r1, p1, r2, p2 = R1[ok], t1[ok], R2[ok], t2[ok]
    used = r1.shape[0]
    rng = relative_rotation_range_deg(r1, r2)
    if rng < min_range_deg:
        raise InputError(f"{who}: the two segments rotate by only {_fmt_deg(rng)} relative to each other over "
                         f"{used} frames; need at least {min_range_deg:g} deg (Ehrig et al. 2006)")
    A, b = _stacked(r1, p1, r2, p2)
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    cond = float(s[-1] / s[0]) if s[0] > 0 else 0.0
    spread = math.degrees(2.0 * math.atan(cond))
    if spread < min_spread_deg:
        raise InputError(f"{who}: the motion is nearly planar: {_fmt_deg(spread)} of rotation off its main axis "
                         f"(singular value ratio {cond:.3g}), need at least {min_spread_deg:g} deg; the centre is "
                         f"undetermined along that axis (for a hinge joint use SARA)")
    x = Vt.T @ ((U.T @ b) / s)
    c1, c2 = x[:3], x[3:]
    g1 = np.einsum("nab,b->na", r1, c1) + p1
    g2 = np.einsum("nab,b->na", r2, c2) + p2
    dist = np.linalg.norm(g1 - g2, axis=1)
    centre = np.full((n_all, 3), np.nan)
    centre[ok] = 0.5 * (g1 + g2)
    return FunctionalCentre(
        centre_local1=c1, centre_local2=c2, centre_global=centre,
        rms_m=float(np.sqrt(np.mean(dist ** 2))), max_mismatch_m=float(dist.max()),
        n_frames_used=used, n_frames_skipped=n_all - used,
        rotation_range_deg=rng, spread_deg=spread, condition=cond, singular_values=s,
    )


# --------------------------------------------------------------------------------------------
# SARA
# --------------------------------------------------------------------------------------------
def _twist_swing(Q: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Twist angle about ``axis`` and swing angle (rad) of each relative rotation Q (n, 3, 3),
    taken from their mean rotation (both in the frame where ``axis`` is given)."""
    rot = Rotation.from_matrix(Q)
    D = rot * rot.mean().inv()  # D_i = Q_i Q_mean^T, rotations in segment 1's frame
    q = D.as_quat()  # (x, y, z, w)
    v, w = q[:, :3], q[:, 3]
    va = v @ axis
    twist = 2.0 * np.arctan2(va, w)
    twist = (twist + np.pi) % (2.0 * np.pi) - np.pi
    perp = np.linalg.norm(v - va[:, None] * axis, axis=1)
    swing = 2.0 * np.arctan2(perp, np.sqrt(w ** 2 + va ** 2))
    return twist, swing


def sara(R1: np.ndarray, t1: np.ndarray, R2: np.ndarray, t2: np.ndarray, /, *,
         min_range_deg: float = SARA_MIN_RANGE_DEG,
         max_condition: float = SARA_MAX_CONDITION,
         direction_hint: np.ndarray | None = None) -> FunctionalAxis:
    """Symmetrical axis of rotation approach (Ehrig et al. 2007).

    Poses as for ``score``. The axis direction (a1, a2) is the right singular vector of the
    smallest singular value s6 of [R1_i, -R2_i]; a point (p1, p2) on it is the minimum-norm
    least-squares solution within the other five. The sign of a1 follows ``direction_hint``
    (segment 1's frame) if given, else its largest component is made positive; a2 agrees with it
    (R1 a1 ~ R2 a2). Raises InputError when fewer than 3 frames remain, when the rotation range
    about the axis is below ``min_range_deg``, or when s6/s5 exceeds ``max_condition`` (the
    motion is not about one axis). Pass 0 / inf to disable a check.
    """
    who = "SARA"
    R1, t1, R2, t2, ok = _check_poses(who, R1, t1, R2, t2)
    n_all = ok.size
    r1, p1, r2, p2 = R1[ok], t1[ok], R2[ok], t2[ok]
    used = r1.shape[0]
    A, b = _stacked(r1, p1, r2, p2)
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    v = Vt[-1]
    a1 = v[:3] / np.linalg.norm(v[:3])
    a2 = v[3:] / np.linalg.norm(v[3:])
    hint = a1[np.argmax(np.abs(a1))] if direction_hint is None else float(a1 @ np.asarray(direction_hint, float))
    if hint < 0:
        a1, a2 = -a1, -a2
    cond = float(s[5] / s[4]) if s[4] > 0 else math.inf
    Q = np.einsum("nji,njk->nik", r1, r2)
    twist, swing = _twist_swing(Q, a1)
    rng = math.degrees(float(twist.max() - twist.min()))
    off_axis = math.degrees(float(np.sqrt(np.mean(swing ** 2))))
    if rng < min_range_deg:
        raise InputError(f"{who}: the rotation about the fitted axis spans only {_fmt_deg(rng)} over {used} frames; "
                         f"need at least {min_range_deg:g} deg")
    if cond > max_condition:
        raise InputError(f"{who}: the motion is not about a single axis: singular value ratio s6/s5 = {cond:.3g} "
                         f"> {max_condition:g} ({_fmt_deg(off_axis)} rms rotation off the axis, {_fmt_deg(rng)} "
                         f"about it); the axis is not defined")
    x = Vt[:5].T @ ((U[:, :5].T @ b) / s[:5])
    c1, c2 = x[:3], x[3:]
    g1 = np.einsum("nab,b->na", r1, c1) + p1
    g2 = np.einsum("nab,b->na", r2, c2) + p2
    dist = np.linalg.norm(g1 - g2, axis=1)
    d1 = np.einsum("nab,b->na", r1, a1)
    d2 = np.einsum("nab,b->na", r2, a2)
    ang = np.arccos(np.clip(np.sum(d1 * d2, axis=1), -1.0, 1.0))
    dg = d1 + d2
    dg /= np.linalg.norm(dg, axis=1, keepdims=True)
    point = np.full((n_all, 3), np.nan)
    point[ok] = 0.5 * (g1 + g2)
    direction = np.full((n_all, 3), np.nan)
    direction[ok] = dg
    return FunctionalAxis(
        direction_local1=a1, point_local1=c1, direction_local2=a2, point_local2=c2,
        point_global=point, direction_global=direction,
        rms_m=float(np.sqrt(np.mean(dist ** 2))),
        direction_rms_deg=math.degrees(float(np.sqrt(np.mean(ang ** 2)))),
        range_deg=rng, off_axis_rms_deg=off_axis, condition=cond,
        n_frames_used=used, n_frames_skipped=n_all - used, method="SARA",
    )


# --------------------------------------------------------------------------------------------
# Axis from point paths
# --------------------------------------------------------------------------------------------
def path_axis(points_local: np.ndarray, /, *, min_range_deg: float = PATH_MIN_RANGE_DEG,
              max_condition: float = SARA_MAX_CONDITION,
              direction_hint: np.ndarray | None = None) -> FunctionalAxis:
    """Fixed axis from the paths of points of the distal body in the proximal segment's frame.

    points_local: (n, m, 3), m >= 1 points fixed to the distal body, expressed in the proximal
    frame (m); NaN where missing (a frame is used if all m points are finite). For a hinge each
    point moves on a circle in a plane normal to the axis: the direction is the eigenvector of
    the smallest eigenvalue of the pooled within-point scatter, the point is the centre common to
    all circles (algebraic circle fit in the plane, one radius per point). Returns a
    FunctionalAxis with method "path" (segment-2 fields NaN). Raises InputError when fewer than 3
    frames remain, the arc spanned is below ``min_range_deg``, or the paths are not planar enough
    (sqrt of smallest / middle scatter eigenvalue above ``max_condition``).
    """
    who = "path_axis"
    P = np.asarray(points_local, dtype=float)
    if P.ndim == 2:
        P = P[:, None, :]
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(f"{who}: points must have shape (n_frames, m, 3), got {np.shape(points_local)}")
    ok = np.isfinite(P).all(axis=(1, 2))
    n_all, m = P.shape[:2]
    X = P[ok]
    used = X.shape[0]
    if used < MIN_FRAMES:
        raise InputError(f"{who}: only {used} of {n_all} frames have all {m} points; need at least {MIN_FRAMES}")
    centred = X - X.mean(axis=0)
    scatter = np.einsum("nja,njb->ab", centred, centred)
    evals, evecs = np.linalg.eigh(scatter)
    a = evecs[:, 0]
    hint = a[np.argmax(np.abs(a))] if direction_hint is None else float(a @ np.asarray(direction_hint, float))
    if hint < 0:
        a = -a
    cond = float(np.sqrt(max(evals[0], 0.0) / evals[1])) if evals[1] > 0 else math.inf
    # in-plane basis
    e1 = evecs[:, 2]
    e2 = np.cross(a, e1)
    u = np.einsum("nja,a->nj", X, e1)
    w = np.einsum("nja,a->nj", X, e2)
    # 2 u.cx + 2 w.cy + k_j = u^2 + w^2, k_j = r_j^2 - |c|^2
    rows = np.zeros((used * m, 2 + m))
    rows[:, 0] = 2.0 * u.reshape(-1)
    rows[:, 1] = 2.0 * w.reshape(-1)
    rows[np.arange(used * m), 2 + np.tile(np.arange(m), used)] = 1.0
    rhs = (u ** 2 + w ** 2).reshape(-1)
    sol, *_ = np.linalg.lstsq(rows, rhs, rcond=None)
    cx, cy = sol[:2]
    radii2 = sol[2:] + cx ** 2 + cy ** 2
    if np.any(radii2 <= 0):
        raise InputError(f"{who}: the circle fit failed (a point does not move on a circle)")
    radii = np.sqrt(radii2)
    du, dw = u - cx, w - cy
    rho = np.sqrt(du ** 2 + dw ** 2)
    heights = np.einsum("nja,a->nj", X, a)
    off_plane = heights - heights.mean(axis=0)
    rms = float(np.sqrt(np.mean((rho - radii) ** 2 + off_plane ** 2)))
    tilt = np.arctan2(off_plane, radii)
    angles = np.unwrap(np.arctan2(dw, du), axis=0)  # (n, m)
    # the arc of the point farthest from the axis (most reliable)
    j = int(np.argmax(radii))
    rng = math.degrees(float(angles[:, j].max() - angles[:, j].min()))
    if radii[j] < 1e-9 or rng < min_range_deg:
        raise InputError(f"{who}: the points turn by only {_fmt_deg(rng)} about the fitted axis over {used} frames; "
                         f"need at least {min_range_deg:g} deg")
    if cond > max_condition:
        raise InputError(f"{who}: the paths do not lie in one plane: scatter ratio {cond:.3g} > {max_condition:g}; "
                         f"the axis is not defined")
    c = cx * e1 + cy * e2  # nearest point to the origin on the axis (no component along a)
    nan3 = np.full(3, np.nan)
    return FunctionalAxis(
        direction_local1=a, point_local1=c, direction_local2=nan3, point_local2=nan3.copy(),
        point_global=np.full((n_all, 3), np.nan), direction_global=np.full((n_all, 3), np.nan),
        rms_m=rms, direction_rms_deg=math.degrees(float(np.sqrt(np.mean(tilt ** 2)))),
        range_deg=rng, off_axis_rms_deg=math.nan, condition=cond,
        n_frames_used=used, n_frames_skipped=n_all - used, method="path",
    )
