"""Whether exchanging two labels is supported by the evidence of the label checks
(exubio.trust.labels: side relations, rigid distances to the reference, chain fits), and the
sentence that says why."""
from __future__ import annotations

import numpy as np

from exubio.trust.label_chains import CHAIN_GOOD_RMS_M, chain_fixed, chain_label
from exubio.trust.label_distances import mm_text
from exubio.trust.label_expectations import MODEL_POINT_TOLERANCE_M, LabelExpectations

__all__ = [
    "RELATION_MIN_EXPECTED",
    "RELATION_MIN_FIXED",
    "RELATION_SWAP_SHARE",
    "RIGID_TOLERANCE_M",
    "permuted",
    "rigid_bad",
    "swap_facts",
    "swap_support",
    "violated",
]

# --------------------------------------------------------------------------------------------
# Thresholds. "Measured" figures are from the eight C3D files of ../shared/data/c3d
# (Ipuch/bioptim_exo, MIT) with the generic model and its coordinate ranges.
# --------------------------------------------------------------------------------------------
# -- side relations
RELATION_MIN_FIXED = 3
"""A swap is supported by side relations when it restores at least 3 more than it reverses, and it
is refused when it reverses 3 or more. Swapping two markers of different segments reverses 25-100
relations; a single relation can be reversed by one marker placed unlike the model."""

RELATION_MIN_EXPECTED = 10
"""Side relations only speak (for or against) a swap of two markers on different segments that the
model itself separates by at least 10 relations (reversed when the two are exchanged in the model
at its median distances over the sampled postures). One marker that the lab places unlike the
model reverses a few relations on its own (measured: 5-7 in every correctly labelled trial, all on
the scapula and clavicle, whose technical markers the generic model places elsewhere); a swap of
two nearby girdle markers that the model separates by a handful of relations cannot be told from
that."""

RELATION_SWAP_SHARE = 0.5
"""... and the swap must restore at least half of those: a real swap restores nearly all the
relations that tell its two markers apart, a misplaced marker only a few."""

# -- rigid pairs
RIGID_TOLERANCE_M = 0.025
"""A rigid pair's median distance may differ from the reference by up to 25 mm. Skin markers over
the scapula and the humerus move 10-30 mm relative to the bone (most for the scapula at high arm
elevation and for humeral markers in axial rotation), and both markers of a pair move; a median
over a trial carries about half of that peak. Measured: up to 10 mm between a trial and its
session's static (7 mm martin, 10 mm kinova_martin: MET2-MET5 and CLAV_SC-CLAV_AC), up to 21 mm
between two sessions of one subject (markers re-placed); a swapped or misplaced marker changes
rigid distances by 40-300 mm."""


# --------------------------------------------------------------------------------------------
# Swaps
# --------------------------------------------------------------------------------------------
def permuted(d: np.ndarray, i: int, j: int) -> np.ndarray:
    p = np.arange(d.shape[0])
    p[[i, j]] = p[[j, i]]
    return d[np.ix_(p, p)]


def violated(d: np.ndarray, rel: np.ndarray) -> np.ndarray:
    a, x, y = rel.T
    dx, dy = d[a, x], d[a, y]
    return np.isfinite(dx) & np.isfinite(dy) & (dx > dy)


def rigid_bad(d: np.ndarray, ref: np.ndarray | None, rigid: np.ndarray) -> np.ndarray:
    if ref is None or rigid.size == 0:
        return np.zeros(len(rigid), dtype=bool)
    i, j = rigid.T
    diff = np.abs(d[i, j] - ref[i, j])
    return np.isfinite(diff) & (diff > RIGID_TOLERANCE_M)


def swap_support(exp: LabelExpectations, d: np.ndarray, ref: np.ndarray | None, ref_name: str,
                  viol: np.ndarray, bad: np.ndarray, chains: dict, stale: set, sw: tuple[int, int]
                  ) -> tuple[bool, list[str], float]:
    """Whether exchanging labels sw = (i, j) resolves the evidence, and why. Not supported when any
    evidence gets worse: a swap that breaks side relations, rigid distances or a chain fit."""
    i, j = sw
    names = exp.names
    reasons: list[str] = []
    score = 0.0
    dp = permuted(d, i, j)
    expected = int(violated(permuted(exp.model_median_m, i, j), exp.relations).sum())
    if exp.segments[i] != exp.segments[j] and expected >= RELATION_MIN_EXPECTED:
        # (within a segment, or for markers the model barely separates, its points do not decide)
        v = violated(dp, exp.relations)
        fixed, created = int((viol & ~v).sum()), int((v & ~viol).sum())
        if created >= RELATION_MIN_FIXED:
            return False, [], 0.0
        if fixed - created >= max(RELATION_MIN_FIXED, RELATION_SWAP_SHARE * expected):
            reasons.append(f"it restores {fixed} side relation(s) the model gives"
                           + (f" (and reverses {created})" if created else ""))
            score += fixed - created
    if ref is not None:
        b = rigid_bad(dp, ref, exp.rigid)
        rf, rc = int((bad & ~b).sum()), int((b & ~bad).sum())
        if rc >= rf and rc:
            return False, [], 0.0
        if rf > rc:
            reasons.append(f"it brings {rf} rigid distance(s) back within {mm_text(RIGID_TOLERANCE_M)} of {ref_name}")
            score += 10 * rf
    for root, ch in chains.items():
        if sw not in ch.by_swap or root in stale:
            continue
        rms0, rms1 = ch.rms_m, ch.by_swap[sw]
        if rms0 <= CHAIN_GOOD_RMS_M < rms1:  # only a chain that fits can object to a swap
            return False, [], 0.0
        if chain_fixed(rms0, rms1):
            alt = [(o, r) for o, r in ch.by_swap.items() if o != sw and chain_fixed(rms0, r)]
            also = ""
            if alt:
                o, r = min(alt, key=lambda t: t[1])
                also = f"; exchanging {names[o[0]]} and {names[o[1]]} instead would leave {mm_text(r)}"
            reasons.append(f"the {'-'.join(chain_label(exp, root))} chain (root free, joints within their "
                           f"ranges) then fits with an RMS residual of {mm_text(rms1)} instead of {mm_text(rms0)}{also}")
            # the largest chain a swap fixes decides between rival swaps (it holds the most
            # constraints), then the residual it removes there
            size = len(next(c for c in exp.chains if c.root == root).markers)
            score = max(score, 1e6 * size + 1e3 * (rms0 - rms1))
    return bool(reasons), reasons, score


def swap_facts(exp: LabelExpectations, d: np.ndarray, ref: np.ndarray | None, i: int, j: int) -> str:
    """The most telling distances of a swap of i and j: the marker whose distances to i and j the
    model orders most clearly (median over the sampled postures) while the trial orders them the
    other way; else a rigid distance of i that the reference contradicts."""
    names = exp.names
    mm = exp.model_median_m
    best, best_gap = None, 0.0
    for n in range(len(names)):
        if n in (i, j) or not (np.isfinite(d[n, i]) and np.isfinite(d[n, j])):
            continue
        gap = mm[n, j] - mm[n, i]  # > 0: the model puts i nearer n
        if gap * (d[n, j] - d[n, i]) < 0 and abs(gap) > max(best_gap, MODEL_POINT_TOLERANCE_M):
            best, best_gap = n, abs(gap)
    if best is not None:
        n = best
        near, far = (i, j) if mm[n, i] < mm[n, j] else (j, i)
        return (f"{names[n]} is {mm_text(d[n, near])} from {names[near]} and {mm_text(d[n, far])} from {names[far]}, "
                f"the model puts {names[near]} nearer (median {mm_text(mm[n, near])} vs {mm_text(mm[n, far])} over "
                f"the joint ranges)")
    if ref is not None:
        for a, b in exp.rigid:
            if (a in (i, j)) != (b in (i, j)) and np.isfinite(ref[a, b]) and abs(d[a, b] - ref[a, b]) > RIGID_TOLERANCE_M:
                return f"{names[a]}-{names[b]} is {mm_text(d[a, b])}, {mm_text(ref[a, b])} in the reference"
    return f"{names[i]}-{names[j]} {mm_text(d[i, j])}"
