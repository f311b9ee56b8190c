"""Analytic kinematics against finite differences at random configurations, and inverse maps."""
import numpy as np
import pytest

from exubio.model.kinematics import Kinematics, axis_rotation
from exubio.model.load import load_model

RNG_SEEDS = [0, 1, 2, 3, 4]
H = 1e-6


@pytest.fixture(scope="module")
def kin():
    return Kinematics(load_model())


@pytest.fixture(scope="module")
def all_points(kin):
    return kin.point_set([(s.name, n) for s in kin.model.segments for n in s.points])


def _random_state(seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.2, 1.2, 13), rng.normal(size=13), rng.normal(size=13)


def test_model_has_13_named_coordinates_and_7_segments(kin):
    assert kin.n_coordinates == 13
    assert kin.model.segment_names == ("thorax", "clavicle", "scapula", "humerus", "ulna", "radius", "hand")
    assert len(set(kin.model.coordinate_names)) == 13


def test_reference_posture_places_points_at_their_reference_coordinates(kin, all_points):
    # q = 0: every segment frame is parallel to the thorax, so global = origin + local
    r = kin.points(np.zeros(13), all_points)
    humerus = kin.model.segment("humerus")
    i = all_points.names.index("EJC")
    # EJC is 326 mm below GH (Winter's upper-arm length for H = 1.75 m)
    assert np.linalg.norm(r[i] - kin.points(np.zeros(13), kin.point_set([("humerus", "GH")]))[0]) == pytest.approx(0.326, abs=1e-3)
    assert humerus.points["GH"] == pytest.approx(np.zeros(3))


def test_rotations_are_orthonormal(kin):
    q, _, _ = _random_state(0)
    R, _ = kin.poses(q)
    for Ri in R:
        assert np.allclose(Ri @ Ri.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(Ri) == pytest.approx(1.0)


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_point_jacobian_matches_finite_differences(kin, all_points, seed):
    q, _, _ = _random_state(seed)
    J = kin.point_jacobian(q, all_points)
    E = np.eye(13)
    Jn = np.stack([(kin.points(q + H * E[j], all_points) - kin.points(q - H * E[j], all_points)) / (2 * H) for j in range(13)], -1)
    assert np.abs(J - Jn).max() < 1e-8


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_constraint_jacobian_matches_finite_differences(kin, seed):
    q, _, _ = _random_state(seed)
    E = np.eye(13)
    Gn = np.stack([(kin.g(q + H * E[j]) - kin.g(q - H * E[j])) / (2 * H) for j in range(13)], -1)
    assert np.abs(kin.G(q) - Gn).max() < 1e-7


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_bias_acceleration_and_eta_match_second_differences(kin, all_points, seed):
    q, qd, qdd = _random_state(seed)
    bias = kin.point_bias_acceleration(q, qd, all_points)
    Jd = (kin.point_jacobian(q + H * qd, all_points) - kin.point_jacobian(q - H * qd, all_points)) / (2 * H)
    assert np.abs(bias - np.einsum("kcm,m->kc", Jd, qd)).max() < 1e-7
    t = 1e-4
    g = [kin.g(q + qd * s + 0.5 * qdd * s * s) for s in (-t, 0.0, t)]
    gdd = (g[0] - 2 * g[1] + g[2]) / t**2
    assert np.abs(gdd - (kin.G(q) @ qdd + kin.eta(q, qd))).max() < 1e-5 * max(1.0, np.abs(gdd).max())


def test_batched_evaluation_equals_frame_by_frame(kin, all_points):
    rng = np.random.default_rng(7)
    qs = rng.uniform(-1, 1, (6, 13))
    batch = kin.points(qs, all_points)
    single = np.stack([kin.points(q, all_points) for q in qs])
    assert np.abs(batch - single).max() < 1e-15
    assert np.abs(kin.G(qs) - np.stack([kin.G(q) for q in qs])).max() < 1e-14


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_coordinates_recovered_from_segment_rotations(kin, seed):
    q, _, _ = _random_state(seed)
    R, _ = kin.poses(q)
    assert np.abs(kin.coordinates_from_rotations(R) - q).max() < 1e-12


def test_coordinates_recovered_at_gimbal_lock(kin):
    q, _, _ = _random_state(3)
    q[7] = np.pi / 2  # GH middle angle at the singularity
    R, _ = kin.poses(q)
    q_rec = kin.coordinates_from_rotations(R, q_previous=q)
    R_rec, _ = kin.poses(q_rec)
    assert np.abs(R_rec - R).max() < 1e-9  # same posture
    assert abs(q_rec[6] - q[6]) < 1e-12  # first angle held at the previous value


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_coordinate_rates_from_angular_velocity_and_acceleration(kin, seed):
    q, qd, qdd = _random_state(seed)
    t = 1e-5
    omega = kin.segment_angular_velocities(q, qd)
    alpha = (kin.segment_angular_velocities(q + qd * t + 0.5 * qdd * t * t, qd + qdd * t)
             - kin.segment_angular_velocities(q - qd * t + 0.5 * qdd * t * t, qd - qdd * t)) / (2 * t)
    qd_rec, qdd_rec = kin.coordinate_rates(q, omega, alpha)
    assert np.abs(qd_rec - qd).max() < 1e-10
    assert np.abs(qdd_rec - qdd).max() < 1e-6


def test_axis_rotation_is_rodrigues():
    a = np.array([1.0, 2.0, 2.0]) / 3.0
    R = axis_rotation(a, np.array(0.7))
    assert R @ a == pytest.approx(a)
    assert np.trace(R) == pytest.approx(1 + 2 * np.cos(0.7))
