"""The Exudyn PF system against the numpy kinematics: same model points for any posture, and exact
marker data tracked back to the motion that made them."""
import numpy as np
import pytest

pytest.importorskip("exudyn")

from exubio.backend.exudyn_system import IntegratorOptions, PFSystem, SpringSet  # noqa: E402
from exubio.errors import ModelError  # noqa: E402
from exubio.kinematics import Kinematics  # noqa: E402
from exubio.model import load_model  # noqa: E402

RATE_HZ = 200.0
JOINT_CENTRES = {"SC", "AC", "GH", "EJC", "RH", "WJC"}


@pytest.fixture(scope="module")
def kin():
    return Kinematics(load_model())


@pytest.fixture(scope="module")
def points(kin):
    """Every named non-joint-centre point of the movable segments (29 model points)."""
    return kin.point_set([(s.name, p) for s in kin.model.segments[1:] for p in s.points if p not in JOINT_CENTRES])


@pytest.fixture(scope="module")
def springs(points):
    return SpringSet.from_points(points, stiffness_n_per_m=1500.0, damping_ns_per_m=300.0)


def exact_motion(kin, n, *, seed=0):
    """Smooth q(t) on the constraint manifold: 11 coordinates are sines, the AC protraction and
    upward rotation are solved per frame so that g = 0, and q̇ satisfies G q̇ = 0 exactly."""
    rng = np.random.default_rng(seed)
    m = kin.n_coordinates
    t = np.arange(n) / RATE_HZ
    amp, freq, phase = rng.uniform(0.05, 0.5, m), rng.uniform(0.2, 0.6, m), rng.uniform(0, 2 * np.pi, m)
    arg = 2 * np.pi * freq * t[:, None] + phase
    q = rng.uniform(-0.2, 0.2, m) + amp * np.sin(arg)
    qd = amp * 2 * np.pi * freq * np.cos(arg)
    dep = [3, 4]
    ind = [j for j in range(m) if j not in dep]
    x = q[0, dep].copy()
    for i in range(n):
        for _ in range(50):
            q[i, dep] = x
            g = kin.g(q[i])
            if np.abs(g).max() < 1e-14:
                break
            x = x - np.linalg.solve(kin.G(q[i])[:, dep], g)
        q[i, dep] = x
        G = kin.G(q[i])
        qd[i, dep] = -np.linalg.solve(G[:, dep], G[:, ind] @ qd[i, ind])
    return q, qd


@pytest.fixture(scope="module")
def motion(kin, points):
    q, qd = exact_motion(kin, 300)
    pos = kin.points(q, points)
    vel = np.einsum("nkcm,nm->nkc", kin.point_jacobian(q, points), qd)
    return q, qd, pos, vel


@pytest.fixture(scope="module")
def tracked(kin, springs, motion):
    q, qd, pos, vel = motion
    system = PFSystem(kin.model, springs, q0=q[0], qd0=qd[0], kinematics=kin)
    return system, system.run(pos, vel, frame_dt_s=1 / RATE_HZ)


def test_exudyn_model_points_equal_numpy_kinematics_for_random_postures(kin, springs, points):
    system = PFSystem(kin.model, springs, q0=np.zeros(13), kinematics=kin)
    rng = np.random.default_rng(7)
    for q in rng.uniform(-1.5, 1.5, (6, 13)):
        assert np.abs(system.model_points(q) - kin.points(q, points)).max() < 1e-9


def test_exact_data_is_tracked_to_the_motion_that_made_it(kin, points, motion, tracked):
    q, qd, pos, _ = motion
    _, run = tracked
    assert run.success and run.completed_frames == len(q), run.message
    assert run.rotations.shape == (len(q), 7, 3, 3) and run.angular_accelerations_rad_s2.shape == (len(q), 7, 3)
    q_pf = kin.coordinates_from_rotations(run.rotations)
    assert np.abs(q_pf[0] - q[0]).max() < 1e-9  # the run starts exactly at q0
    residual = np.linalg.norm(kin.points(q_pf, points) - pos, axis=2)
    assert residual.mean() < 0.2e-3 and residual.max() < 1e-3  # inertial lag only (m a / c)
    assert np.degrees(np.abs(q_pf - q)).max() < 0.5
    assert np.abs(kin.g(q_pf)).max() < 1e-6
    # the native joints hold: Exudyn's poses are the numpy poses of the recovered coordinates
    R, p = kin.poses(q_pf)
    assert np.abs(R - run.rotations).max() < 1e-6 and np.abs(p - run.origins_m).max() < 1e-6
    qd_pf, qdd_pf = kin.coordinate_rates(q_pf, run.angular_velocities_rad_s, run.angular_accelerations_rad_s2)
    assert np.abs(qd_pf[0] - qd[0]).max() < 1e-6  # initial velocities from qd0
    assert np.abs(qd_pf - qd).max() < 0.05
    assert np.all(np.isfinite(qdd_pf))


def test_run_reports_solver_statistics(tracked):
    _, run = tracked
    assert run.steps == run.n_frames - 1
    assert run.newton_iterations >= run.steps and run.jacobian_updates >= 1
    assert run.solver_times_s["total"] > 0 and run.wall_time_s > 0


def test_model_points_query_does_not_move_the_start_of_a_run(kin, springs, motion, tracked):
    q, qd, pos, vel = motion
    system, first = tracked
    system.model_points(np.full(13, 0.3))
    again = system.run(pos[:50], vel[:50], frame_dt_s=1 / RATE_HZ)
    assert np.abs(again.rotations - first.rotations[:50]).max() < 1e-12


def test_a_missing_marker_switches_its_spring_off(kin, springs, motion):
    q, qd, pos, vel = motion
    n = 120
    active = np.ones((n, springs.n_springs), dtype=bool)
    active[30:80, 5] = False
    active[60:70, 20] = False
    runs = []
    for garbage in (np.nan, 0.1):
        p, v = pos[:n].copy(), vel[:n].copy()
        p[~active] = garbage
        v[~active] = garbage
        system = PFSystem(kin.model, springs, q0=q[0], qd0=qd[0], kinematics=kin)
        runs.append(system.run(p, v, active, frame_dt_s=1 / RATE_HZ))
    assert all(r.success for r in runs)
    assert np.array_equal(runs[0].rotations, runs[1].rotations)  # the gap's values do not act
    q_pf = kin.coordinates_from_rotations(runs[0].rotations)
    assert np.degrees(np.abs(q_pf - q[:n])).max() < 0.5


def test_sub_steps_interpolate_between_frames(kin, springs, motion, tracked):
    q, qd, pos, vel = motion
    n = 100
    system = PFSystem(kin.model, springs, q0=q[0], qd0=qd[0], kinematics=kin)
    run = system.run(pos[:n], vel[:n], frame_dt_s=1 / RATE_HZ, options=IntegratorOptions(step_s=0.5 / RATE_HZ))
    assert run.success and run.steps == 2 * (n - 1)
    one_step = kin.coordinates_from_rotations(tracked[1].rotations[:n])
    assert np.degrees(np.abs(kin.coordinates_from_rotations(run.rotations) - one_step)).max() < 0.05


def test_gravity_pulls_the_arm_down(kin, springs, motion):
    q, qd, pos, vel = motion
    n = 60
    system = PFSystem(kin.model, springs, q0=q[0], qd0=qd[0], gravity=True, kinematics=kin)
    run = system.run(pos[:n], vel[:n], frame_dt_s=1 / RATE_HZ)
    hand = kin.model.segment_index("hand")
    assert run.success
    assert run.origins_m[-1, hand, 1] < kin.poses(q[n - 1])[1][hand, 1] - 1e-4


def test_bad_arguments_are_rejected(kin, springs, motion):
    q, qd, pos, vel = motion
    system = PFSystem(kin.model, springs, q0=q[0], qd0=qd[0], kinematics=kin)
    with pytest.raises(ValueError, match="targets_pos"):
        system.run(pos[:10, :3], vel[:10, :3], frame_dt_s=0.005)
    with pytest.raises(ValueError, match="active but not finite"):
        p = pos[:10].copy()
        p[4, 2] = np.nan
        system.run(p, vel[:10], frame_dt_s=0.005)
    with pytest.raises(ValueError, match="integer"):
        system.run(pos[:10], vel[:10], frame_dt_s=0.005, options=IntegratorOptions(step_s=0.003))
    with pytest.raises(ModelError, match="movable segments"):
        PFSystem(kin.model, SpringSet([0], [[0.0, 0.0, 0.0]], 1500.0, 300.0), q0=np.zeros(13), kinematics=kin)
    with pytest.raises(ValueError, match="local_m"):
        SpringSet([1, 2], [[0.0, 0.0, 0.0]], 1500.0, 300.0)


def test_a_diverging_run_is_reported_not_raised(kin, motion):
    q, qd, pos, vel = motion
    points = kin.point_set([("hand", "MCP2"), ("humerus", "DELT"), ("scapula", "AA")])
    target = kin.points(q[:40], points)
    target[20:] += 5.0
    system = PFSystem(kin.model, SpringSet.from_points(points, stiffness_n_per_m=1e9, damping_ns_per_m=300.0),
                      q0=q[0], qd0=qd[0], kinematics=kin)
    run = system.run(target, np.zeros_like(target), frame_dt_s=1 / RATE_HZ,
                     options=IntegratorOptions(max_newton_iterations=2, adaptive_step=False, newton_relative_tolerance=1e-12))
    assert not run.success and run.message
    assert 0 < run.completed_frames < 40
    assert np.isnan(run.rotations[run.completed_frames:]).all()
    assert np.isfinite(run.rotations[: run.completed_frames]).all()
