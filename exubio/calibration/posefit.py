"""The anatomical fit: the static pose and the segment scale factors of the scaled generic model
(without the ellipsoid constraint, robust weights, inside the joint ranges)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from exubio.calibration.scaling import SCALE_BOUNDS, SCALE_PRIOR_M2, _scale_design, scale_model
from exubio.kinematics import Kinematics, PointSet
from exubio.methods.ls import Limits
from exubio.ranges import AT_LIMIT_TOLERANCE_RAD, violation
from exubio.types import Model

ROBUST_SCALE_M = 0.02  # Cauchy weight 1 / (1 + (d / ROBUST_SCALE_M)^2) in the anatomical fit

GIRDLE_PRIOR_M2_PER_RAD2 = 1e-4  # clavicle/scapula angles: 10 deg costs like 1.7 mm of one marker
GIRDLE_SEGMENTS = ("clavicle", "scapula")
ARM_PRIOR_M2_PER_RAD2 = 1e-7  # the other coordinates: only breaks ties where nothing is observed

MAX_REWEIGHTING = 50  # iterations of the robust reweighting (stop: weights change < 1e-3)



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
              tol: float = 1e-10, held: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
        if held is not None:
            J = J * ~held  # held coordinates stay at their start value
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
    held: np.ndarray | None = None  # (m,) bool: coordinates the protocol holds (kept at 0, as the methods do)

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
        if self.held is not None:
            Jq = Jq * ~self.held  # held coordinates stay where they are
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


