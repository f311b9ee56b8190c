"""The scapulothoracic constraints after a solve: the least-norm projection of q (and q̇, q̈) onto
g = 0 (G q̇ = 0, G q̈ + eta = 0), shared by both methods."""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

from exubio.model.kinematics import Kinematics
from exubio.methods.lsq import NewtonResult, newton

log = logging.getLogger(__name__)


def _constraint_chain(kin: Kinematics) -> tuple[Kinematics, np.ndarray]:
    """Kinematics of the chain that carries the ellipsoid contact points (thorax, clavicle,
    scapula) and the indices of its coordinates in the full model: g depends on nothing else, and
    the projection below runs ~4x faster on it. Made once per ``kin`` and kept on it (57 us a
    build: the live loop projects a block of 16 frames at a time)."""
    chain = kin.__dict__.get("_constraint_chain")
    if chain is None:
        chain = kin.__dict__["_constraint_chain"] = _make_constraint_chain(kin)
    return chain


def _make_constraint_chain(kin: Kinematics) -> tuple[Kinematics, np.ndarray]:
    model = kin.model
    keep: set[int] = set()
    for i in np.unique(kin.contacts.segment_index):
        i = int(i)
        while i >= 0:
            keep.add(i)
            i = int(kin.parent_index[i])
    sub = dataclasses.replace(model, segments=tuple(model.segments[i] for i in sorted(keep)))
    names = model.coordinate_names
    return Kinematics(sub), np.array([names.index(c) for c in sub.coordinate_names], dtype=int)


def _constraint_terms(kin: Kinematics, q: np.ndarray):
    """g (n, 2), G (n, 2, m) and the contact-point offsets e and Jacobians J from one
    forward-kinematics pass."""
    fr = kin.frames(q)
    r = kin.points(q, kin.contacts, frames=fr)
    J = kin.point_jacobian(q, kin.contacts, frames=fr, positions=r)
    e = r - kin.centre
    g = np.einsum("...kc,c->...k", e * e, kin.a_diag) - 1.0
    G = 2.0 * np.einsum("...kc,...kcm->...km", e * kin.a_diag, J)
    return g, G, e, J


def _pinv_apply(G: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """G^T (G G^T)^-1 rhs, frame by frame: the least-norm correction that makes G x = rhs."""
    GGt = G @ np.swapaxes(G, -1, -2)
    return np.einsum("...km,...k->...m", G, np.linalg.solve(GGt, rhs[..., None])[..., 0])


BLOCK_FRAMES = 8192
"""Frames are projected in blocks of this many (each frame is independent): all frames of a long
trial at once held ~4 kB of temporaries per frame."""


def project_on_constraints(kin: Kinematics, q: np.ndarray, qd: np.ndarray | None = None,
                           qdd: np.ndarray | None = None, /, *, tol: float = 1e-13, max_iterations: int = 4,
                           held: np.ndarray | None = None):
    """Project (q, q̇, q̈) on the constraints (``_project_block``), BLOCK_FRAMES frames at a time.
    Returns q, q̇, q̈ and (max |g|, max |G q̇|) before the projection; a block whose Newton
    iteration on g = 0 stops above ``tol`` is logged (its max |g| after, and why)."""
    n = q.shape[0]
    if n <= BLOCK_FRAMES:
        *out, solved = _project_block(kin, q, qd, qdd, tol=tol, max_iterations=max_iterations, held=held)
        _log_unsettled(solved, 0, n, tol)
        return tuple(out)
    parts = [_project_block(kin, q[a:a + BLOCK_FRAMES], None if qd is None else qd[a:a + BLOCK_FRAMES],
                            None if qdd is None else qdd[a:a + BLOCK_FRAMES], tol=tol, max_iterations=max_iterations,
                            held=held) for a in range(0, n, BLOCK_FRAMES)]
    for a, p in zip(range(0, n, BLOCK_FRAMES), parts):
        _log_unsettled(p[4], a, min(a + BLOCK_FRAMES, n), tol)
    befores = [p[3] for p in parts]
    before = tuple(float(np.nanmax([b[i] for b in befores])) if any(np.isfinite(b[i]) for b in befores)
                   else float("nan") for i in range(2))
    qd_out = None if qd is None else np.concatenate([p[1] for p in parts])
    qdd_out = None if qdd is None else np.concatenate([p[2] for p in parts])
    return np.concatenate([p[0] for p in parts]), qd_out, qdd_out, before


def _log_unsettled(solved: NewtonResult | None, start: int, stop: int, tol: float) -> None:
    """Say where and why a projection's Newton iteration stopped above its tolerance."""
    if solved is not None and not solved.converged:
        log.warning("constraint projection of frames %d-%d stopped at max |g| = %.1e, above %.0e (%s)",
                    start, stop - 1, solved.residual, tol, solved.reason.label)


def _project_block(kin: Kinematics, q: np.ndarray, qd: np.ndarray | None = None,
                   qdd: np.ndarray | None = None, /, *, tol: float = 1e-13, max_iterations: int = 4,
                   held: np.ndarray | None = None):
    """Project (q, q̇, q̈) on g = 0, G q̇ = 0, G q̈ + eta = 0 (least-norm corrections in coordinate
    space, every frame at once; only the coordinates g depends on change; ``held`` coordinates are
    not corrected). Without q̇ and q̈ only q is projected. Frames with non-finite values are left
    alone. Returns q, q̇, q̈, (max |g|, max |G q̇|) before the projection, and the Newton
    iteration's result on g = 0 (exubio.methods.lsq.NewtonResult: whether it reached ``tol`` and max |g|
    after; None when no frame is finite)."""
    positions_only = qd is None
    if positions_only:
        qd = np.zeros_like(q)
        qdd = np.zeros_like(q)
    ok = np.isfinite(q).all(axis=1) & np.isfinite(qd).all(axis=1) & np.isfinite(qdd).all(axis=1)
    if not ok.any():
        return q, qd, qdd, (float("nan"), float("nan")), None
    chain, cols = _constraint_chain(kin)
    q, qd, qdd = q.copy(), qd.copy(), qdd.copy()
    x, v, a = (arr[np.ix_(ok, cols)] for arr in (q, qd, qdd))
    free = np.ones(len(cols)) if held is None else (~np.asarray(held, dtype=bool)[cols]).astype(float)
    g, G, e, J = _constraint_terms(chain, x)
    before = (float(np.abs(g).max()), float(np.abs(np.einsum("...km,...m->...k", G, v)).max()))

    def terms(xx: np.ndarray):
        g, G, e, J = _constraint_terms(chain, xx)
        return g, (G, e, J)

    def update(xx: np.ndarray, g: np.ndarray, aux) -> np.ndarray:
        return xx - _pinv_apply(aux[0] * free, g)  # held coordinates are not corrected

    solved = newton(x, terms, update, tol=tol, max_iterations=max_iterations, first=(g, (G, e, J)))
    x, (G, e, J) = solved.x, solved.aux
    if positions_only:
        q[np.flatnonzero(ok)[:, None], cols] = x
        return q, None, None, before, solved
    v = v - _pinv_apply(G * free, np.einsum("...km,...m->...k", G, v))
    rd = np.einsum("...kcm,...m->...kc", J, v)
    bias = chain.point_bias_acceleration(x, v, chain.contacts)
    eta = 2.0 * np.einsum("...kc,c->...k", rd * rd + e * bias, chain.a_diag)
    a = a - _pinv_apply(G * free, np.einsum("...km,...m->...k", G, a) + eta)
    rows = np.flatnonzero(ok)[:, None]
    q[rows, cols], qd[rows, cols], qdd[rows, cols] = x, v, a
    return q, qd, qdd, before, solved
