"""The compiled kernels (exubio.model.kernels) against their numpy references: forward kinematics
(Kinematics.frames against frames_numpy) and the least-squares terms (exubio.model.pose_kernel) on
random poses, markers and weights (to 1e-12); and the reference against finite differences of its
cost and constraints (a truth that neither computes)."""
import numpy as np
import pytest

from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.model.pose_kernel import least_squares_terms, least_squares_terms_numpy

NAMES = ("cost", "H", "grad", "g", "G")


@pytest.fixture(scope="module")
def kin():
    return Kinematics(load_model())


@pytest.fixture(scope="module")
def points(kin):
    return kin.point_set([(s.name, n) for s in kin.model.segments for n in s.points])


@pytest.mark.parametrize("shape", [(), (1,), (9,), (2, 3)])
def test_compiled_forward_kinematics_equals_the_numpy_reference(kin, shape):
    q = np.random.default_rng(len(shape)).uniform(-3.0, 3.0, shape + (kin.n_coordinates,))
    got, want = kin.frames(q), kin.frames_numpy(q)
    for name in ("R", "p", "axes", "pivots"):
        a, b = getattr(got, name), getattr(want, name)
        assert a.shape == b.shape and np.abs(a - b).max() <= 1e-12, name
    # a frame's result does not depend on the batch it comes in (chunked runs equal one pass)
    flat = q.reshape(-1, kin.n_coordinates)
    assert np.array_equal(kin.frames(flat[-1:]).R[0], kin.frames(flat).R[-1])


def _problem(kin, points, seed, batch=7):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.5, 1.5, (batch, kin.n_coordinates))
    k = len(points.names)
    target = kin.points(q + rng.normal(scale=0.05, size=q.shape), points) + rng.normal(scale=0.01, size=(batch, k, 3))
    w = rng.uniform(0.2, 3.0, (batch, k))
    w[rng.random((batch, k)) < 0.2] = 0.0  # missing markers
    target[w == 0] = 0.0  # as the solve gives them (exubio.methods.poses)
    return q, target, w


@pytest.mark.parametrize("seed", range(5))
def test_compiled_terms_equal_the_numpy_reference(kin, points, seed):
    q, target, w = _problem(kin, points, seed)
    for name, a, b in zip(NAMES, least_squares_terms(kin, points, q, target, w),
                          least_squares_terms_numpy(kin, points, q, target, w)):
        assert a.shape == b.shape, name
        assert np.abs(a - b).max() <= 1e-12 * max(1.0, np.abs(b).max()), name


def test_a_frame_without_markers_has_zero_cost_and_curvature(kin, points):
    q, target, w = _problem(kin, points, 9, batch=2)
    w[1] = 0.0
    cost, H, grad, g, G = least_squares_terms(kin, points, q, target, w)
    assert cost[1] == 0.0 and not H[1].any() and not grad[1].any()
    assert cost[0] > 0.0 and np.isfinite(g).all() and np.abs(G).max() > 0


def test_reference_gradient_and_constraint_jacobian_match_finite_differences(kin, points):
    q, target, w = _problem(kin, points, 11, batch=1)
    cost, H, grad, g, G = least_squares_terms_numpy(kin, points, q, target, w)
    h = 1e-6
    for j in range(kin.n_coordinates):
        dq = np.zeros_like(q)
        dq[0, j] = h
        cp, _, _, gp, _ = least_squares_terms_numpy(kin, points, q + dq, target, w)
        cm, _, _, gm, _ = least_squares_terms_numpy(kin, points, q - dq, target, w)
        assert (cp - cm)[0] / (2 * h) / 2 == pytest.approx(grad[0, j], abs=1e-7)  # grad = J^T W e = d(cost/2)/dq
        assert (gp - gm)[0] / (2 * h) == pytest.approx(G[0, :, j], abs=1e-7)
    assert np.allclose(H, np.swapaxes(H, 1, 2)) and np.linalg.eigvalsh(H[0]).min() > -1e-12


def test_compiled_euler_parameter_motion_equals_the_numpy_reference():
    from exubio.backend.pf_numerics import ep_G, ep_rotation
    from exubio.model.kernels import euler_parameter_motion

    rng = np.random.default_rng(3)
    n, s = 6, 5
    ltg = rng.permutation(7 * s + 4)[:7 * s].reshape(s, 7).astype(np.int64)  # nodes scattered in the system vector
    X, Xt, Xtt = (rng.normal(scale=0.3, size=(n, 7 * s + 4)) for _ in range(3))
    ep_ref, p_ref = rng.normal(size=(s, 4)), rng.normal(size=(s, 3))
    R = np.empty((n, s + 1, 3, 3))
    p, v, a, w, al = (np.empty((n, s + 1, 3)) for _ in range(5))
    euler_parameter_motion(X, Xt, Xtt, ltg, ep_ref, p_ref, R, p, v, a, w, al)
    ep = X[:, ltg[:, 3:]] + ep_ref
    unit = ep / np.linalg.norm(ep, axis=-1, keepdims=True)
    G = ep_G(unit)
    assert np.array_equal(R[:, 0], np.broadcast_to(np.eye(3), (n, 3, 3))) and not p[:, 0].any() and not w[:, 0].any()
    assert np.abs(R[:, 1:] - ep_rotation(ep)).max() <= 1e-14
    assert np.abs(p[:, 1:] - (X[:, ltg[:, :3]] + p_ref)).max() == 0.0
    assert np.array_equal(v[:, 1:], Xt[:, ltg[:, :3]]) and np.array_equal(a[:, 1:], Xtt[:, ltg[:, :3]])
    assert np.abs(w[:, 1:] - (G @ Xt[:, ltg[:, 3:], None])[..., 0]).max() <= 1e-14
    assert np.abs(al[:, 1:] - (G @ Xtt[:, ltg[:, 3:], None])[..., 0]).max() <= 1e-14


@pytest.mark.parametrize("shape", [(), (1,), (8,)])
def test_compiled_coordinate_rates_equal_the_numpy_reference_and_invert_the_forward_map(kin, shape):
    rng = np.random.default_rng(20 + len(shape))
    q = rng.uniform(-1.3, 1.3, shape + (kin.n_coordinates,))
    qd_true = rng.normal(size=q.shape)
    omega = kin.segment_angular_velocities(q, qd_true)  # the forward map of the rates: a truth
    alpha = rng.normal(size=omega.shape)
    qd, qdd = kin.coordinate_rates(q, omega, alpha)
    qd_ref, qdd_ref = kin.coordinate_rates_numpy(q, omega, alpha)
    assert qd.shape == qdd.shape == q.shape
    assert np.abs(qd - qd_ref).max() <= 1e-12 and np.abs(qdd - qdd_ref).max() <= 1e-12
    assert np.abs(qd - qd_true).max() <= 1e-12
    assert np.array_equal(kin.coordinate_rates(q, omega), qd)  # without alpha: q̇ alone


def test_compiled_inverse_map_equals_the_numpy_reference_on_a_batch(kin):
    rng = np.random.default_rng(31)
    lo, hi = kin.model.coordinate_ranges_rad.T
    q = rng.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0), (40, kin.n_coordinates)).reshape(4, 10, -1)
    R = kin.frames(q).R
    for prev in (None, q + rng.normal(scale=0.05, size=q.shape), q[0, 0]):
        got = kin.coordinates_from_rotations(R, q_previous=prev)
        want = kin.coordinates_from_rotations_numpy(R, q_previous=prev)
        assert got.shape == want.shape == q.shape
        assert np.abs(got - want).max() <= 1e-9  # R's round-off times 1 / cos of a middle angle (random postures)
    assert np.abs(kin.coordinates_from_rotations(R, q_previous=q) - q).max() <= 1e-9  # the postures themselves


@pytest.mark.parametrize("shape", [(), (1,), (6,), (2, 3), (0,)])
def test_compiled_model_points_equal_the_numpy_reference(kin, points, shape):
    q = np.random.default_rng(40 + len(shape)).uniform(-2.0, 2.0, shape + (kin.n_coordinates,))
    got, want = kin.points(q, points), kin.points_numpy(q, points)
    assert got.shape == want.shape == shape + (len(points.names), 3)
    assert got.size == 0 or np.abs(got - want).max() <= 1e-14
    empty = kin.point_set([])
    assert kin.points(q, empty).shape == shape + (0, 3)
