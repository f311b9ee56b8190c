"""The anatomical fit: the static pose and the segment scale factors of the scaled generic model
(without the ellipsoid constraint, robust weights, inside the joint ranges), both by the
Levenberg-Marquardt core of exubio.methods.lsq (each fit says why it stopped: exubio.types.StopReason)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from exubio.calibration.scaling import SCALE_BOUNDS, SCALE_PRIOR_M2, _scale_design, scale_model
from exubio.model.kinematics import Kinematics, PointSet
from exubio.methods.lsq import Evaluation, Result, Settings, levenberg_marquardt
from exubio.types import StopReason
from exubio.methods.poses import Limits
from exubio.model.ranges import AT_LIMIT_TOLERANCE_RAD, violation
from exubio.types import Model

ROBUST_SCALE_M = 0.02  # Cauchy weight 1 / (1 + (d / ROBUST_SCALE_M)^2) in the anatomical fit

GIRDLE_PRIOR_M2_PER_RAD2 = 1e-4  # clavicle/scapula angles: 10 deg costs like 1.7 mm of one marker
GIRDLE_SEGMENTS = ("clavicle", "scapula")
ARM_PRIOR_M2_PER_RAD2 = 1e-7  # the other coordinates: only breaks ties where nothing is observed

MAX_REWEIGHTING = 50  # iterations of the robust reweighting (stop: weights change < 1e-3)


def _settings(max_iterations: int, tol: float) -> Settings:
    """Both fits: mu from 1e-4, tenfold up on a rejected step, threefold down (not below 1e-9) on
    a kept one, given up beyond 1e8; steps capped at 0.3 (rad, or scale factor); a step is kept
    if it does not raise the cost; converged when a kept step is at most ``tol``."""
    return Settings(max_iterations=max_iterations, step_tol=tol, damping=1e-4, damping_floor=1e-9, step_cap=0.3,
                    damping_decrease=3.0, damping_increase=10.0, damping_cap=1e8)


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
              tol: float = 1e-10, held: np.ndarray | None = None) -> Result:
    """min_q sum w_i |r_i(q) - m_i|^2 + sum_j prior_j q_j^2 + kappa sum_j v_j(q)^2 (the joint
    ranges, exubio.model.ranges) for every start (S, m) at once, Levenberg-Marquardt (exubio.methods.lsq);
    returns the core's result: q (S, m) in ``x``, the cost (S,) in ``evaluation.cost``, why each
    start stopped in ``reason``."""
    m = np.shape(q_starts)[1]
    tgt = np.where(np.isnan(target), 0.0, target)

    def evaluate(qq: np.ndarray, rows: np.ndarray) -> Evaluation:
        e = (kin.points(qq, points) - tgt) * (w[:, None] > 0)
        cost = np.einsum("k,skc->s", w, e * e) + (prior * qq * qq).sum(axis=1) + _range_cost(qq, limits)
        return Evaluation(cost, data={"e": e})

    def linearise(qq: np.ndarray, rows: np.ndarray, ev: Evaluation) -> Evaluation:
        J = kin.point_jacobian(qq, points)  # (A, k, 3, m)
        if held is not None:
            J = J * ~held  # held coordinates stay at their start value
        Jw = J * w[None, :, None, None]
        H = np.einsum("akcm,akcn->amn", Jw, J) + np.eye(m) * prior
        grad = np.einsum("akcm,akc->am", Jw, ev.data["e"]) + prior * qq
        if limits is not None:
            v = violation(qq, limits.ranges_rad)
            H = H + limits.kappa * (v != 0)[..., :, None] * np.eye(m)
            grad = grad + limits.kappa * v
        return Evaluation(ev.cost, H=H, grad=grad, data=ev.data)

    return levenberg_marquardt(q_starts, evaluate, linearise=linearise, settings=_settings(max_iterations, tol))


def best_start(fit: Result) -> tuple[np.ndarray, StopReason]:
    """The lowest-cost start of a ``_fit_pose`` result: its pose (m,) and why its fit stopped."""
    i = int(np.argmin(fit.evaluation.cost))
    return fit.x[i], fit.stop(i)


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
            tol: float = 1e-10) -> tuple[np.ndarray, dict[str, float], float, StopReason]:
        """Joint Levenberg-Marquardt (exubio.methods.lsq) over the pose and the free scale factors (bounded:
        a trial step is clipped to SCALE_BOUNDS). Returns q, factors, cost and why the fit stopped."""
        m, free = q.size, self.free
        prior = np.concatenate([self.prior_q, np.full(len(free), SCALE_PRIOR_M2)])
        centre = np.concatenate([np.zeros(m), np.ones(len(free))])  # where the priors pull x

        def factors(x: np.ndarray) -> dict[str, float]:
            out = dict(s)
            out.update({g: float(v) for g, v in zip(free, x[m:])})
            return out

        def evaluate(x: np.ndarray, rows: np.ndarray) -> Evaluation:
            cost, e, _ = self.evaluate(x[0, :m], factors(x[0]), w, jacobian=False)
            return Evaluation(np.array([cost]))

        def linearise(x: np.ndarray, rows: np.ndarray, ev: Evaluation) -> Evaluation:
            qq = x[0, :m]
            cost, e, J = self.evaluate(qq, factors(x[0]), w, jacobian=True)
            Jw = J * w[:, None, None]
            H = np.einsum("kcm,kcn->mn", Jw, J) + np.diag(prior)
            grad = np.einsum("kcm,kc->m", Jw, e) + prior * (x[0] - centre)
            if self.limits is not None:
                v = violation(qq, self.limits.ranges_rad)
                H[:m, :m] += self.limits.kappa * np.diag((v != 0).astype(float))
                grad[:m] += self.limits.kappa * v
            return Evaluation(np.array([cost]), H=H[None], grad=grad[None])

        def bounded(x: np.ndarray, rows: np.ndarray) -> np.ndarray:
            x[:, m:] = np.clip(x[:, m:], *SCALE_BOUNDS)
            return x

        x0 = np.concatenate([q, [s[g] for g in free]])[None]
        res = levenberg_marquardt(x0, evaluate, linearise=linearise, project=bounded,
                                  settings=_settings(max_iterations, tol))
        x = res.x[0]
        return x[:m].copy(), factors(x), float(res.evaluation.cost[0]), res.stop(0)


