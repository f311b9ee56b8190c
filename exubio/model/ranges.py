"""Joint ranges of motion: the one-sided limit potential both methods share, and the frames where a
reconstruction sits at or beyond a limit.

Every model coordinate q_j has a range [lo_j, hi_j] (rad; +-inf where the model gives none). Both
methods enforce it with the same one-sided quadratic potential

    V(q) = 0.5 k_lim sum_j v_j(q)^2,   v_j = max(0, q_j - hi_j) - max(0, lo_j - q_j),

PF as Exudyn elements that push back beyond a limit (exubio.backend.exudyn_limits), LS inside its
solve: LS minimises sum_i w_i |r_i - m_i|^2 with w_i = c_i / c_default, i.e. (2 / c_default) times
the springs' potential, so it adds (2 / c_default) V = kappa sum_j v_j^2 with
kappa = k_lim / c_default (m^2/rad^2). The quasi-static equilibrium of PF and the LS optimum are
then the same point, at the limits too.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_LIMIT_STIFFNESS_NM_PER_RAD = 1.0e4
"""k_lim, the same in both methods. Measured on the 21-marker protocol (studies/README.md,
"Joint limits"): the markers hold a joint with 16-22 N m/rad (pronation, wrist) to 620 (elbow) and
3-5e3 (GH, girdle) when the other coordinates are held, at most ~110 N m/rad when they are free to
compensate, which is what resists markers that drive one coordinate past its range. At 1e4 a
coordinate stops 0.57 deg past its limit per 10 N m of excess torque (elbow driven 20 deg past by
exact markers: 0.4 deg; 1e3: 3.5 deg); stiffer limits cost PF more Jacobian updates (1e4: +34 %
while a limit is reached, 3e4: +50 %, 1e5: +67 %), so 1e4 is the knee."""

AT_LIMIT_TOLERANCE_RAD = np.radians(0.5)
"""A coordinate within this of a limit (or beyond) counts as 'at its limit' in the reports."""


def violation(q: np.ndarray, ranges_rad: np.ndarray, /) -> np.ndarray:
    """Signed distance beyond the range, (..., m): > 0 above hi, < 0 below lo, 0 inside."""
    q = np.asarray(q, dtype=float)
    lo, hi = ranges_rad[:, 0], ranges_rad[:, 1]
    return np.maximum(q - hi, 0.0) - np.maximum(lo - q, 0.0)


def penalty_weight(limit_stiffness_nm_per_rad: float, default_stiffness_n_per_m: float, /) -> float:
    """kappa = k_lim / c_default (m^2/rad^2): the LS weight of the limit potential."""
    return float(limit_stiffness_nm_per_rad) / float(default_stiffness_n_per_m)


@dataclass(frozen=True)
class LimitReport:
    """Per coordinate: its range (lower, upper, deg), the frames at (within AT_LIMIT_TOLERANCE_RAD
    of) or beyond a limit, the first of them, and the largest excursion beyond it (deg). Written
    and read by exubio.io.records (a summary.json's ``limits``)."""

    coordinate: str
    range_deg: tuple[float, float]
    frames_at_limit: int
    first_frame: int
    max_beyond_deg: float


def limit_report(q: np.ndarray, ranges_rad: np.ndarray, names, /, *, exclude=(),
                 ignore: np.ndarray | None = None) -> list[LimitReport]:
    """Coordinates of q (n, m) that reach their range limits (coordinates in ``exclude`` are left
    out: held or locked ones are not solved; frames where ``ignore`` (n, m) is True are not
    counted, e.g. the first and last angles of a sequence near its gimbal lock, whose split the
    limit only chooses)."""
    out = []
    lo, hi = ranges_rad[:, 0], ranges_rad[:, 1]
    finite = np.isfinite(q).all(axis=1)
    for j, name in enumerate(names):
        if name in exclude:
            continue
        keep = finite if ignore is None else finite & ~ignore[:, j]
        if not keep.any():
            continue
        qj = q[keep, j]
        at = (qj >= hi[j] - AT_LIMIT_TOLERANCE_RAD) | (qj <= lo[j] + AT_LIMIT_TOLERANCE_RAD)
        if at.any():
            beyond = np.maximum(np.maximum(qj - hi[j], lo[j] - qj), 0.0).max()
            out.append(LimitReport(name, (float(np.degrees(lo[j])), float(np.degrees(hi[j]))), int(at.sum()),
                                   int(np.flatnonzero(keep)[np.argmax(at)]), float(np.degrees(beyond))))
    return out


def wrap_into_range(q: np.ndarray, ranges_rad: np.ndarray, /, reference: np.ndarray | None = None) -> np.ndarray:
    """Each angle moved by a multiple of 2 pi into its range, or nearest to it; where the range is
    unbounded (or wider than 2 pi, or the angle fits several ways), nearest to ``reference``
    (default: the middle of the range, 0 where unbounded)."""
    q = np.asarray(q, dtype=float)
    lo, hi = ranges_rad[:, 0], ranges_rad[:, 1]
    bounded = np.isfinite(lo) & np.isfinite(hi)
    mid = np.where(bounded, 0.5 * (np.where(bounded, lo, 0.0) + np.where(bounded, hi, 0.0)), 0.0)
    ref = mid if reference is None else np.asarray(reference, dtype=float)
    k0 = np.round((ref - q) / (2 * np.pi))
    best = q + 2 * np.pi * k0
    best_cost = np.abs(violation(best, ranges_rad))
    for dk in (-1.0, 1.0):
        cand = q + 2 * np.pi * (k0 + dk)
        cost = np.abs(violation(cand, ranges_rad))
        better = cost < best_cost - 1e-12
        best = np.where(better, cand, best)
        best_cost = np.where(better, cost, best_cost)
    return best
