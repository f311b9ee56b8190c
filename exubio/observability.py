"""Which coordinates the markers determine, frame by frame.

At a pose q the markers determine the coordinates through the constrained, weighted first-order
problem min |W^1/2 (J dq - dm)|^2 subject to G dq = 0. With isotropic marker noise of 1 mm (the
same on every present marker), the standard deviation this gives each coordinate is

    s_j = sqrt(diag(N (A^T W A)^+ (A^T W^2 A) (A^T W A)^+ N^T))_j * 1 mm,   A = J N,

where N spans the null space of G (the directions the ellipsoid constraints allow) and the held or
locked coordinates are left out. s_j in degrees per millimetre of marker noise is the
coordinate's *noise gain*: about 0.1-0.5 deg/mm for a well-observed joint, and it grows without
bound where the markers cannot see a rotation (a clavicle's axial rotation seen through two markers
on its axis, a segment with no marker, or the middle angle of a Cardan sequence near +-90 deg,
where the first and last rotations act about the same axis). A coordinate whose gain exceeds
``UNDETERMINED_DEG_PER_MM`` is *undetermined* in that frame: its value there comes from the
method's regularisation and dynamics, not from the markers, and it is marked so in every output.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from exubio.kinematics import Kinematics, PointSet

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
    sel = np.arange(0, n, max(int(every), 1))
    qs = q[sel]
    ok = np.isfinite(qs).all(axis=1)
    gain = np.full((len(sel), m), np.nan)
    for a in range(0, len(sel), BLOCK_FRAMES):  # blocks bound the per-frame matrices on long trials
        part = slice(a, a + BLOCK_FRAMES)
        gain[part] = _gains(kin, points, qs[part], ok[part], present[sel[part]], weights, free, m)
    # spread to every frame (nearest computed frame)
    idx = np.clip(np.round(np.arange(n) / max(int(every), 1)).astype(int), 0, len(sel) - 1)
    gain_all = gain[idx]
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


BLOCK_FRAMES = 2048  # frames whose noise gains are computed together (their matrices: ~60 kB per frame)


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
