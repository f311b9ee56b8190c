"""Which coordinates the markers determine, frame by frame.

At a pose q the markers determine the coordinates through the constrained, weighted first-order
problem min |W^1/2 (J dq - dm)|^2 subject to G dq = 0. With isotropic marker noise of 1 mm (the
same on every present marker), the standard deviation this gives each coordinate is

    s_j = sqrt(diag(N (A^T W A)^+ (A^T W^2 A) (A^T W A)^+ N^T))_j * 1 mm,   A = J N,

where N spans the null space of G (the directions the ellipsoid constraints allow) and the held or
locked coordinates are left out. s_j in degrees per millimetre of marker noise is the
coordinate's *noise gain*: about 0.1-0.5 deg/mm for a well-observed joint, and it grows without
bound where the markers cannot see a rotation (a clavicle's axial rotation seen through two markers
on its axis, a segment with no marker, or a Cardan sequence's middle angle near +-90 deg). A
coordinate whose gain exceeds ``UNDETERMINED_DEG_PER_MM`` is *undetermined* in that frame: its value
comes from the method's regularisation and dynamics, not the markers, and every output says so.
"""
from __future__ import annotations

import enum
import warnings
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from exubio.io.heap import release_freed_heap
from exubio.model.kinematics import Kinematics, PointSet
from exubio.trust.design import constrained_design, information_pinv as _pinv, marker_information as _marker_information
from exubio.trust.gap_frames import computed_frames, nearest_sample

UNDETERMINED_DEG_PER_MM = 2.0
"""Noise gain above which a coordinate counts as undetermined. Skin-marker errors on the shoulder
and arm are 5-30 mm (soft-tissue artefact; e.g. Cappozzo et al. 1996, Clin Biomech 11:90): at
2 deg/mm, 5 mm of independent error on every marker alone moves the coordinate by 10 deg SD,
beyond what skin-marker joint angles are read for. Measured medians on the 21-marker C3D trials
(shipped protocol): 0.06-0.4 deg/mm for the girdle, GH axial rotation and elbow, 0.7-1.1 for
pronation and the wrist, about 3 for the clavicle's axial rotation when it is not held, and
unbounded near a sequence's gimbal lock."""

GIMBAL_MARGIN_RAD = np.radians(20.0)
"""A frame whose middle angle of a 3-angle sequence lies within this of +-90 deg is near the
sequence's gimbal lock: there its first and last angles are undetermined whatever the markers
(the segment's orientation is determined, its split into these two angles is not)."""

UNDETERMINED_TRIAL_FRACTION = 0.5
"""A coordinate undetermined in more than this fraction of a trial's frames is undetermined for the
trial (the protocol should hold it); below, the frames are marked but the coordinate is reported."""


@dataclass(frozen=True)
class Determinacy:
    """gain_deg_per_mm: (n, m) noise gain of every coordinate (NaN where held/locked or the frame
    has too few markers); undetermined: (n, m) bool; names: coordinate names."""

    names: tuple[str, ...]
    gain_deg_per_mm: np.ndarray
    undetermined: np.ndarray
    excluded: tuple[str, ...]
    near_gimbal_lock: np.ndarray | None = None  # (n, m) bool: first/last angle of a sequence near lock

    def fraction_undetermined(self) -> dict[str, float]:
        return {n: float(self.undetermined[:, j].mean()) for j, n in enumerate(self.names) if n not in self.excluded}

    def fraction_by_markers(self) -> dict[str, float]:
        """Fraction of frames undetermined for want of markers (not near a gimbal lock)."""
        und = self.undetermined if self.near_gimbal_lock is None else self.undetermined & ~self.near_gimbal_lock
        return {n: float(und[:, j].mean()) for j, n in enumerate(self.names) if n not in self.excluded}

    def fraction_gimbal(self) -> dict[str, float]:
        if self.near_gimbal_lock is None:
            return {}
        und = self.undetermined & self.near_gimbal_lock
        return {n: float(und[:, j].mean()) for j, n in enumerate(self.names) if n not in self.excluded and und[:, j].any()}

    def trial_undetermined(self) -> list[str]:
        """Coordinates the markers leave undetermined in most of the trial (not a gimbal lock)."""
        return [n for n, f in self.fraction_by_markers().items() if f > UNDETERMINED_TRIAL_FRACTION]

    def to_dict(self) -> dict:
        """Kept by hand (exubio.io.records' exception): fractions and medians over frames, not fields."""
        frac = self.fraction_undetermined()
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(self.gain_deg_per_mm, axis=0) if self.gain_deg_per_mm.size else np.zeros(0)
        return {
            "definition": "coordinate SD per mm of isotropic marker noise (constrained, weighted, first order); "
                          f"undetermined above {UNDETERMINED_DEG_PER_MM} deg/mm",
            "threshold_deg_per_mm": UNDETERMINED_DEG_PER_MM,
            "undetermined_for_trial": self.trial_undetermined(),
            "frames_undetermined_fraction": {n: round(f, 4) for n, f in frac.items() if f > 0},
            "frames_near_gimbal_lock_fraction": {n: round(f, 4) for n, f in self.fraction_gimbal().items()},
            "median_gain_deg_per_mm": {n: (None if not np.isfinite(med[j]) else round(float(med[j]), 4))
                                       for j, n in enumerate(self.names) if n not in self.excluded},
            "not_solved": list(self.excluded),
        }


def determinacy(kin: Kinematics, points: PointSet, q: np.ndarray, present: np.ndarray, weights: np.ndarray, /, *,
                excluded: np.ndarray | None = None, every: int = 1) -> Determinacy:
    """Noise gains for the frames of q (n, m) (every ``every``-th frame, the others copied from
    the nearest computed one). present: (n, k) bool; weights: (k,) LS weights; excluded: (m,)
    bool, coordinates not solved (held, locked)."""
    n, m = q.shape
    names = kin.model.coordinate_names
    excl = np.zeros(m, dtype=bool) if excluded is None else np.asarray(excluded, dtype=bool)
    free = np.flatnonzero(~excl)
    sel, idx = computed_frames(np.asarray(present, dtype=bool), every)  # gap edges computed, not copied across
    qs = q[sel]
    ok = np.isfinite(qs).all(axis=1)
    gain = np.full((len(sel), m), np.nan)
    for a in range(0, len(sel), BLOCK_FRAMES):  # blocks bound the per-frame matrices on long trials
        part = slice(a, a + BLOCK_FRAMES)
        gain[part] = _gains(kin, points, qs[part], ok[part], present[sel[part]], weights, free, m)
    gain_all = gain[idx]  # every frame: the nearest computed frame with the same markers

    with np.errstate(invalid="ignore"):
        und = gain_all > UNDETERMINED_DEG_PER_MM
    und[:, excl] = False
    gimbal = np.zeros((n, m), dtype=bool)
    for _, _, idx, _ in kin.joint_frames():
        if len(idx) == 3:
            near = np.abs(np.cos(q[:, idx[1]])) < np.sin(GIMBAL_MARGIN_RAD)
            gimbal[:, idx[0]] |= near
            gimbal[:, idx[2]] |= near
    return Determinacy(tuple(names), gain_all, und, tuple(names[j] for j in np.flatnonzero(excl)), gimbal)


BLOCK_FRAMES = 512  # frames whose noise gains and uncertainties are computed together (their per-frame matrices,
# ~0.12 MB a frame at 18 markers, ~60 MB a block; 2048 took ~250 MB on a long trial; the values do not depend on it)


def _gains(kin: Kinematics, points: PointSet, qs: np.ndarray, ok: np.ndarray, present: np.ndarray,
           weights: np.ndarray, free: np.ndarray, m: int) -> np.ndarray:
    """Noise gains (b, m) of the frames qs (b, m); NaN where ``ok`` is False and for coordinates
    not in ``free``."""
    gain = np.full((qs.shape[0], m), np.nan)
    if not ok.any():
        return gain
    qf = qs[ok]
    w = np.where(present[ok], weights[None, :], 0.0)  # (b, k)
    J = kin.point_jacobian(qf, points)[..., free]  # (b, k, 3, f)
    b, k = w.shape
    J = J.reshape(b, 3 * k, len(free))
    w3 = np.repeat(w, 3, axis=1)
    G = kin.G(qf)[..., free]  # (b, 2, f)
    _, _, Vt = np.linalg.svd(G)
    N = np.swapaxes(Vt[:, G.shape[1]:, :], 1, 2)  # (b, f, f - 2): null space of G
    A = J @ N
    M = np.swapaxes(A, 1, 2) @ (A * w3[..., None])
    S = np.swapaxes(A, 1, 2) @ (A * (w3**2)[..., None])
    Minv = np.linalg.pinv(M, rcond=1e-12, hermitian=True)
    cov = N @ Minv @ S @ Minv @ np.swapaxes(N, 1, 2)
    diag = np.einsum("bii->bi", cov)
    # pinv drops directions no marker sees: those coordinates are undetermined (infinite gain)
    rank = np.linalg.matrix_rank(M, hermitian=True, rtol=1e-12)
    blind = rank < M.shape[-1]
    g = np.degrees(np.sqrt(np.maximum(diag, 0.0))) / 1000.0
    if blind.any():
        # the coordinates the null direction of M moves
        evals, evecs = np.linalg.eigh(M[blind])
        null = evals <= 1e-12 * evals[..., -1:]  # (nb, f-2): directions no marker sees
        moved = (np.abs(np.einsum("bfr,brs->bfs", N[blind], evecs)) * null[:, None, :]).max(axis=2) > 1e-6
        g[blind] = np.where(moved, np.inf, g[blind])
    full = np.full((int(ok.sum()), m), np.nan)
    full[:, free] = g
    gain[ok] = full
    return gain


# --------------------------------------------------------------------------------------------
# Per anatomical angle: measured, modelled or not measured
# --------------------------------------------------------------------------------------------
class AngleStatus(enum.IntEnum):
    """What an anatomical angle's value in a frame rests on."""

    MEASURED = 0  # the markers determine it (noise gain <= UNDETERMINED_DEG_PER_MM)
    MODELLED = 1  # set by a named rule of the protocol (a hold), which the markers could not replace
    NOT_MEASURED = 2  # neither: undetermined by the markers, or of a segment no marker observes

    @property
    def label(self) -> str:
        return self.name.lower().replace("_", " ")


MODELLED_SHARE = 0.5
"""An angle counts as modelled by a hold when, with the hold released, more than this share of its
variance under marker noise would come through the held coordinates (the squared multiple
correlation of the linearised problem: holding a coordinate is conditioning on it). A share of 0.5
or more means the hold, not the markers, decides most of what the angle is. The measured values
are clear-cut (21-marker set, clavicle axial rotation held, elevation in three planes): 1.0 for the
clavicle's axial rotation, 0.99 for AC upward rotation and tilt, 0.79 for AC internal rotation, at
most 0.05 for every other angle (tests/trust/test_angle_status.py)."""

RELEASE_PRIOR = 1e-8
"""Relative Tikhonov weight that keeps a released problem invertible where no marker sees a
direction (its variance becomes huge but finite, so its share can be computed)."""

FD_STEP_RAD = 1e-6


@dataclass(frozen=True)
class AngleDeterminacy:
    """names: anatomical angle columns; gain_deg_per_mm: (n, a) their noise gain with the
    protocol's holds (inf where no marker sees a direction the angle moves with); held_share:
    (n, a) share of the released variance that comes through held coordinates; status: (n, a)
    AngleStatus codes (int8); rule: per angle, the rule that models it where modelled."""

    names: tuple[str, ...]
    gain_deg_per_mm: np.ndarray
    held_share: np.ndarray
    status: np.ndarray
    rule: Mapping[str, str]
    uncertainty_rad: np.ndarray | None = None  # (n, a) standard uncertainty (exubio.trust.angle_uncertainty)
    near_gimbal_lock: np.ndarray | None = None  # (n, a) bool: first/third angle of a set near its gimbal lock
    uncertainty_model: str = ""  # a lab's STA amplitude model the uncertainty used: "FILE (source)"; "": the shipped

    def fraction(self, status: "AngleStatus") -> dict[str, float]:
        return {n: float((self.status[:, j] == status).mean()) for j, n in enumerate(self.names)}

    def trial_status(self) -> dict[str, str]:
        """Per angle: 'measured' if measured in every frame, else the status of most of its
        other frames, with 'partly' where it is measured in some."""
        out = {}
        for j, n in enumerate(self.names):
            col = self.status[:, j]
            if (col == AngleStatus.MEASURED).all():
                out[n] = AngleStatus.MEASURED.label
                continue
            other = col[col != AngleStatus.MEASURED]
            worst = AngleStatus(int(np.bincount(other, minlength=3).argmax()))
            out[n] = worst.label if (col != AngleStatus.MEASURED).all() else f"partly {worst.label}"
        return out

    def causes(self) -> dict[str, dict[str, np.ndarray]]:
        """Per angle, the frames (bool, (n,)) where it is not measured for each cause: "markers" (the
        markers do not determine it: noise gain above the threshold, or a segment no marker
        observes), "gimbal" (its sequence near its gimbal lock), "uncertainty" (its standard
        uncertainty above the bound); each frame counted under the first cause that applies."""
        from exubio.trust.angle_uncertainty import U_BOUND_DEG

        out = {}
        nm = self.status == AngleStatus.NOT_MEASURED
        with np.errstate(invalid="ignore"):
            markers = nm & ~(self.gain_deg_per_mm <= UNDETERMINED_DEG_PER_MM)
            gimbal = (nm & ~markers & self.near_gimbal_lock) if self.near_gimbal_lock is not None else np.zeros_like(nm)
            unc = (nm & ~markers & ~gimbal & (np.degrees(self.uncertainty_rad) > U_BOUND_DEG)
                   if self.uncertainty_rad is not None else np.zeros_like(nm))
        markers = markers | (nm & ~gimbal & ~unc & ~markers)  # a locked segment: no marker sees it
        for j, n in enumerate(self.names):
            out[n] = {"markers": markers[:, j], "gimbal": gimbal[:, j], "uncertainty": unc[:, j]}
        return out

    def to_dict(self) -> dict:
        """Kept by hand (as Determinacy's): per-trial status, fractions and medians over the frames."""
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(np.where(np.isfinite(self.gain_deg_per_mm), self.gain_deg_per_mm, 1e9), axis=0) \
                if self.gain_deg_per_mm.size else np.zeros(0)
        return {
            "definition": f"measured: noise gain <= {UNDETERMINED_DEG_PER_MM} deg per mm of marker noise; modelled: "
                          f"more than {MODELLED_SHARE:.0%} of its released variance comes through a held coordinate "
                          "(the rule is named); not measured: otherwise (undetermined, or a segment without markers)",
            "status": self.trial_status(),
            "frames_measured_fraction": {n: round(f, 4) for n, f in self.fraction(AngleStatus.MEASURED).items()},
            "median_gain_deg_per_mm": {n: (None if med[j] >= 1e9 else round(float(med[j]), 4))
                                       for j, n in enumerate(self.names)},
            "rules": dict(self.rule),
            **self._uncertainty_dict(),
        }

    def _uncertainty_dict(self) -> dict:
        if self.uncertainty_rad is None:
            return {}
        from exubio.trust.angle_uncertainty import U_BOUND_DEG, UNCERTAINTY_DEFINITION

        u = np.degrees(self.uncertainty_rad)
        meas = self.status == AngleStatus.MEASURED
        med = {}
        for j, n in enumerate(self.names):
            col = u[meas[:, j], j]
            col = col[np.isfinite(col)]
            med[n] = round(float(np.median(col)), 3) if col.size else None
        gimbal = {} if self.near_gimbal_lock is None else {
            n: round(float(self.near_gimbal_lock[:, j].mean()), 4) for j, n in enumerate(self.names)
            if self.near_gimbal_lock[:, j].any()}
        above = {n: round(float((u[:, j] > U_BOUND_DEG).mean()), 4) for j, n in enumerate(self.names)
                 if (u[:, j] > U_BOUND_DEG).any()}
        return {"uncertainty_definition": UNCERTAINTY_DEFINITION,
                **({"uncertainty_model": self.uncertainty_model} if self.uncertainty_model else {}),
                "median_uncertainty_deg_measured_frames": med,
                "frames_near_gimbal_lock_fraction": gimbal, "frames_uncertainty_above_bound_fraction": above}


def _angle_jacobian(table, q: np.ndarray, distal: dict[int, int] | None = None) -> np.ndarray:
    """d angle / d q (b, a, m) by central differences (angle differences wrapped to (-pi, pi]); ``distal``
    (exubio.model.angles.distal_only_coordinates): coordinate -> its one column, set without the frames."""
    b, m = q.shape
    qp, qm = q[:, None, :] + np.eye(m) * FD_STEP_RAD, q[:, None, :] - np.eye(m) * FD_STEP_RAD
    rows = [j for j in range(m) if j not in (distal or {})]
    part = table(qp[:, rows].reshape(-1, m)) - table(qm[:, rows].reshape(-1, m))
    d = np.zeros((b, m, part.shape[-1]))  # the other rows: 0 but in the coordinate's own column, as the table gives
    d[:, rows] = part.reshape(b, len(rows), -1)
    for j, col in (distal or {}).items():
        d[:, j, col] = qp[:, j, j] - qm[:, j, j]
    d = np.angle(np.exp(1j * d)) / (2.0 * FD_STEP_RAD)  # (b, m, a)
    return np.swapaxes(d, 1, 2)


def _covariance(N, M, S, m: int, free: np.ndarray, prior: float | None, *, minv: np.ndarray | None = None):
    """Coordinate covariance (b, m, m) per m^2 of marker noise (zero rows for coordinates not in
    ``free``), and the blind directions (b, m, r) (zero columns where a direction is seen); with
    ``prior`` (relative), a Tikhonov term instead of the pseudo-inverse, and no blind directions.
    ``minv``: the pseudo-inverse of M (design.information_pinv), where the caller has it."""
    b = N.shape[0]
    if prior is not None:  # information form (the posterior of a weak Gaussian prior): a direction no
        # marker sees gets the prior's large variance, not the sandwich form's zero
        scale = np.maximum(np.trace(M, axis1=1, axis2=2) / M.shape[-1], 1e-300)
        Minv = np.linalg.inv(M + (prior * scale)[:, None, None] * np.eye(M.shape[-1]))
        cov = np.zeros((b, m, m))
        cov[:, free[:, None], free[None, :]] = N @ Minv @ np.swapaxes(N, 1, 2)
        return cov, np.zeros((b, m, 0))
    else:
        Minv = _pinv(M) if minv is None else minv
        evals, evecs = np.linalg.eigh(M)
        null = evals <= 1e-12 * evals[..., -1:]
        dirs = np.einsum("bfr,brs->bfs", N, evecs) * null[:, None, :]
        blind = np.zeros((b, m, dirs.shape[-1]))
        blind[:, free, :] = dirs
    cov_f = N @ Minv @ S @ Minv @ np.swapaxes(N, 1, 2)
    cov = np.zeros((b, m, m))
    cov[:, free[:, None], free[None, :]] = cov_f
    return cov, blind


def angle_determinacy(kin: Kinematics, points: PointSet, q: np.ndarray, present: np.ndarray, weights: np.ndarray, /,
                      *, held: np.ndarray, locked: np.ndarray, every: int = 1,
                      rules: Mapping[str, str] | None = None, amplitude=None,
                      noise_mm: float | None = None, residuals_m: np.ndarray | None = None,
                      bounded: bool = True, thorax_assumed_still: bool = False,
                      marker_positions_m: np.ndarray | None = None) -> AngleDeterminacy:
    """Measured / modelled / not measured for every anatomical angle (exubio.model.angles.ANATOMICAL_ANGLES)
    in the frames of q (n, m), computed every ``every``-th frame and copied to the frames between.
    held: (m,) bool, coordinates a protocol rule holds; locked: (m,) bool, coordinates of segments
    no marker observes; rules: the rule's name per held coordinate (default 'hold'). Each angle's
    standard uncertainty (exubio.trust.angle_uncertainty: ``noise_mm`` of marker noise and the STA
    ``amplitude`` model, default the shipped one; the model's misfit where ``residuals_m`` (n, k) is
    given; ``marker_positions_m`` (n, k, 3), the markers tracked: its direction) is computed with it; an angle is not measured
    where it exceeds the bound or where its sequence is near its gimbal lock. ``bounded=False``: the
    markers' determinacy alone (what a marker set can see, e.g. whether dropping a marker loses an
    angle), no uncertainty computed. ``thorax_assumed_still``: the run has no thorax marker and takes
    the thorax as fixed (exubio truth): the unseen trunk motion of the amplitude model's ``trunk``
    (exubio.trust.angle_uncertainty.trunk_angle_variance) is added to every angle's variance."""
    from exubio.model.angles import anatomical_table
    from exubio.trust import angle_uncertainty as AU
    from exubio.trust.sta_amplitude import shipped_amplitude
    amplitude = amplitude if amplitude is not None else shipped_amplitude()
    noise_mm = AU.NOISE_MM if noise_mm is None else float(noise_mm)
    if thorax_assumed_still and not amplitude.has_trunk:
        raise ValueError("thorax_assumed_still needs an amplitude model with the trunk's motion")

    model = kin.model
    n, m = q.shape
    held = np.asarray(held, dtype=bool)
    locked = np.asarray(locked, dtype=bool) & ~held
    table = lambda qq: anatomical_table(model, qq, kinematics=kin, unwrap=False)[1]
    names = anatomical_table(model, np.zeros(m), kinematics=kin)[0]
    a = len(names)
    free_actual = np.flatnonzero(~held & ~locked)
    free_released = np.flatnonzero(~locked)
    present = np.asarray(present, dtype=bool)
    sel, idx = computed_frames(present, every)
    trial_markers = present.any(axis=0)  # the markers the trial has: a frame lacking one is in a gap
    ok = np.isfinite(q[sel]).all(axis=1)

    res_floor = None if residuals_m is None else nearest_sample(residuals_m)  # a hidden marker's misfit: its edges'

    def block(frames: np.ndarray, pres: np.ndarray, res: np.ndarray | None, vec: np.ndarray | None = marker_positions_m):
        return _angle_block(kin, points, q[frames], pres, weights, table, held=held, locked=locked,
                            free_actual=free_actual, free_released=free_released, bounded=bounded, amplitude=amplitude,
                            noise_mm=noise_mm, residuals=None if res is None else res[frames],
                            trunk=amplitude if thorax_assumed_still else None, vectors=None if vec is None else vec[frames])

    gain = np.full((len(sel), a), np.inf)
    unc = np.full((len(sel), a), np.inf)
    share = np.zeros((len(sel), a))
    dep_locked = np.zeros((len(sel), a), dtype=bool)
    for s0 in range(0, len(sel), BLOCK_FRAMES):
        part = np.arange(s0, min(s0 + BLOCK_FRAMES, len(sel)))
        part = part[ok[part]]
        if not part.size:
            continue
        frames = sel[part]
        gain[part], unc[part], share[part], dep_locked[part] = block(frames, present[frames], residuals_m)
        gap = (present[frames] != trial_markers[None, :]).any(axis=1)
        if gap.any():  # a gap never makes an angle surer than the trial's markers make it (GAP_FLOOR)
            g_full, u_full, _, _ = block(frames[gap], np.broadcast_to(trial_markers, (int(gap.sum()), len(trial_markers))),
                                         res_floor, None)
            rows = part[gap]
            with np.errstate(invalid="ignore"):
                gain[rows] = np.fmax(gain[rows], g_full)
                unc[rows] = np.fmax(unc[rows], u_full)
    gain, share, dep_locked, unc = gain[idx], share[idx], dep_locked[idx], unc[idx]
    with np.errstate(invalid="ignore"):
        gimbal = (AU.gimbal_mask(table(np.where(np.isfinite(q), q, 0.0))) & np.isfinite(q).all(axis=1)[:, None]
                  if bounded else np.zeros((n, a), dtype=bool))
    status = np.full((n, a), AngleStatus.MEASURED, dtype=np.int8)
    status[share > MODELLED_SHARE] = AngleStatus.MODELLED
    status[(gain > UNDETERMINED_DEG_PER_MM) & (share <= MODELLED_SHARE)] = AngleStatus.NOT_MEASURED
    if bounded:
        judged = np.array([AU.bound_applies(nm) for nm in names], dtype=bool)
        with np.errstate(invalid="ignore"):
            status[(np.degrees(unc) > AU.U_BOUND_DEG) & (status == AngleStatus.MEASURED) & judged[None, :]] = \
                AngleStatus.NOT_MEASURED
    status[gimbal & (status == AngleStatus.MEASURED)] = AngleStatus.NOT_MEASURED
    status[dep_locked] = AngleStatus.NOT_MEASURED
    status[~np.isfinite(q).all(axis=1)] = AngleStatus.NOT_MEASURED
    names_q = model.coordinate_names
    rules = dict(rules or {})
    held_names = [names_q[j] for j in np.flatnonzero(held)]
    rule_of = {}
    for j, nm in enumerate(names):
        if (status[:, j] == AngleStatus.MODELLED).any():
            rule_of[nm] = "; ".join(rules.get(h, f"hold: {h} fixed at its reference value") for h in held_names)
    release_freed_heap()  # the blocks' matrices, freed: back to the system before the files are written
    lab_model = f"{amplitude.path} ({amplitude.source or 'no source given'})" if amplitude.path and bounded else ""
    return AngleDeterminacy(tuple(names), gain, share, status, rule_of, unc if bounded else None,
                            gimbal if bounded else None, lab_model)


GAP_FLOOR = ("in a frame where a marker the trial has is missing (a gap), each angle's noise gain and "
             "uncertainty are at least those the trial's full marker set gives at the same pose, with each hidden "
             "marker's residual taken from the nearest frame where it was seen")
"""Why a floor: the uncertainty propagates the artefact model through the protocol's fixed least-squares weights, which
are not the model's optimal (inverse-covariance) weights, so leaving out a marker the model gives a large non-rigid
artefact (e.g. ARM on the upper arm) can lower the propagated value by up to a quarter (measured on
bioptim_exo_martin_dynamique, docs/gaps.md). Leaving a marker out is not how a lab would make an angle surer, and
the artefact model's per-marker parts were not fitted for it: a gap frame says at least what the full set says."""


def _angle_block(kin: Kinematics, points: PointSet, qf: np.ndarray, pres: np.ndarray, weights: np.ndarray, table, /,
                 *, held: np.ndarray, locked: np.ndarray, free_actual: np.ndarray, free_released: np.ndarray,
                 bounded: bool, amplitude, noise_mm: float, residuals: np.ndarray | None, trunk=None, vectors=None):
    """For the poses qf (b, m) with the markers pres (b, k): the angles' noise gains (deg/mm), standard
    uncertainties (rad; inf where unseen, where not ``bounded``), held shares and whether they depend
    on a locked coordinate, each (b, a). ``trunk``: the amplitude model whose unseen trunk motion is added to
    every angle's variance (a run that assumes the thorax still)."""
    from exubio.model.angles import distal_only_coordinates, segment_anatomical_rotations
    from exubio.trust import angle_uncertainty as AU

    model = kin.model
    m = qf.shape[1]
    D = _angle_jacobian(table, qf, distal_only_coordinates(model, kin))  # (b, a, m)
    b, a = D.shape[:2]
    design = constrained_design(kin, points, qf, pres, weights, free_actual)  # shared with the sensitivity below
    N, M, S = _marker_information(kin, points, qf, pres, weights, free_actual, design=design)
    Minv = _pinv(M)
    cov, blind = _covariance(N, M, S, m, free_actual, None, minv=Minv)
    var = np.einsum("bam,bmn,ban->ba", D, cov, D)
    g = np.degrees(np.sqrt(np.maximum(var, 0.0))) / 1000.0
    unseen = (np.abs(np.einsum("bam,bmr->bar", D, blind)) > 1e-6).any(axis=2) if blind.shape[-1] else False
    gain = np.where(unseen, np.inf, g)
    unc = np.full((b, a), np.inf)
    share = np.zeros((b, a))
    if bounded:
        K, Jm = AU.sensitivity(kin, points, qf, pres, weights, free_actual, with_jacobian=True, design=design, minv=Minv)
        frames_isb = segment_anatomical_rotations(model, qf, kinematics=kin)
        anat = {s_: frames_isb[s_] for s_ in ("scapula", "humerus") if s_ in frames_isb}
        Sigma = AU.marker_covariance(kin, points, qf, pres, amplitude, noise_mm=noise_mm, anatomical=anat)
        direct = 0.0  # a misfit segment's frame turned (AU.misfit_angle_variance), in the frames with residuals
        if residuals is not None:
            expected = AU.expected_residual_ms(Jm, K, Sigma)
            direct = (AU.misfit_angle_variance(kin, points, qf, pres, residuals, expected, a, measured_m=vectors,
                                               frames=frames_isb) if AU.DIRECT_MISFIT else 0.0)
            Sigma = Sigma + AU.marker_covariance(kin, points, qf, pres, amplitude, noise_mm=noise_mm, anatomical=anat,
                                                 residual_m=residuals, expected_ms=expected)
        var_u = AU.quadratic_forms(DK := D @ K, Sigma) + direct + AU.girdle_angle_variance(kin, qf, amplitude, a, frames_isb)
        if AU.ellipsoid_from_skin((model.metadata or {}).get("calibration")):  # the scapula turns with its skin:
            var_u = var_u + AU.skin_ellipsoid_variance(kin, qf, amplitude, a, frames=frames_isb)  # its frame too
        if trunk is not None:
            var_u = var_u + AU.trunk_angle_variance(kin, points, qf, DK, trunk)
        unc = np.where(unseen, np.inf, np.sqrt(np.maximum(var_u, 0.0)))
    dep_locked = (np.abs(D[:, :, locked]) > 1e-6).any(axis=2) if locked.any() else np.zeros((b, a), dtype=bool)
    if held.any():
        N, M, S = _marker_information(kin, points, qf, pres, weights, free_released)
        cov_r, _ = _covariance(N, M, S, m, free_released, RELEASE_PRIOR)
        h = np.flatnonzero(held)
        c_ah = np.einsum("bam,bmh->bah", D, cov_r[:, :, h])  # cov(angle, q_held)
        C_hh = cov_r[:, h[:, None], h[None, :]]
        var_r = np.einsum("bam,bmn,ban->ba", D, cov_r, D)
        explained = np.einsum("bah,bhk,bak->ba", c_ah, np.linalg.inv(C_hh), c_ah)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.where(var_r > 0, np.clip(explained / var_r, 0.0, 1.0), 0.0)
    return gain, unc, share, dep_locked

