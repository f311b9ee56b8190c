"""The least-squares core (exubio.methods.lsq) on problems with a known answer, and why it stops."""
import numpy as np
import pytest

from exubio.methods.lsq import Evaluation, Settings, damped_step, levenberg_marquardt, newton, stop_counts
from exubio.types import StopReason

PLAIN = Settings(max_iterations=100, step_tol=1e-12, damping=1e-12, damping_floor=1e-15, accept_rtol=1e-12)
"""Nearly Gauss-Newton; a step that raises the cost by no more than rounding is kept (as in LS):
without that slack a problem already at its minimum rejects its rounding-level steps and ends in
DAMPING_EXHAUSTED."""


def _least_squares(residual, jacobian):
    """evaluate(x, rows) of sum r(x)^2 for a batch: r (B, k), J (B, k, n) from row-wise functions
    residual(x, rows) and jacobian(x)."""
    def evaluate(x, rows):
        r, J = residual(x, rows), jacobian(x)
        return Evaluation(cost=(r * r).sum(axis=1), H=np.swapaxes(J, 1, 2) @ J,
                          grad=(np.swapaxes(J, 1, 2) @ r[..., None])[..., 0])
    return evaluate


def test_a_linear_least_squares_problem_is_solved_in_one_step():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 3))
    b = rng.normal(size=(4, 6))  # four right-hand sides: four problems of one batch
    evaluate = _least_squares(lambda x, rows: x @ A.T - b[rows], lambda x: np.broadcast_to(A, (len(x), 6, 3)))
    exact = np.linalg.lstsq(A, b.T, rcond=None)[0].T
    one = levenberg_marquardt(np.zeros((4, 3)), evaluate, settings=Settings(**{**PLAIN.__dict__, "max_iterations": 1}))
    np.testing.assert_allclose(one.x, exact, atol=1e-10)
    assert (one.reason == StopReason.MAX_ITERATIONS).all()  # the step was not yet below the tolerance
    full = levenberg_marquardt(np.zeros((4, 3)), evaluate, settings=PLAIN)
    np.testing.assert_allclose(full.x, exact, atol=1e-12)
    assert (full.reason <= StopReason.STALLED).all() and full.converged.all()
    assert (full.iterations <= 3).all()
    np.testing.assert_allclose(full.evaluation.cost, ((exact @ A.T - b) ** 2).sum(axis=1), rtol=1e-12)


def _rosenbrock():
    """r = (10 (x2 - x1^2), 1 - x1): the Rosenbrock valley as least squares, minimum 0 at (1, 1)."""
    def residual(x, rows):
        return np.stack([10.0 * (x[:, 1] - x[:, 0] ** 2), 1.0 - x[:, 0]], axis=1)

    def jacobian(x):
        J = np.zeros((len(x), 2, 2))
        J[:, 0, 0], J[:, 0, 1], J[:, 1, 0] = -20.0 * x[:, 0], 10.0, -1.0
        return J
    return _least_squares(residual, jacobian)


def test_rosenbrock_from_far_starts():
    starts = np.array([[-1.2, 1.0], [-3.0, -4.0], [5.0, 30.0], [0.0, 0.0]])
    res = levenberg_marquardt(starts, _rosenbrock(), settings=Settings(max_iterations=500, step_tol=1e-12,
                                                                       damping=1e-3, damping_floor=1e-12, step_cap=1.0))
    np.testing.assert_allclose(res.x, 1.0, atol=1e-9)
    assert res.converged.all(), res.reason
    assert stop_counts(res.reason)["converged"] + stop_counts(res.reason)["stalled"] == 4


def test_too_few_iterations_end_in_max_iterations():
    res = levenberg_marquardt(np.array([[-1.2, 1.0]]), _rosenbrock(),
                              settings=Settings(max_iterations=3, step_tol=1e-12, damping=1e-3, damping_floor=1e-12))
    assert res.stop(0) == StopReason.MAX_ITERATIONS and not res.converged[0]
    assert res.iterations[0] == 3
    assert res.counts() == {"converged": 0, "stalled": 0, "max_iterations": 1, "damping_exhausted": 0, "not_finite": 0}


def test_nearest_point_on_a_plane_in_one_step():
    """min |x - p|^2 subject to n.x = c: the KKT step is exact, the projection p - (n.p - c) n/|n|^2."""
    n, c = np.array([1.0, 2.0, -2.0]), 0.5
    p = np.array([[1.0, 1.0, 1.0], [0.0, -3.0, 2.0]])

    def evaluate(x, rows):
        e = x - p[rows]
        return Evaluation(cost=(e * e).sum(axis=1), H=np.broadcast_to(np.eye(3), (len(x), 3, 3)).copy(), grad=e,
                          g=(x @ n - c)[:, None], G=np.broadcast_to(n, (len(x), 1, 3)).copy())

    res = levenberg_marquardt(np.zeros((2, 3)), evaluate, settings=PLAIN)
    exact = p - ((p @ n - c) / (n @ n))[:, None] * n
    np.testing.assert_allclose(res.x, exact, atol=1e-12)
    assert (res.reason == StopReason.CONVERGED).all() and (res.iterations <= 3).all()  # then steps of rounding size


def _ellipse(p, a=2.0, b=1.0):
    """min |x - p|^2 subject to (x/a)^2 + (y/b)^2 = 1, the Gauss-Newton model (H = I, without the
    constraint's curvature times its multiplier: exact near the ellipse, poor far from it)."""
    def evaluate(x, rows):
        e = x - p[rows]
        return Evaluation(cost=(e * e).sum(axis=1), H=np.broadcast_to(np.eye(2), (len(x), 2, 2)).copy(), grad=e,
                          g=((x[:, 0] / a) ** 2 + (x[:, 1] / b) ** 2 - 1.0)[:, None],
                          G=np.stack([2 * x[:, 0] / a**2, 2 * x[:, 1] / b**2], axis=1)[:, None, :])
    return evaluate


ELLIPSE = Settings(max_iterations=200, step_tol=1e-13, damping=1e-6, damping_floor=1e-6, step_cap=0.3,
                   accept_rtol=1e-12, accept_atol=1e-18)  # LS's settings, without its stall test


def test_nearest_point_on_an_ellipse_with_the_constraint_as_an_equality():
    """The Gauss-Newton SQP with the l1 merit: the optimum is where x - p is normal to the ellipse;
    checked against a dense sampling of the ellipse."""
    a, b = 2.0, 1.0
    p = np.array([[2.1, 0.3], [0.3, 0.9], [-1.9, -0.4], [0.0, 1.2], [0.5, -1.1]])
    res = levenberg_marquardt(p * 0.8 + 0.1, _ellipse(p), settings=ELLIPSE)
    assert (res.reason == StopReason.CONVERGED).all(), res.reason
    t = np.linspace(0, 2 * np.pi, 400001)
    ring = np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
    for x, q in zip(res.x, p):
        assert abs((x[0] / a) ** 2 + (x[1] / b) ** 2 - 1.0) < 1e-14  # on the ellipse
        nearest = ring[np.argmin(((ring - q) ** 2).sum(axis=1))]
        assert np.linalg.norm(x - nearest) < 1e-4  # the sampling's resolution
        assert np.linalg.norm(x - q) <= np.linalg.norm(nearest - q) + 1e-12  # no sample is nearer
        normal = np.array([x[0] / a**2, x[1] / b**2])
        d = x - q
        assert abs(normal[0] * d[1] - normal[1] * d[0]) < 1e-12  # x - p along the normal
    np.testing.assert_allclose(res.x[3], [0.0, 1.0], atol=1e-12)  # on the minor axis: the vertex


def test_far_from_the_constraint_the_gauss_newton_sqp_stalls_in_a_flat_valley():
    """From p = (0, 5) the multiplier is large and the Gauss-Newton model misses the curvature the
    constraint adds: the steps creep along the ellipse while the merit changes by rounding only.
    Without a stall test that runs out of iterations; with LS's (1e-12 of the merit) the problem
    STALLs a little off the vertex, where the cost along the ellipse, 16 + 8 t^2, no longer changes
    by 1e-12 of itself."""
    p = np.array([[0.0, 5.0]])
    creep = levenberg_marquardt(p * 0.5 + 0.1, _ellipse(p), settings=ELLIPSE)
    assert creep.stop(0) == StopReason.MAX_ITERATIONS
    flat = levenberg_marquardt(p * 0.5 + 0.1, _ellipse(p), settings=Settings(**{**ELLIPSE.__dict__, "stall_rtol": 1e-12}))
    assert flat.stop(0) == StopReason.STALLED and flat.converged[0]
    assert abs(flat.x[0, 0]) < 1e-5 and abs(flat.x[0, 1] - 1.0) < 1e-9


def test_a_direction_that_never_lowers_the_cost_exhausts_the_damping():
    """A wrong gradient (its sign flipped): every step raises the cost, the damping grows tenfold
    per try until beyond its cap, and x stays where it started."""
    def evaluate(x, rows):
        return Evaluation(cost=(x * x).sum(axis=1), H=np.broadcast_to(np.eye(2), (len(x), 2, 2)).copy(), grad=-x)

    res = levenberg_marquardt(np.array([[1.0, 2.0]]), evaluate, settings=Settings(max_iterations=100, step_tol=1e-12,
                                                                                 damping=1.0, damping_floor=1e-9))
    assert res.stop(0) == StopReason.DAMPING_EXHAUSTED
    np.testing.assert_array_equal(res.x, [[1.0, 2.0]])
    assert res.iterations[0] == 9 and res.mu[0] > 1e8  # 1 -> 1e9 in nine tenfold steps


def test_a_singular_flat_problem_stalls_or_converges_as_documented():
    """Singular normal matrix: the variable the cost does not see keeps its start value (the
    damping makes the system solvable) and the problem converges. A cost that stays flat while a
    nonzero gradient keeps proposing steps (a flat valley) STALLs when stall_rtol is set and runs
    out of iterations when it is not."""
    def seen_once(x, rows):  # cost (x0 - 1)^2, x1 unseen
        H = np.zeros((len(x), 2, 2))
        H[:, 0, 0] = 1.0
        return Evaluation(cost=(x[:, 0] - 1.0) ** 2, H=H, grad=np.stack([x[:, 0] - 1.0, 0 * x[:, 1]], axis=1))

    res = levenberg_marquardt(np.array([[5.0, 7.0]]), seen_once, settings=PLAIN)
    assert res.stop(0) == StopReason.CONVERGED
    np.testing.assert_allclose(res.x, [[1.0, 7.0]], atol=1e-12)

    def flat(x, rows):
        return Evaluation(cost=np.ones(len(x)), H=np.broadcast_to(np.eye(2), (len(x), 2, 2)).copy(),
                          grad=np.tile([1.0, 0.0], (len(x), 1)))

    stalled = levenberg_marquardt(np.zeros((1, 2)), flat, settings=Settings(**{**PLAIN.__dict__, "stall_rtol": 1e-12}))
    assert stalled.stop(0) == StopReason.STALLED and stalled.converged[0] and stalled.iterations[0] == 1
    unbounded = levenberg_marquardt(np.zeros((1, 2)), flat, settings=Settings(**{**PLAIN.__dict__, "max_iterations": 20}))
    assert unbounded.stop(0) == StopReason.MAX_ITERATIONS


def test_a_nan_stops_its_problem_at_once_and_leaves_the_others_alone():
    base = _rosenbrock()

    def evaluate(x, rows):
        ev = base(x, rows)
        bad = rows == 1
        ev.cost[bad], ev.grad[bad], ev.H[bad] = np.nan, np.nan, np.nan
        return ev

    starts = np.array([[-1.2, 1.0], [-1.2, 1.0], [2.0, 2.0]])
    settings = Settings(max_iterations=500, step_tol=1e-12, damping=1e-3, damping_floor=1e-12, step_cap=1.0)
    res = levenberg_marquardt(starts, evaluate, settings=settings)
    alone = levenberg_marquardt(starts[[0, 2]], base, settings=settings)
    assert res.stop(1) == StopReason.NOT_FINITE and res.iterations[1] == 1
    np.testing.assert_array_equal(res.x[1], starts[1])
    np.testing.assert_array_equal(res.x[[0, 2]], alone.x)  # the batch changes nothing for the others
    np.testing.assert_array_equal(res.iterations[[0, 2]], alone.iterations)


def test_fixed_variables_and_bounds():
    """fixed: a variable keeps its start value; project: a trial point is clipped to bounds."""
    def evaluate(x, rows):  # cost |x - (3, 3)|^2
        return Evaluation(cost=((x - 3.0) ** 2).sum(axis=1), H=np.broadcast_to(np.eye(2), (len(x), 2, 2)).copy(),
                          grad=x - 3.0)

    res = levenberg_marquardt(np.zeros((1, 2)), evaluate, settings=PLAIN, fixed=np.array([False, True]))
    np.testing.assert_allclose(res.x, [[3.0, 0.0]], atol=1e-12)
    assert res.converged[0]

    def clip(x, rows):
        x[:, 1] = np.clip(x[:, 1], 0.0, 1.0)
        return x

    bounded = levenberg_marquardt(np.zeros((1, 2)), evaluate, settings=Settings(**{**PLAIN.__dict__, "max_iterations": 30}),
                                  project=clip)
    np.testing.assert_allclose(bounded.x, [[3.0, 1.0]], atol=1e-12)
    # the convergence test is on the proposed step, which keeps pushing against the bound
    assert bounded.stop(0) == StopReason.MAX_ITERATIONS


def test_damped_step_is_the_kkt_solution():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(3, 5, 4))
    ev = Evaluation(cost=np.zeros(3), H=np.swapaxes(J, 1, 2) @ J, grad=rng.normal(size=(3, 4)),
                    g=rng.normal(size=(3, 2)), G=rng.normal(size=(3, 2, 4)))
    mu = np.array([0.0, 1e-3, 1.0])
    dx, lam = damped_step(ev, mu)
    for b in range(3):
        np.testing.assert_allclose((ev.H[b] + mu[b] * np.eye(4)) @ dx[b] + ev.G[b].T @ lam[b], -ev.grad[b], atol=1e-10)
        np.testing.assert_allclose(ev.G[b] @ dx[b], -ev.g[b], atol=1e-12)


@pytest.mark.parametrize("start, reason", [(0.5, StopReason.CONVERGED), (np.nan, StopReason.NOT_FINITE)])
def test_newton_says_why_it_stopped(start, reason):
    res = newton(np.array([start]), lambda x: (x * x - 2.0, 2.0 * x), lambda x, g, d: x - g / d,
                 tol=1e-14, max_iterations=50)
    assert res.reason == reason
    if reason == StopReason.CONVERGED:
        np.testing.assert_allclose(res.x, [np.sqrt(2.0)], rtol=1e-15)
        assert res.residual <= 1e-14 and res.iterations < 10
    short = newton(np.array([0.5]), lambda x: (x * x - 2.0, 2.0 * x), lambda x, g, d: x - g / d,
                   tol=1e-14, max_iterations=2)
    assert short.reason == StopReason.MAX_ITERATIONS and short.iterations == 2 and not short.converged


def test_stop_reasons_are_plain_labels():
    assert [r.label for r in StopReason] == ["converged", "stalled", "max_iterations", "damping_exhausted", "not_finite"]
    assert StopReason.STALLED.converged and not StopReason.DAMPING_EXHAUSTED.converged
    assert stop_counts(np.array([0, 0, 3], dtype=np.int8)) == {"converged": 2, "stalled": 0, "max_iterations": 0,
                                                               "damping_exhausted": 1, "not_finite": 0}
