"""A standard uncertainty (rad) on every anatomical angle in every frame, and the frames where an
angle's sequence is near its gimbal lock.

The uncertainty is the first-order propagation of the markers' errors through the reconstruction:
at a pose q the weighted, constrained least-squares step maps marker displacements dm to coordinate
changes dq = K dm, K = N (A^T W A)^+ A^T W with A = J N (N: the null space of the ellipsoid
constraints' G; held and locked coordinates left out; exubio.trust.observability), and the angles
move by D dq (D = d angle / d q). The markers' error covariance has two parts:

* measurement noise, ``NOISE_MM`` per coordinate, independent between markers;
* the model's misfit, where the reconstruction shows one: a segment whose markers lie farther from
  their model points than noise and the artefact explain (the excess v of its mean square residual
  per coordinate over what those leave after the least-squares step, ``expected_residual_ms``) may
  be off by that much as a whole. It enters twice: as marker errors (a rigid rotation of SD
  sqrt(v)/rho per axis, rho the RMS distance of its markers from their centroid, and a translation
  of SD sqrt(v)) carried through the step, and as the segment's frame turned by the rotation that
  carries its model points onto its markers, scaled by the share of the residual that is misfit
  (``misfit_angle_variance``): the step does not follow a misfit, by construction, so the first
  alone leaves out what the bone is off by. A model that cannot follow the bones (a girdle that
  does not fit the subject, a thorax that moved while assumed still) thus widens the angles it
  moves, frame by frame;
* the soft-tissue artefact (``exubio.trust.sta_amplitude``, fitted on bone pins): each segment's
  markers move together by a rigid rotation about their centroid and a translation (standard
  deviations per ISB axis, proportional to the motion away from the reference posture:
  ``STAAmplitude.skin_driver``), plus
  independent non-rigid parts. The rigid part is what averaging over a cluster cannot remove: it is
  why an angle's error under real skin is far larger than its marker residual suggests. The
  scapula's and the humerus's clusters move together (both skins are dragged by the same arm): their
  cross second moment, measured on the same pins, couples the two segments' rigid parts;
* what the model's girdle cannot follow (``girdle_angle_variance``): a rigid clavicle about a fixed
  sternoclavicular joint, a scapula on a thorax ellipsoid and a fixed GH centre are not a real girdle,
  and with skin that does not slide at all the model's scapula and humerus frames still miss the
  bones' (``exubio.truth.girdle``, measured on bone pins); those two frames are taken as turned by a
  random rotation of that size, growing with the humerus's rotation from rest like the artefact;
* in a run that assumes the thorax still (no thorax marker: ``exubio truth``), the trunk's unseen
  motion (``trunk_angle_variance``), added by ``observability.angle_determinacy`` to the variance.

The variance is D K Sigma K^T D^T. It is not the residual of this trial: a trial whose markers fit
the model well can still carry a large rigid artefact, which no residual shows.

An angle is not ``measured`` in a frame where its uncertainty exceeds ``U_BOUND_DEG`` (the ST, GH and HT
angles, whose segments the artefact model was measured on: ``BOUND_SETS``) or where its
sequence is within ``GIMBAL_MARGIN_DEG`` of its gimbal lock (first and third angle only: the middle
angle stays defined): ISB GH and HT Y-X'-Y'' at elevations below the margin (the plane of elevation
and the axial rotation of an arm at the side are not defined), a Cardan sequence with its middle
angle near +-90 deg.
"""
from __future__ import annotations

import warnings
from typing import Mapping

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.trust.design import constrained_design
from exubio.trust.sta_amplitude import STAAmplitude

__all__ = ["girdle_angle_variance", "ellipsoid_from_skin", "misfit_angle_variance", "skin_ellipsoid_variance", "BOUND_SETS", "bound_applies", "NOISE_MM", "U_BOUND_DEG", "GIMBAL_MARGIN_DEG", "marker_covariance", "sensitivity", "gimbal_mask",
           "expected_residual_ms", "UNCERTAINTY_DEFINITION"]

NOISE_MM = 1.0
"""Marker measurement noise (SD per coordinate, mm) after the low-pass filter: optical systems
reconstruct a marker to 0.2-1 mm; 1 mm is the conservative end."""

U_BOUND_DEG = 10.0
"""An angle whose standard uncertainty exceeds this is not measured in that frame: its 95 % band
(+-2u) would then span more than 40 deg, wider than the differences shoulder studies report between
groups or tasks (e.g. 5-15 deg of scapular upward rotation between patients and controls)."""

GIMBAL_MARGIN_DEG = 25.0
"""Within this of a sequence's gimbal lock its first and third angles are not measured. At 25 deg
the two angles' sensitivity to the segment's orientation is 1/sin(25 deg) = 2.4 times its value
away from the lock; the ISB GH Y-X'-Y'' plane of elevation and axial rotation errors of 5-7 deg at
13-21 deg of GH elevation (SIER, issue 33) come from inside this band."""

UNCERTAINTY_DEFINITION = (
    f"standard uncertainty (1 SD, deg): {NOISE_MM:g} mm marker noise and the soft-tissue artefact model fitted on "
    "bone pins (rigid cluster rotation and translation plus non-rigid parts per segment, the scapula's and humerus's "
    "correlated, growing with the motion from the reference posture; exubio.trust.sta_amplitude), carried through "
    "the reconstruction's first-order sensitivity, and where a segment's markers fit the model worse than noise and "
    "the artefact explain, that misfit as a turn of the segment's frame (the rotation carrying its model points onto "
    "its markers), the scapula's and humerus's frames turned by what the model's girdle (a rigid clavicle, a scapula "
    "on a thorax ellipsoid) cannot follow of the bones even with skin that does not slide (exubio.truth.girdle, "
    "fitted on the same pins), and where the calibration fitted the thorax ellipsoid through the scapula's skin poses away from "
    "rest (a scapula trial, several statics), the scapula's frame turned by its cluster's whole rotation"
    f"; an ST, GH or HT angle is not measured where u > {U_BOUND_DEG:g} deg, any angle within "
    f"{GIMBAL_MARGIN_DEG:g} deg of its sequence's gimbal lock (SC, AC and distal angles: u from coefficients borrowed "
    "from the humerus, no bone data)")

BOUND_SETS = ("ST_", "GH_", "HT_")
"""The angles the bound judges: those between segments the bone-pin artefact model was measured on
(thorax, scapula, humerus). The SC, AC, elbow, forearm and wrist angles carry an uncertainty made
with borrowed coefficients (exubio.trust.sta_amplitude) and are not set 'not measured' by it."""


def bound_applies(angle: str) -> bool:
    return angle.startswith(BOUND_SETS)


_SETS = (("SC", "YXZ"), ("AC", "YXZ"), ("ST", "YXZ"), ("GH", "YXY"), ("GH_phadke", "XZY"), ("HT", "YXY"))


def gimbal_mask(angles: np.ndarray, /) -> np.ndarray:
    """(n, 22) bool: the first and third angle of each shoulder set (ANATOMICAL_ANGLES order: the
    first 18 columns, six sets of three) near its sequence's gimbal lock; distal angles never."""
    a = np.atleast_2d(angles)
    out = np.zeros(a.shape, dtype=bool)
    s = np.sin(np.radians(GIMBAL_MARGIN_DEG))
    for i, (_, seq) in enumerate(_SETS):
        mid = a[:, 3 * i + 1]
        near = np.abs(np.sin(mid)) < s if seq[0] == seq[2] else np.abs(np.cos(mid)) < s
        out[:, 3 * i] = near
        out[:, 3 * i + 2] = near
    return out


def sensitivity(kin: Kinematics, points: PointSet, qf: np.ndarray, present: np.ndarray, weights: np.ndarray,
                free: np.ndarray, *, with_jacobian: bool = False, design: tuple | None = None,
                minv: np.ndarray | None = None):
    """K (b, m, 3k): coordinate change per marker displacement of the weighted, constrained
    least-squares step at poses qf (b, m); zero rows for coordinates not in ``free``. With
    ``with_jacobian``: (K, J) with J (b, 3k, m) the markers' Jacobian (zero columns for the others),
    so J K is the step's hat matrix. ``design`` (constrained_design of the same arguments) and
    ``minv`` (the pseudo-inverse of its M): where the caller has them (the same numbers)."""
    b, m = qf.shape
    k = present.shape[1]
    J, N, A, w3, M = constrained_design(kin, points, qf, present, weights, free) if design is None else design
    Minv = np.linalg.pinv(M, rcond=1e-12, hermitian=True) if minv is None else minv
    Kf = N @ Minv @ (np.swapaxes(A, 1, 2) * w3[:, None, :])
    K = np.zeros((b, m, 3 * k))
    K[:, free, :] = Kf
    if with_jacobian:
        Jf = np.zeros((b, 3 * k, m))
        Jf[:, :, free] = J
        return K, Jf
    return K


def _skew(r: np.ndarray) -> np.ndarray:
    z = np.zeros(r.shape[:-1])
    return np.stack([np.stack([z, -r[..., 2], r[..., 1]], -1), np.stack([r[..., 2], z, -r[..., 0]], -1),
                     np.stack([-r[..., 1], r[..., 0], z], -1)], -2)


def _rotation_angle(R: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))


def _driver(names: list, R: np.ndarray) -> np.ndarray:
    """(b,) rad: the amplitude model's driver, the humerus's rotation from its reference orientation, from
    the segments' rotations R (b, s, 3, 3) named ``names``; zero without a humerus."""
    return _rotation_angle(R[:, names.index("humerus")]) if "humerus" in names else np.zeros(R.shape[0])


def marker_covariance(kin: Kinematics, points: PointSet, qf: np.ndarray, present: np.ndarray,
                      amplitude: STAAmplitude, /, *, noise_mm: float = NOISE_MM,
                      anatomical: dict[str, np.ndarray] | None = None,
                      residual_m: np.ndarray | None = None, expected_ms: np.ndarray | None = None) -> np.ndarray:
    """Sigma (b, 3k, 3k) m^2: the markers' error covariance at poses qf (module docstring). Missing
    markers carry no weight in K, so their rows do not matter. ``anatomical``: the ISB frames of the
    scapula and humerus (segment -> (b, 3, 3)) where the caller has them (their axes are the
    amplitudes' axes); other segments use their model frames. With ``residual_m`` (b, k, the
    reconstruction's marker residuals) and ``expected_ms`` (b, k, the mean square residual per
    coordinate that noise and the artefact leave: ``expected_residual_ms``), the misfit term alone
    (module docstring); else the noise and the artefact."""
    model = kin.model
    b = qf.shape[0]
    k = len(points.segment_index)
    R, _ = kin.poses(qf)  # (b, s, 3, 3)
    P = kin.points(qf, points)  # (b, k, 3)
    misfit_only = expected_ms is not None and residual_m is not None
    sigma = np.zeros((b, 3 * k, 3 * k))
    idx = np.arange(3 * k)
    if not misfit_only:
        sigma[:, idx, idx] = (noise_mm * 1e-3) ** 2
    names = [s.name for s in model.segments]
    theta_hum = amplitude.skin_driver(_driver(names, R))
    seen: dict[str, tuple] = {}  # measured segments: (rows, B, T, theta) for the cross terms
    for s_idx in np.unique(points.segment_index):
        sel = np.flatnonzero(points.segment_index == s_idx)
        seg = names[s_idx]
        C6, nonrigid, measured = amplitude.of(seg)
        if measured or seg == "clavicle":
            theta = theta_hum
        else:  # no bone data: the humerus's coefficients, driven by the segment's own joint (its rotation from its parent)
            parent = model.segments[s_idx].parent
            Rp = R[:, names.index(parent)] if parent in names else np.eye(3)
            theta = amplitude.skin_driver(_rotation_angle(np.swapaxes(Rp, -1, -2) @ R[:, s_idx]))
        axes = anatomical[seg] if anatomical is not None and seg in anatomical else R[:, s_idx]
        ok = present[:, sel]
        cnt = np.maximum(ok.sum(axis=1), 1)
        c = (np.where(ok[..., None], P[:, sel], 0.0)).sum(axis=1) / cnt[:, None]
        r = P[:, sel] - c[:, None, :]  # (b, j, 3)
        B = np.concatenate([-_skew(r), np.broadcast_to(np.eye(3), r.shape + (3,))], axis=-1)  # (b, j, 3, 6)
        T = np.zeros((b, 6, 6))
        T[:, :3, :3] = axes
        T[:, 3:, 3:] = axes
        S6 = T @ C6[None] @ np.swapaxes(T, -1, -2) * (theta ** 2)[:, None, None]
        if misfit_only:
            res = np.where(ok, residual_m[:, sel], np.nan)
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                exp = np.nanmean(np.where(ok, expected_ms[:, sel], np.nan), axis=1)
                v = np.nan_to_num(np.nanmean(res ** 2, axis=1) / 3.0 - exp, nan=0.0)
            v = np.maximum(v, 0.0)
            rho2 = np.maximum((np.where(ok[..., None], r, 0.0) ** 2).sum(axis=(1, 2)) / cnt, 1e-4)
            S6 = np.zeros((b, 6, 6))
            S6[:, :3, :3] = (v / rho2)[:, None, None] * np.eye(3)
            S6[:, 3:, 3:] = v[:, None, None] * np.eye(3)
        C = _bilinear_blocks(B, S6, B)  # (b, j, 3, j, 3)
        if not misfit_only:
            S_nr = axes @ np.diag(nonrigid ** 2)[None] @ np.swapaxes(axes, -1, -2) * (theta ** 2)[:, None, None]
            for a_i in range(len(sel)):
                C[:, a_i, :, a_i, :] += S_nr
        rows = (3 * sel[:, None] + np.arange(3)[None, :]).reshape(-1)
        sigma[:, rows[:, None], rows[None, :]] += C.reshape(b, 3 * len(sel), 3 * len(sel))
        if measured and not misfit_only:
            seen[seg] = (rows, B, T, theta)
    names_seen = list(seen)
    for i, a in enumerate(names_seen):  # two bones' clusters move together (both driven by the arm)
        for c in names_seen[i + 1:]:
            X = amplitude.cross_of(a, c) if hasattr(amplitude, "cross_of") else None
            if X is None:
                continue
            ra, Ba, Ta, tha = seen[a]
            rc, Bc, Tc, _ = seen[c]
            S = Ta @ X[None] @ np.swapaxes(Tc, -1, -2) * (tha ** 2)[:, None, None]
            Cx = _bilinear_blocks(Ba, S, Bc).reshape(b, ra.size, rc.size)
            sigma[:, ra[:, None], rc[None, :]] += Cx
            sigma[:, rc[:, None], ra[None, :]] += np.swapaxes(Cx, 1, 2)
    return sigma


def _bilinear_blocks(X: np.ndarray, S: np.ndarray, Y: np.ndarray, /) -> np.ndarray:
    """np.einsum("bixk,bkl,bjyl->bixjy", X, S, Y) (the covariance blocks X S Y^T of two marker
    clusters), by the compiled kernel exubio.model.batch_kernels.bilinear_blocks: the same products
    summed in the same order (bit for bit), about 10 times faster."""
    from exubio.model import batch_kernels as kernels  # numba: imported where used

    X, S, Y = (np.ascontiguousarray(a, dtype=float) for a in (X, S, Y))
    out = np.empty(X.shape[:3] + Y.shape[1:3])
    kernels.bilinear_blocks(X, S, Y, out)
    return out


def quadratic_forms(D: np.ndarray, S: np.ndarray, /) -> np.ndarray:
    """(B, A): the variances diag(D S D^T) of D (B, A, n) under the covariances S (B, n, n):
    np.einsum("bai,bij,baj->ba", D, S, D), by the compiled kernel
    exubio.model.batch_kernels.quadratic_forms (bit for bit, about 3 times faster)."""
    from exubio.model import batch_kernels as kernels  # numba: imported where used

    D, S = np.ascontiguousarray(D, dtype=float), np.ascontiguousarray(S, dtype=float)
    out = np.empty(D.shape[:2])
    kernels.quadratic_forms(D, S, out)
    return out


def expected_residual_ms(J: np.ndarray, K: np.ndarray, sigma: np.ndarray, /) -> np.ndarray:
    """(b, k): the mean square residual per coordinate of each marker that marker errors of
    covariance ``sigma`` (b, 3k, 3k) leave after the least-squares step (hat matrix J K): the part of
    the artefact and noise the model cannot follow, which a residual shows without any misfit."""
    b, n3, _ = sigma.shape
    I_H = np.eye(n3)[None] - J @ K
    R = I_H @ sigma @ np.swapaxes(I_H, -1, -2)
    d = np.einsum("bii->bi", R).reshape(b, n3 // 3, 3)
    return d.sum(axis=2) / 3.0


def frame_angle_turns(frames: dict, turned, /) -> np.ndarray:
    """(b, n, 3): the change of the frame angles (``angles_of_frames``, its order; n = 18 with every
    shoulder frame) per unit of a small rotation w about the thorax's axes applied to the ISB frames
    ``frames`` (segment -> (b, 3, 3)) for which ``turned(name)`` is true, the others kept (first order,
    a forward difference of 1e-6 rad, wrapped)."""
    from exubio.model.angles import angles_of_frames

    sets = list(angles_of_frames(frames))

    def table(fr):
        a = angles_of_frames(fr)
        return np.concatenate([a[s] for s in sets], axis=-1)

    base = table(frames)
    G = np.zeros(base.shape + (3,))
    eps = 1e-6
    for i in range(3):
        w = np.zeros(3)
        w[i] = eps
        Q = np.eye(3) + _skew(w)
        moved = {s: (Q @ F if turned(s) else F) for s, F in frames.items()}
        G[..., i] = ((table(moved) - base + np.pi) % (2 * np.pi) - np.pi) / eps
    return G


MISFIT_MIN_MARKERS = 3
"""A segment's misfit turns its frame (``misfit_angle_variance``) only where at least this many of
its markers are seen: fewer define no rotation."""

DIRECT_MISFIT = True  # benchmarks and studies only: False leaves the misfit to the step (K) alone, as before


def misfit_angle_variance(kin: Kinematics, points: PointSet, qf: np.ndarray, present: np.ndarray,
                          residual_m: np.ndarray, expected_ms: np.ndarray, n_angles: int, /, *,
                          measured_m: np.ndarray | None = None, frames: dict | None = None) -> np.ndarray:
    """(b, n_angles) rad^2: what a segment the model does not follow adds to the angles of its frame.

    A segment whose markers lie farther from their model points than noise and the artefact leave
    (the excess v of its mean square residual per coordinate over ``expected_ms``; at least
    ``MISFIT_MIN_MARKERS`` markers seen) is taken as turned away from its model frame, and every angle
    of its ISB frame moves with it (d angle / d rotation of that frame alone, the other frames kept):
    - with ``measured_m`` (b, k, 3: the markers the reconstruction tracked), by the rotation omega
      that best carries the model points onto the markers (least squares, with a translation), scaled by
      sqrt(v / (v + expected)): the share of the residual that noise and the artefact do not explain.
      A misfit that is a shift of the cluster (a scapula off its ellipsoid) turns no frame;
    - without (a reconstruction read back from its files keeps the distances only), by a rotation of SD
      sqrt(v)/rho per axis (rho: the RMS distance of the markers from their centroid): a shift is
      then taken as a turn, which errs on the wide side.
    Carried through the least-squares step instead (``marker_covariance``'s misfit term) the turn is
    mostly lost: a residual is what the step did not follow, so the step's response to it is small
    by construction, while the bone is off by it (measured on the ISB STA data-sharing trials with
    every skin marker carried by its bone: in an arm extension the scapula markers lay 18-73 mm from
    the model, ST upward rotation and GH elevation were 11-28 deg off, and the step's misfit term
    gave u of 4-11 deg). Frame angles only (the first columns, as ``angles_of_frames`` orders them);
    the distal angles, coordinates, get nothing here. ``frames``: the ISB frames at qf
    (``segment_anatomical_rotations``) where the caller has them."""
    from exubio.model.angles import segment_anatomical_rotations

    model = kin.model
    b = qf.shape[0]
    P = kin.points(qf, points)
    names = [s.name for s in model.segments]
    frames = segment_anatomical_rotations(model, qf, kinematics=kin) if frames is None else frames
    out = np.zeros((b, n_angles))
    for s_idx in np.unique(points.segment_index):
        seg = names[s_idx]
        if seg not in frames:
            continue
        sel = np.flatnonzero(points.segment_index == s_idx)
        ok = present[:, sel] & np.isfinite(residual_m[:, sel])
        cnt = ok.sum(axis=1)
        if not (cnt >= MISFIT_MIN_MARKERS).any():
            continue
        c = np.where(ok[..., None], P[:, sel], 0.0).sum(axis=1) / np.maximum(cnt, 1)[:, None]
        r = np.where(ok[..., None], P[:, sel] - c[:, None, :], 0.0)  # (b, j, 3)
        rho2 = (r ** 2).sum(axis=(1, 2)) / np.maximum(cnt, 1)
        with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            exp = np.nan_to_num(np.nanmean(np.where(ok, expected_ms[:, sel], np.nan), axis=1), nan=0.0)
            v = np.maximum(np.nan_to_num(np.nanmean(np.where(ok, residual_m[:, sel], np.nan) ** 2, axis=1) / 3.0 - exp,
                                         nan=0.0), 0.0)
        enough = cnt >= MISFIT_MIN_MARKERS
        if not (enough & (v > 0)).any():
            continue  # no misfit in these frames: nothing turns (the usual case)
        G = frame_angle_turns(frames, lambda name, seg=seg: name == seg)  # this frame alone turns
        if measured_m is not None:
            e = measured_m[:, sel] - P[:, sel]
            use = ok & np.isfinite(e).all(axis=2)
            enough &= use.sum(axis=1) >= MISFIT_MIN_MARKERS
            A = np.concatenate([np.broadcast_to(np.eye(3), r.shape + (3,)), -_skew(r)], axis=-1)  # e = t + w x r
            A = np.where(use[..., None, None], A, 0.0)
            M = np.einsum("bjxk,bjxl->bkl", A, A)
            y = np.einsum("bjxk,bjx->bk", A, np.where(use[..., None], e, 0.0))
            turn = np.einsum("bkl,bl->bk", np.linalg.pinv(M, rcond=1e-9, hermitian=True), y)[:, 3:]
            with np.errstate(invalid="ignore", divide="ignore"):
                share = np.where(v > 0, v / (v + exp), 0.0)
            turn = turn * np.sqrt(np.where(enough, share, 0.0))[:, None]
            out[:, : G.shape[1]] += np.einsum("bai,bi->ba", G, turn) ** 2
        else:
            var = np.where(enough, v / np.maximum(rho2, 1e-4), 0.0)  # rad^2 per axis
            out[:, : G.shape[1]] += var[:, None] * (G ** 2).sum(axis=2)
    return out


def trunk_angle_variance(kin: Kinematics, points: PointSet, qf: np.ndarray, DK: np.ndarray, amplitude: STAAmplitude,
                         /) -> np.ndarray:
    """(b, a) rad^2: what a trunk that moves unseen, in a run that assumes the thorax still, adds to
    each anatomical angle's variance at poses qf (b, m). The trunk turns by omega (thorax axes, about
    IJ: the thorax frame's origin) and IJ moves by t, with the second moment C (6, 6) the amplitude
    model gives at the humerus's rotation theta (``STAAmplitude.trunk_at``: a constant as shipped,
    exubio.truth.trunk_amplitude); every marker then moves by
    omega x (p - IJ) + t in the assumed thorax frame, and the reconstruction follows by DK (b, a, 3k:
    the angles' change per marker displacement) as far as the model lets it (the sternoclavicular
    joint and the ellipsoid are fixed in the thorax); the angles relative to the (assumed) thorax
    (SC, ST, HT) of the bones themselves turn by omega, the relative ones (AC, GH, distal) do not. The
    error is the difference: E = DK B - G, variance E C E^T."""
    from exubio.model.angles import anatomical_frames, segment_anatomical_rotations

    model = kin.model
    b = qf.shape[0]
    R, p = kin.poses(qf)
    names = [s.name for s in model.segments]
    origin = p[:, names.index("thorax")] if "thorax" in names else np.zeros((b, 3))
    T = R[:, names.index("thorax")] if "thorax" in names else np.broadcast_to(np.eye(3), (b, 3, 3))
    r = kin.points(qf, points) - origin[:, None, :]  # (b, k, 3)
    B = np.concatenate([-_skew(r), np.broadcast_to(np.eye(3), r.shape + (3,))], axis=-1)  # (b, k, 3, 6)
    B = B.reshape(b, -1, 6)
    T6 = np.zeros((b, 6, 6))
    T6[:, :3, :3] = T
    T6[:, 3:, 3:] = T
    frames = segment_anatomical_rotations(model, qf, kinematics=kin, frames=anatomical_frames(model), rotations=R)
    turns = frame_angle_turns(frames, lambda name: name != "thorax")  # the bones turn about the thorax's axes
    G = np.zeros((b, DK.shape[1], 6))
    G[:, : turns.shape[1], :3] = turns
    E = (DK @ B - G) @ T6  # (b, a, 6): per unit of the trunk's motion in its own axes
    return np.einsum("bai,bij,baj->ba", E, amplitude.trunk_at(_driver(names, R)), E)


def girdle_angle_variance(kin: Kinematics, qf: np.ndarray, amplitude: STAAmplitude, n_angles: int,
                          frames: dict | None = None, /) -> np.ndarray:
    """(b, n_angles) rad^2: what the model's girdle cannot follow of the bones adds to the angles at
    poses qf (b, m) (zero where the amplitude model has no ``girdle``).

    The model's scapula and humerus ISB frames are taken as turned off the bones by rotation vectors
    (in their own axes) of second moment C (theta + theta_0)^2 (``STAAmplitude.girdle``, 6 x 6, the two
    frames together; theta the humerus's rotation from rest, theta_0 ``girdle_offset_rad``: the scapula
    is off the model's near rest too), and every angle of either frame moves with it (e = d angle / d
    rotation of that frame alone, the other frames kept: ST, GH and HT): e C e^T (theta + theta_0)^2, or
    nothing where that is negative. C is the girdle's error with no skin plus twice its
    covariance with what the skin adds (``exubio.truth.girdle``: the two partly cancel on the pins,
    and the skin's part is already in u), so it is not positive definite. ``frames``: the ISB frames
    at qf where the caller has them. On the standing S2M pin trials, with skin markers carried
    rigidly by the bones, the model's scapula frame is up to 16 deg off the bone about an ISB axis (RMS
    per bin of theta, growing with it); without this term a lab's u covered the bone's ST, GH and HT
    angles within +-2u in fewer than 90 % of frames in 17 of the standing tasks' 60 task-angle cells
    (``studies/bone_u_girdle.py``). Frame angles only (the first columns, as ``angles_of_frames``
    orders them)."""
    from exubio.model.angles import segment_anatomical_rotations

    model = kin.model
    b = qf.shape[0]
    out = np.zeros((b, n_angles))
    names = [s.name for s in model.segments]
    if amplitude.girdle is None or "scapula" not in names or "humerus" not in names:
        return out
    R, _ = kin.poses(qf)
    theta = _driver(names, R)
    frames = segment_anatomical_rotations(model, qf, kinematics=kin) if frames is None else frames
    E = np.concatenate([frame_angle_turns(frames, lambda name, s=s: name == s) @ frames[s]
                        for s in ("scapula", "humerus")], axis=2)  # (b, 18, 6) per rad of each frame's own axes
    C = np.asarray(amplitude.girdle, dtype=float)
    drive = amplitude.girdle_driver(theta)
    out[:, : E.shape[1]] = np.maximum(np.einsum("bai,ij,baj->ba", E, C, E), 0.0) * (drive ** 2)[:, None]
    return out


def ellipsoid_from_skin(calibration, /) -> bool:
    """Whether a calibration (its record: ``CalibrationReport.to_dict()``, which a calibrated model
    carries as ``model.metadata["calibration"]``, or the report itself) fitted the thorax ellipsoid
    through scapula poses the skin markers gave away from the rest posture: a scapula movement trial
    (``--scapula-trial``) or several static postures."""
    if not calibration:
        return False
    get = calibration.get if isinstance(calibration, Mapping) else (lambda key: getattr(calibration, key, None))
    scapula = (get("functional") or {}).get("scapula") or {}
    return bool(scapula.get("used")) or len(get("ellipsoid_poses_mm") or ()) > 1


def skin_ellipsoid_variance(kin: Kinematics, qf: np.ndarray, amplitude: STAAmplitude, n_angles: int, /, *,
                            frames: dict | None = None) -> np.ndarray:
    """(b, n_angles) rad^2: what a thorax ellipsoid fitted through the scapula's skin markers
    (``ellipsoid_from_skin``) adds to the angles at poses qf (b, m).

    An ellipsoid calibrated at rest holds the model's scapula on a surface its skin markers did not
    shape away from rest, and so takes back part of the skin's rigid sliding over the scapula (the
    step K carries the rest). An ellipsoid fitted through the poses the skin markers gave over a
    movement has taken that sliding into its shape: the model's scapula then turns with its marker
    cluster. The scapula's ISB frame is therefore taken as turned by the cluster's whole rigid
    rotation of the artefact model (rotation vector covariance C_rot theta^2 in the scapula's ISB
    axes, theta the humerus's rotation from rest), and every angle of that frame moves with it (ST,
    and GH, whose proximal frame it is). Measured on the bone-pin trials of one subject (ISB STA
    data-sharing sample, S2M; ``studies/scapula_trial_bone.py``): the ellipsoid fitted on a scapula
    trial put ST upward rotation 1-10 deg farther from the bone than the static calibration in all 9
    pairs of calibration and trial, and within +-2u of the bone in only 40-98 % of frames without
    this term. Frame angles only (the first columns, as ``angles_of_frames`` orders them)."""
    from exubio.model.angles import segment_anatomical_rotations

    model = kin.model
    b = qf.shape[0]
    out = np.zeros((b, n_angles))
    names = [s.name for s in model.segments]
    if "scapula" not in names or "humerus" not in names:
        return out
    C6, _, measured = amplitude.of("scapula")
    if not measured:
        return out
    R, _ = kin.poses(qf)
    theta = amplitude.skin_driver(_driver(names, R))
    frames = segment_anatomical_rotations(model, qf, kinematics=kin) if frames is None else frames
    axes = frames["scapula"]
    Cw = axes @ np.asarray(C6)[None, :3, :3] @ np.swapaxes(axes, -1, -2) * (theta ** 2)[:, None, None]
    G = frame_angle_turns(frames, lambda name: name == "scapula")  # (b, 18, 3) per turn about the thorax axes
    out[:, : G.shape[1]] = np.einsum("bai,bij,baj->ba", G, Cw, G)
    return out
