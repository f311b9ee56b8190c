"""Chain fits (exubio.trust.labels, point 3): every moving segment's subtree fitted to a few frames
with its root free and its joints within their ranges, with the labels as given and with two
labels exchanged; what tells mirror-image markers apart."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.trust.label_expectations import POSTURE_SEED, ChainDef, LabelExpectations, finite_ranges, marker_points

__all__ = [
    "CHAIN_FRAMES",
    "CHAIN_GOOD_RMS_M",
    "CHAIN_ITERATIONS",
    "CHAIN_MAX_TRIES",
    "CHAIN_MIN_GAIN_M",
    "CHAIN_RELIEF",
    "CHAIN_STARTS",
    "CHAIN_SWAP_RATIO",
    "CHAIN_SWAP_STARTS",
    "chain_fixed",
    "chain_label",
    "chain_scores",
]

# --------------------------------------------------------------------------------------------
# Thresholds. "Measured" figures are from the eight C3D files of ../shared/data/c3d
# (Ipuch/bioptim_exo, MIT) with the generic model and its coordinate ranges.
# --------------------------------------------------------------------------------------------
CHAIN_FRAMES = 5
"""Chain fits use 5 frames spread evenly over the frames where the chain's markers are all
present: a swap shows in every frame; 5 average over postures and keep the fits cheap."""

CHAIN_STARTS = 8
"""Starts of the fit with the labels as given: the middle of the ranges and 7 random postures
within them (fixed seed); the root's placement is solved from each (Kabsch). Mirror-like
configurations have local minima (e.g. near 180 deg of pronation), so one start is not enough."""

CHAIN_SWAP_STARTS = 4
"""Starts of the fits with two labels exchanged: the fit with the labels as given (right for every
other marker), the middle of the ranges and 2 of the random postures."""

CHAIN_ITERATIONS = 60
"""Levenberg-Marquardt iterations at most (a fit stops earlier when every start has converged);
measured: 30 iterations already give the RMS residuals within 0.05 mm of 200."""

CHAIN_GOOD_RMS_M = 0.020
"""A chain fits when its RMS marker residual is at most 20 mm, the level of a correctly labelled
chain on a generic model: skin motion up to 10 mm, proportions and joint offsets of a generic
adult (measured: 11-14 mm on the forearm-and-hand chain). A swap is supported by a chain fit only
if the chain then fits; a chain that fits as given refuses a swap that makes it not fit. A chain
whose markers the model places poorly fits worse than that whatever the labels, so it neither
supports nor refuses anything."""

CHAIN_SWAP_RATIO = 0.6
"""... and only if the swap brings the chain's RMS residual to 60 % of its value with the labels as
given, or less: a swapped pair adds about the distance between the two markers (40-80 mm) to two
residuals (measured: 34-36 mm -> 13-14 mm for the kinova_martin forearm and hand)."""

CHAIN_MIN_GAIN_M = 0.010
"""... and by at least 10 mm: a small residual can halve by chance."""

CHAIN_RELIEF = 1.5
"""A swap is tried in a chain that does not fit only if undoing it could make the chain fit: the
RMS residual of the other markers, divided by 1.5, must be at most CHAIN_GOOD_RMS_M. Undoing a
swap also relieves the other markers (the fit no longer bends to the two wrong ones), by a factor
of 1.2 on the kinova_martin forearm and hand (21 -> 17 mm); 1.5 leaves a margin. With a generic
model this skips the girdle chains, whose technical markers the model places 50-120 mm from where
this lab puts them, and most of the fitting time."""

CHAIN_MAX_TRIES = 15
"""... and at most the 15 pairs with the lowest such bound per chain (every pair of a chain of up
to 6 markers, such as the forearm and hand): the fit may blame the wrong markers of a mirror-image
swap (a radius-ulna swap can show as large residuals on the metacarpal markers), so in a small
chain every pair is tried; in a large one the cost grows with every pair. A swap that makes any
chain fit is then also tried in the larger chains that hold it, and the largest chain it makes
fit decides between rival swaps."""


# --------------------------------------------------------------------------------------------
# Chain fits (root free, joints within ranges)
# --------------------------------------------------------------------------------------------
def _skew(v: np.ndarray) -> np.ndarray:
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _kabsch(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (b, 3, 3) and translation t (b, 3) minimising sum w |R src + t - dst|^2."""
    ws = w / w.sum(axis=1, keepdims=True)
    cs = np.einsum("bk,bki->bi", ws, src)
    cd = np.einsum("bk,bki->bi", ws, dst)
    h = np.einsum("bk,bki,bkj->bij", ws, src - cs[:, None], dst - cd[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("bji,bkj->bik", vt, u)))
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    rot = np.einsum("bji,bj,bkj->bik", vt, fix, u)
    return rot, cd - np.einsum("bij,bj->bi", rot, cs)


class _ChainModel:
    """Positions of a chain's marker points in the root segment's frame, and their derivatives
    with respect to the chain's coordinates."""

    def __init__(self, kin: Kinematics, chain: ChainDef, points: PointSet):
        self.kin = kin
        self.chain = chain
        self.root = kin.model.segment_index(chain.root)
        self.points = PointSet(points.segment_index[chain.markers], points.local_m[chain.markers])
        self.m = kin.n_coordinates
        self.coordinates = np.asarray(chain.coordinates, dtype=np.int64)
        self.affects = np.ascontiguousarray(kin.affects[self.points.segment_index], dtype=float)  # (k, m): 1.0 where q_j moves the point

    def local(self, qc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from exubio.model import batch_kernels as kernels  # numba: imported where used

        q = np.zeros(qc.shape[:-1] + (self.m,))
        q[..., self.chain.coordinates] = qc
        fr = self.kin.frames(q)
        p = self.kin.points(q, self.points, frames=fr)
        rel = np.empty(p.shape)
        jrel = np.empty(p.shape + (len(self.chain.coordinates),))
        kernels.chain_in_root_frame(fr.R, fr.p, fr.axes, fr.pivots, p, self.affects, self.coordinates, self.root,
                                    rel, jrel)  # = _chain_in_root_frame_numpy, bit for bit
        return rel, jrel

    def local_numpy(self, qc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``local`` in numpy: the compiled kernel's reference."""
        q = np.zeros(qc.shape[:-1] + (self.m,))
        q[..., self.chain.coordinates] = qc
        fr = self.kin.frames(q)
        p = self.kin.points(q, self.points, frames=fr)
        return _chain_in_root_frame_numpy(self.kin, self.points, fr, p, self.chain.coordinates, self.root)


def _chain_in_root_frame_numpy(kin: Kinematics, points: PointSet, fr, p: np.ndarray, coordinates: np.ndarray,
                               root: int) -> tuple[np.ndarray, np.ndarray]:
    """The points p (b, k, 3) and their Jacobian with respect to ``coordinates`` in the frame of
    segment ``root`` at the forward kinematics ``fr``: the numpy reference of
    exubio.model.batch_kernels.chain_in_root_frame."""
    jac = kin.point_jacobian(None, points, frames=fr, positions=p)[..., coordinates]
    rot = fr.R[..., root, :, :]
    org = fr.p[..., root, :]
    return np.einsum("bji,bkj->bki", rot, p - org[:, None, :]), np.einsum("bji,bkjc->bkic", rot, jac)


def _normal_equations_numpy(rot: np.ndarray, rel: np.ndarray, jrel: np.ndarray, w: np.ndarray,
                            e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Newton terms (hess (b, p, p), grad (b, p)) of the chain fit at the placement rot
    and the chain's points rel (b, k, 3) and Jacobian jrel (b, k, 3, c) in the root frame, marker
    weights w (b, k), residuals e (b, k, 3): the numpy reference of
    exubio.model.batch_kernels.chain_normal_equations."""
    jw = np.empty(rel.shape[:2] + (3, 6 + jrel.shape[-1]))
    jw[..., :3] = -np.einsum("bij,bkjl->bkil", rot, _skew(rel))
    jw[..., 3:6] = np.eye(3)
    jw[..., 6:] = np.einsum("bij,bkjc->bkic", rot, jrel)
    jw *= w[..., None, None]
    return np.einsum("bkip,bkiq->bpq", jw, jw), np.einsum("bkip,bki->bp", jw, e)


def _fit_chain(cm: _ChainModel, targets: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares fit of the chain to each target (b, k, 3) from every start ((s, nc), or
    (b, s, nc) per target); the root's placement is solved from each start (Kabsch). Returns the
    per-marker residual (b, k) (m) and the coordinates (b, nc) of the best start. Missing target
    markers (NaN) are ignored."""
    from exubio.model import batch_kernels as kernels  # numba: imported where used

    b, k, _ = targets.shape
    starts = np.broadcast_to(starts, (b,) + starts.shape[-2:])
    s, nc = starts.shape[1:]
    tgt = np.repeat(targets, s, axis=0)  # (b*s, k, 3)
    w = np.isfinite(tgt).all(axis=2).astype(float)
    tgt = np.where(w[..., None] > 0, tgt, 0.0)
    qc = starts.reshape(b * s, nc).copy()
    rel, jrel = cm.local(qc)
    rot, t = _kabsch(rel, tgt, np.maximum(w, 1e-12))

    def residual(rot_, t_, rel_):
        return (np.einsum("bij,bkj->bki", rot_, rel_) + t_[:, None, :] - tgt) * w[..., None]

    e = residual(rot, t, rel)
    cost = (e * e).sum(axis=(1, 2))
    mu = np.full(len(qc), 1e-3)
    n_par = 6 + nc
    eye = np.eye(n_par)
    hess = np.empty((len(qc), n_par, n_par))
    grad = np.empty((len(qc), n_par))
    for _ in range(CHAIN_ITERATIONS):
        if nc >= 2:  # the compiled terms, bit for bit those of numpy, which sums one coordinate's column otherwise
            kernels.chain_normal_equations(rot, rel, jrel, w, e, hess, grad)
        else:
            hess, grad = _normal_equations_numpy(rot, rel, jrel, w, e)
        diag = np.einsum("bpp->bp", hess)
        step = -np.linalg.solve(hess + mu[:, None, None] * (eye * (diag[:, None, :] + 1e-9)), grad[..., None])[..., 0]
        big = np.abs(step).max(axis=1)
        step *= np.minimum(1.0, 0.5 / np.maximum(big, 1e-300))[:, None]
        dw = step[:, :3]
        angle = np.linalg.norm(dw, axis=1)
        axis = dw / np.maximum(angle, 1e-300)[:, None]
        rot_new = np.einsum("bij,bjk->bik", rot, _rodrigues(axis, angle))
        t_new = t + step[:, 3:6]
        qc_new = np.clip(qc + step[:, 6:], lo, hi)
        rel_new, jrel_new = cm.local(qc_new)
        e_new = residual(rot_new, t_new, rel_new)
        cost_new = (e_new * e_new).sum(axis=(1, 2))
        ok = cost_new < cost
        done = np.where(ok, cost - cost_new <= 1e-8 * cost + 1e-14, mu >= 1e6)
        rot[ok], t[ok], qc[ok], rel[ok], jrel[ok], e[ok], cost[ok] = (
            rot_new[ok], t_new[ok], qc_new[ok], rel_new[ok], jrel_new[ok], e_new[ok], cost_new[ok])
        mu = np.where(ok, np.maximum(mu / 3.0, 1e-9), np.minimum(mu * 10.0, 1e9))
        if done.all():
            break
    per = np.linalg.norm(e, axis=2).reshape(b, s, k)
    best = cost.reshape(b, s).argmin(axis=1)
    res = per[np.arange(b), best]
    return np.where(np.isfinite(targets).all(axis=2), res, np.nan), qc.reshape(b, s, nc)[np.arange(b), best]


def _rodrigues(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    k = _skew(axis)
    s = np.sin(angle)[:, None, None]
    c = np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def _chain_frames(pos: np.ndarray, markers: np.ndarray) -> np.ndarray:
    full = np.flatnonzero(np.isfinite(pos[:, markers]).all(axis=(1, 2)))
    if full.size == 0:
        return full
    pick = np.unique(np.round(np.linspace(0, full.size - 1, min(CHAIN_FRAMES, full.size))).astype(int))
    return full[pick]


@dataclass(frozen=True)
class _ChainResult:
    rms_m: float  # RMS residual with the labels as given
    residual_m: np.ndarray  # (k,) median residual per protocol marker (NaN outside the chain)
    by_swap: dict  # (i, j) -> RMS residual with labels i and j exchanged


def chain_scores(exp: LabelExpectations, pos: np.ndarray) -> dict[str, _ChainResult]:
    """Fit every chain to a few frames with the labels as given. In a chain that does not fit
    (RMS > CHAIN_GOOD_RMS_M), fit again with the labels of two of its markers exchanged, for every
    pair whose exchange could make it fit (see CHAIN_RELIEF)."""
    model = exp.model
    kin = Kinematics(model)
    points = marker_points(kin, exp.protocol)
    fin = finite_ranges(exp.ranges_rad, model.n_coordinates)
    lo_all = np.asarray(exp.ranges_rad, dtype=float)[:, 0]
    hi_all = np.asarray(exp.ranges_rad, dtype=float)[:, 1]
    seen = np.isfinite(pos).all(axis=2).any(axis=0)
    prepared = []
    for chain in exp.chains:
        mk = chain.markers[seen[chain.markers]]
        if len(mk) < 4 or len({exp.segments[m] for m in mk}) < 2:
            continue
        frames = _chain_frames(pos, mk)
        if frames.size == 0:
            continue
        chain = ChainDef(chain.root, chain.segments, chain.coordinates, mk)
        gen = np.random.default_rng(POSTURE_SEED)
        flo, fhi = fin[chain.coordinates, 0], fin[chain.coordinates, 1]
        starts = np.vstack([0.5 * (flo + fhi), flo + (fhi - flo) * gen.random((CHAIN_STARTS - 1, len(flo)))])
        prepared.append((chain, frames, starts, _ChainModel(kin, chain, points)))

    def fit(item, hyps: list, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        chain, frames, _, cm = item
        targets = []
        for sw in hyps:
            perm = np.arange(pos.shape[1])
            if sw is not None:
                perm[[sw[0], sw[1]]] = perm[[sw[1], sw[0]]]
            targets.append(pos[np.ix_(frames, perm[chain.markers])])
        res, q = _fit_chain(cm, np.concatenate(targets, axis=0), lo_all[chain.coordinates],
                            hi_all[chain.coordinates], starts)
        return res.reshape(len(hyps), frames.size, len(chain.markers)), q

    given = {}
    warm = {}
    searched = []  # (chain root, swap) pairs worth fitting
    for item in prepared:
        chain = item[0]
        mk = chain.markers
        res0, q0 = fit(item, [None], item[2])
        res0 = res0[0]
        warm[chain.root] = q0  # (frames, nc): the given fit, a start for the swap hypotheses
        per_marker = np.full(pos.shape[1], np.nan)
        per_marker[mk] = np.nanmedian(res0, axis=0)
        given[chain.root] = (res0, per_marker)
        if np.sqrt(np.nanmean(res0 ** 2)) <= CHAIN_GOOD_RMS_M:
            continue  # the chain fits: nothing to search
        r2 = np.nanmean(res0 ** 2, axis=0)  # per marker, over the frames
        bounds = sorted((np.sqrt((r2.sum() - r2[x] - r2[y]) / len(mk)) / CHAIN_RELIEF, int(mk[x]), int(mk[y]))
                        for x, y in itertools.combinations(range(len(mk)), 2))
        small = len(bounds) <= CHAIN_MAX_TRIES  # a small chain: every pair (CHAIN_MAX_TRIES says why)
        searched += [(chain.root, (x, y)) for b, x, y in bounds[:CHAIN_MAX_TRIES] if small or b <= CHAIN_GOOD_RMS_M]
    def try_swaps(item, hyps: list) -> dict:
        if not hyps:
            return {}
        generic = item[2][:CHAIN_SWAP_STARTS - 1]
        per_frame = np.concatenate([warm[item[0].root][:, None, :],
                                    np.broadcast_to(generic, (len(item[1]),) + generic.shape)], axis=1)
        rms = np.sqrt(np.nanmean(fit(item, hyps, np.tile(per_frame, (len(hyps), 1, 1)))[0] ** 2, axis=(1, 2)))
        return {sw: float(r) for sw, r in zip(hyps, rms)}

    rms0 = {root: float(np.sqrt(np.nanmean(res ** 2))) for root, (res, _) in given.items()}
    by_swap: dict[str, dict] = {}
    for item in prepared:
        root = item[0].root
        by_swap[root] = try_swaps(item, sorted({tuple(sorted(sw)) for r, sw in searched if r == root}))
    # a swap that makes one chain fit is also tried in every other chain that holds both markers
    # and does not fit, so that rival swaps are compared on the same chains
    winners = {sw for root, d_ in by_swap.items() for sw, r in d_.items() if chain_fixed(rms0[root], r)}
    for item in prepared:
        root, members = item[0].root, set(int(m) for m in item[0].markers)
        if rms0[root] <= CHAIN_GOOD_RMS_M:
            continue
        extra = sorted(sw for sw in winners if sw not in by_swap[root] and set(sw) <= members)
        by_swap[root].update(try_swaps(item, extra))
    return {root: _ChainResult(rms_m=rms0[root], residual_m=given[root][1], by_swap=by_swap[root])
            for root in given}


def chain_fixed(rms0: float, rms1: float) -> bool:
    return rms1 <= CHAIN_GOOD_RMS_M and rms1 <= CHAIN_SWAP_RATIO * rms0 and rms0 - rms1 >= CHAIN_MIN_GAIN_M


def chain_label(exp: LabelExpectations, root: str) -> tuple[str, ...]:
    chain = next(c for c in exp.chains if c.root == root)
    return tuple(s for s in chain.segments if s in {exp.segments[m] for m in chain.markers})
