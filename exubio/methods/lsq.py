"""One least-squares core: batched Levenberg-Marquardt / Gauss-Newton with a stop status.

Minimises, for each problem b of a batch at once, a cost c_b(x) (a weighted sum of squared
residuals plus any penalties), optionally subject to equality constraints g_b(x) = 0. The caller
gives the quantities of the Gauss-Newton model at a point (``Evaluation``): the cost, the normal
matrix H = J^T W J (+ prior and penalty curvature), the gradient J^T W e, and with constraints
their residuals g and Jacobian G. Each iteration solves the damped system

    (H + mu I) dx = -grad                                   (no constraints)
    [H + mu I, G^T; G, 0] [dx; lambda] = [-grad; -g]        (Gauss-Newton SQP, KKT system)

scales the step down to ``step_cap`` in its largest component, and keeps it only if it does not
raise the merit (beyond the slack ``accept_rtol``, ``accept_atol``): the cost, or with constraints
the l1 merit cost + rho |g|_1 (rho = 2 max|lambda| + ``RHO_FLOOR``, above the multipliers). A kept step divides the Levenberg-Marquardt damping mu by
``damping_decrease`` (not below ``damping_floor``), a rejected one multiplies it by
``damping_increase``. Why each problem stopped is its ``StopReason``.

``newton`` is the small companion for square or least-norm Newton solves of g(x) = 0 (the
constraint projections): it iterates until max |g| <= tol and says whether it got there.

Pure numpy; no exubio imports.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from exubio.types import StopReason

RHO_FLOOR = 1e-6
"""Added to 2 max|lambda| for the l1 merit's penalty weight rho (units of the cost per unit of g)."""


def stop_counts(reasons: np.ndarray) -> dict[str, int]:
    """{label: number of problems} for every StopReason (zeros included), from an array of codes."""
    codes = np.asarray(reasons, dtype=int).ravel()
    return {r.label: int((codes == r).sum()) for r in StopReason}


def converged(reasons: np.ndarray) -> np.ndarray:
    """Boolean array: which stop codes mean a solution (CONVERGED or STALLED)."""
    return np.asarray(reasons) <= StopReason.STALLED


@dataclass
class Evaluation:
    """A batch of problems evaluated at their points x (leading axis B, one row per problem).

    cost: (B,) the objective. H: (B, n, n) Gauss-Newton normal matrix; grad: (B, n) gradient of
    cost / 2 (J^T W e); both None where the evaluation did not linearise (the core then asks the
    ``linearise`` callback before the next step). g: (B, c) equality-constraint residuals and
    G: (B, c, n) their Jacobian, None without constraints. data: any further per-problem arrays
    the callbacks want to keep with the point (e.g. the residual vectors), leading axis B.
    """

    cost: np.ndarray
    H: np.ndarray | None = None
    grad: np.ndarray | None = None
    g: np.ndarray | None = None
    G: np.ndarray | None = None
    data: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def linearised(self) -> bool:
        return self.H is not None and self.grad is not None

    def rows(self, idx: np.ndarray) -> "Evaluation":
        """The problems ``idx`` (integer or boolean index), as copies."""
        H, grad, g, G = self.H, self.grad, self.g, self.G
        return Evaluation(self.cost[idx], None if H is None else H[idx], None if grad is None else grad[idx],
                          None if g is None else g[idx], None if G is None else G[idx],
                          {k: v[idx] for k, v in self.data.items()})

    def put(self, idx: np.ndarray, other: "Evaluation") -> None:
        """Write the rows of ``other`` into rows ``idx`` (integer index) of this batch; a field
        this batch lacks is allocated, one ``other`` lacks is left as it was."""
        for name in _ARRAYS:
            src = getattr(other, name)
            if src is None:
                continue
            dst = getattr(self, name)
            if dst is None:
                dst = np.zeros((self.cost.shape[0],) + src.shape[1:], dtype=src.dtype)
                setattr(self, name, dst)
            dst[idx] = src
        for k, src in other.data.items():
            if k not in self.data:
                self.data[k] = np.zeros((self.cost.shape[0],) + src.shape[1:], dtype=src.dtype)
            self.data[k][idx] = src


_ARRAYS = ("cost", "H", "grad", "g", "G")


@dataclass(frozen=True)
class Settings:
    """How the core iterates (units are those of the problem's variables and cost).

    max_iterations: steps per problem. step_tol: converged when a kept step's largest component is
    at most this (the step as proposed and capped, before any ``project``). step_cap: a step is
    scaled down so that its largest component is at most this (None: no cap). damping: mu at the
    start; damping_floor: mu never falls below it; damping_decrease / damping_increase: mu's
    factors after a kept / rejected step; damping_cap: mu beyond it stops the problem
    (DAMPING_EXHAUSTED). accept_rtol, accept_atol: a step is kept if
    merit_new <= merit_old (1 + accept_rtol) + accept_atol. stall_rtol: a kept step with
    merit_old - merit_new <= stall_rtol merit_old stops the problem as STALLED (None: no such test).
    """

    max_iterations: int
    step_tol: float
    damping: float
    damping_floor: float
    step_cap: float | None = None
    damping_decrease: float = 3.0
    damping_increase: float = 10.0
    damping_cap: float = 1e8
    accept_rtol: float = 0.0
    accept_atol: float = 0.0
    stall_rtol: float | None = None


@dataclass(frozen=True)
class Result:
    """x: (B, n) the last kept iterate of each problem. evaluation: the problems evaluated there.
    iterations: (B,) steps tried. reason: (B,) int8 StopReason codes. mu: (B,) final damping."""

    x: np.ndarray
    evaluation: Evaluation
    iterations: np.ndarray
    reason: np.ndarray
    mu: np.ndarray

    @property
    def converged(self) -> np.ndarray:
        """(B,) True where the problem stopped at a solution (CONVERGED or STALLED)."""
        return converged(self.reason)

    def stop(self, b: int = 0) -> StopReason:
        """The StopReason of problem b."""
        return StopReason(int(self.reason[b]))

    def counts(self) -> dict[str, int]:
        """{label: number of problems} for every StopReason."""
        return stop_counts(self.reason)


def fix_variables(K: np.ndarray, rhs: np.ndarray, fixed: np.ndarray | None) -> None:
    """Give the ``fixed`` variables (n,) bool a zero step in the batched systems K (B, p, p),
    rhs (B, p), in place: their rows and columns of K become identity, their rhs 0."""
    if fixed is None or not fixed.any():
        return
    idx = np.flatnonzero(fixed)
    K[:, idx, :] = 0.0
    K[:, :, idx] = 0.0
    K[:, idx, idx] = 1.0
    rhs[:, idx] = 0.0


def damped_step(ev: Evaluation, mu: np.ndarray, fixed: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """The Levenberg-Marquardt step at ``ev`` with damping mu (B,): (dx (B, n), lambda (B, c) or
    None). With constraints the Gauss-Newton SQP step of the KKT system; ``fixed`` variables do
    not move. numpy's LinAlgError if a system is singular (constraints with a rank-deficient G)."""
    B, n = ev.grad.shape
    if ev.G is None:
        A = ev.H + mu[:, None, None] * np.eye(n)
        if fixed is None or not fixed.any():
            return -np.linalg.solve(A, ev.grad[..., None])[..., 0], None
        rhs = -ev.grad
        fix_variables(A, rhs, fixed)
        return np.linalg.solve(A, rhs[..., None])[..., 0], None
    c = ev.G.shape[1]
    K = np.zeros((B, n + c, n + c))
    K[:, :n, :n] = ev.H + mu[:, None, None] * np.eye(n)
    K[:, :n, n:] = np.swapaxes(ev.G, 1, 2)
    K[:, n:, :n] = ev.G
    rhs = np.concatenate([-ev.grad, -ev.g], axis=1)
    fix_variables(K, rhs, fixed)
    sol = np.linalg.solve(K, rhs[..., None])[..., 0]
    return sol[:, :n], sol[:, n:]


Evaluate = Callable[[np.ndarray, np.ndarray], Evaluation]
"""evaluate(x (A, n), rows (A,) problem indices) -> Evaluation at x: at least the cost (and g
with constraints); H and grad (and G) too where they come cheaply with it."""

Linearise = Callable[[np.ndarray, np.ndarray, Evaluation], Evaluation]
"""linearise(x (A, n), rows (A,), evaluation at x) -> Evaluation with H and grad (and G)."""


def levenberg_marquardt(x0: np.ndarray, evaluate: Evaluate, /, *, settings: Settings,
                        linearise: Linearise | None = None,
                        step: Callable[[Evaluation, np.ndarray], tuple[np.ndarray, np.ndarray | None]] | None = None,
                        fixed: np.ndarray | None = None,
                        project: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> Result:
    """Minimise every problem of the batch x0 (B, n) from its row of x0 (see the module docstring).

    evaluate(x, rows): the problems ``rows`` at x (an ``Evaluation``). linearise(x, rows, ev): the
    same with H and grad, called before a step where ``evaluate`` gave none (None: ``evaluate``
    always linearises). step(ev, mu): the step and multipliers (default ``damped_step`` with
    ``fixed``). fixed: (n,) bool variables that keep their start value (default step only).
    project(x_trial, rows): maps a trial point onto the feasible set of simple bounds (e.g.
    clipping); the convergence test uses the step before it. Problems converge, stall, exhaust the
    damping or turn non-finite independently: each stops on its own and leaves the batch.
    """
    s = settings
    x = np.array(x0, dtype=float)
    B = x.shape[0]
    cur = evaluate(x, np.arange(B))
    stale = None if linearise is None else np.full(B, not cur.linearised)  # rows whose H, grad are missing
    if step is None:
        def step(ev: Evaluation, mu: np.ndarray):
            return damped_step(ev, mu, fixed)
    mu = np.full(B, s.damping)
    reason = np.full(B, StopReason.MAX_ITERATIONS, dtype=np.int8)
    active = np.ones(B, dtype=bool)
    it = np.zeros(B, dtype=int)
    for _ in range(s.max_iterations):
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        if stale is not None:
            need = a[stale[a]]
            if need.size:
                cur.put(need, linearise(x[need], need, cur.rows(need)))
                stale[need] = False
        sub = cur.rows(a)
        dx, lam = step(sub, mu[a])
        size = np.abs(dx).max(axis=1)
        if s.step_cap is not None:
            scale = np.minimum(1.0, s.step_cap / np.maximum(size, 1e-300))
            dx = dx * scale[:, None]
            size = size * scale  # = max |dx| after the cap, exactly (rounding is monotonic)
        x_try = x[a] + dx
        if project is not None:
            x_try = project(x_try, a)
        trial = evaluate(x_try, a)
        if lam is None or sub.g is None:
            merit_old, merit_new = sub.cost, trial.cost
        else:
            rho = 2.0 * np.abs(lam).max(axis=1) + RHO_FLOOR
            merit_old = sub.cost + rho * np.abs(sub.g).sum(axis=1)
            merit_new = trial.cost + rho * np.abs(trial.g).sum(axis=1)
        ok = merit_new <= merit_old * (1.0 + s.accept_rtol) + s.accept_atol
        kept = a[ok]
        x[kept] = x_try[ok]
        cur.put(kept, trial if ok.all() else trial.rows(ok))
        if stale is not None:
            stale[kept] = not trial.linearised
        mu[a] = np.where(ok, np.maximum(mu[a] / s.damping_decrease, s.damping_floor), mu[a] * s.damping_increase)
        it[a] += 1
        # why a problem stops, in this order of precedence
        finished = ok & (size <= s.step_tol)
        stalled = (ok & ~finished & (merit_old - merit_new <= s.stall_rtol * merit_old) if s.stall_rtol is not None
                   else np.zeros_like(ok))
        nan = np.isnan(merit_old)  # at a NaN point (or with a NaN step) no damping makes the next try finite
        trial_nan = np.isnan(merit_new)
        if trial_nan.any():
            nan |= trial_nan & np.isnan(dx).any(axis=1)
        exhausted = mu[a] > s.damping_cap
        done = finished | stalled | nan | exhausted
        if done.any():
            code = np.where(finished, StopReason.CONVERGED, np.where(
                stalled, StopReason.STALLED, np.where(nan, StopReason.NOT_FINITE, StopReason.DAMPING_EXHAUSTED)))
            reason[a[done]] = code[done]
            active[a[done]] = False
    # a problem that ran out of iterations or damping at a non-finite point: say so
    bad = ~np.isfinite(cur.cost) if cur.g is None else ~(np.isfinite(cur.cost) & np.isfinite(cur.g).all(axis=1))
    reason[bad & ~converged(reason)] = StopReason.NOT_FINITE
    return Result(x=x, evaluation=cur, iterations=it, reason=reason, mu=mu)


@dataclass(frozen=True)
class NewtonResult:
    """x: the last iterate; reason: CONVERGED (max |g| <= tol), MAX_ITERATIONS or NOT_FINITE;
    iterations: updates made; residual: max |g| at x; aux: what ``residual`` returned with g at x."""

    x: Any
    reason: StopReason
    iterations: int
    residual: float
    aux: Any = None

    @property
    def converged(self) -> bool:
        return self.reason == StopReason.CONVERGED


def newton(x: Any, residual: Callable[[Any], tuple[np.ndarray, Any]], update: Callable[[Any, np.ndarray, Any], Any],
           /, *, tol: float, max_iterations: int, first: tuple[np.ndarray, Any] | None = None) -> NewtonResult:
    """Solve g(x) = 0 by x <- update(x, g, aux) until max |g| <= tol, at most ``max_iterations``
    updates. residual(x) -> (g, aux): g any array (all problems of a batch together: the test is on
    the largest |g| of them all), aux what the update needs besides (e.g. the Jacobian); ``first``:
    residual(x) if the caller has it already. ``update`` may modify x in place and return it.
    A non-finite g does not stop the iteration early (other problems of the batch may still need
    the updates); it is reported as NOT_FINITE if the iteration ends unconverged."""
    g, aux = residual(x) if first is None else first
    it = 0
    while True:
        size = float(np.abs(g).max()) if np.size(g) else 0.0
        if size <= tol:
            return NewtonResult(x, StopReason.CONVERGED, it, size, aux)
        if it >= max_iterations:
            bad = StopReason.MAX_ITERATIONS if np.isfinite(g).all() else StopReason.NOT_FINITE
            return NewtonResult(x, bad, it, size, aux)
        x = update(x, g, aux)
        it += 1
        g, aux = residual(x)
