"""Inverse dynamics (exubio.dynamics): the same q, q', q'' through exubio, biorbd (RBDL's
InverseDynamics on the exported .bioMod) and OpenSim (Simbody's InverseDynamicsSolver, the engine
of its ID tool, on the exported .osim) give the same generalized forces (1e-6 N m) on the open
chain with exubio's inertia exported; the two sums of exubio's own Newton-Euler agree; a static
posture gives the textbook moment of the weights; the Dumas et al. 2007 inertia is the table's;
the girdle's contact split is the one its docstring states."""
import locale

import numpy as np
import pytest

from exubio.dynamics.inertia import DUMAS_2007_MALE, dynamics_model, isb_segment_frames
from exubio.dynamics.moments import joint_moments
from exubio.dynamics.newton_euler import GRAVITY_M_S2, girdle_split, inverse_dynamics
from exubio.errors import ModelError
from exubio.export import write_biomod, write_osim
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model

TOL_NM = 1e-6


@pytest.fixture(autouse=True)
def _keep_the_locale():
    before = locale.setlocale(locale.LC_ALL)  # biorbd.Model() sets LC_ALL=C (see tests/export/test_export.py)
    yield
    locale.setlocale(locale.LC_ALL, before)


@pytest.fixture(scope="module")
def dyn():
    return dynamics_model(load_model(body_mass_kg=70.0), hand_load_kg=2.0)


def states(model, n=8, seed=1, speed=4.0, acc=300.0):
    """Random postures inside the ranges (a half turn each way where unbounded) with fast rates (rad/s)
    and large accelerations (rad/s^2)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.clip(model.coordinate_ranges_rad.T, -np.pi, np.pi)
    m = model.n_coordinates
    return rng.uniform(lo, hi, (n, m)), rng.normal(0, speed, (n, m)), rng.normal(0, acc, (n, m))


def test_generalized_forces_match_biorbd(dyn, tmp_path):
    biorbd = pytest.importorskip("biorbd")
    q, qd, qdd = states(dyn)
    tau = inverse_dynamics(Kinematics(dyn), q, qd, qdd).tau
    bio = biorbd.Model(str(write_biomod(dyn, tmp_path / "dyn.bioMod")))
    ref = np.array([bio.InverseDynamics(a, b, c).to_array() for a, b, c in zip(q, qd, qdd)])
    assert np.abs(tau).max() > 10.0, "the test states load the joints"
    np.testing.assert_allclose(tau, ref, rtol=0, atol=TOL_NM)
    # gravity alone (static postures): the same
    zero = np.zeros_like(q)
    ref0 = np.array([bio.InverseDynamics(a, z, z).to_array() for a, z in zip(q, zero)])
    np.testing.assert_allclose(inverse_dynamics(Kinematics(dyn), q, zero, zero).tau, ref0, rtol=0, atol=TOL_NM)


def test_generalized_forces_match_opensim(dyn, tmp_path):
    opensim = pytest.importorskip("opensim")
    q, qd, qdd = states(dyn, seed=2)
    tau = inverse_dynamics(Kinematics(dyn), q, qd, qdd).tau
    osim = opensim.Model(str(write_osim(dyn, tmp_path / "dyn.osim", coordinates="model", thorax="weld")))
    state = osim.initSystem()
    coords = osim.getCoordinateSet()
    assert [coords.get(i).getName() for i in range(coords.getSize())] == list(dyn.coordinate_names)
    solver = opensim.InverseDynamicsSolver(osim)
    for i in range(len(q)):
        for j, name in enumerate(dyn.coordinate_names):
            coords.get(name).setValue(state, float(q[i, j]), False)
            coords.get(name).setSpeedValue(state, float(qd[i, j]))
        osim.realizeVelocity(state)
        udot = opensim.Vector(dyn.n_coordinates, 0.0)
        for j in range(dyn.n_coordinates):
            udot.set(j, float(qdd[i, j]))
        got = solver.solve(state, udot)
        np.testing.assert_allclose([got.get(j) for j in range(dyn.n_coordinates)], tau[i], rtol=0, atol=TOL_NM)


def test_joint_moments_and_virtual_work_agree(dyn):
    """tau_j = a_j . M_joint (the subtree sums) equals sum_s J_cs^T F_s + J_ws^T N_s computed here
    from finite differences of exubio's forward kinematics (velocities and accelerations of the
    centres of mass and the rotations), an independent route."""
    kin = Kinematics(dyn)
    q, qd, qdd = states(dyn, n=3, seed=3)
    tau = inverse_dynamics(kin, q, qd, qdd).tau
    coms = kin.point_set([(s.name, s.com_m) for s in dyn.segments])
    h = 1e-4
    mass = np.array([s.mass_kg for s in dyn.segments])
    for i in range(len(q)):
        def at(t, i=i):  # the motion q(t) = q + qd t + qdd t^2 / 2 around t = 0
            return q[i] + qd[i] * t + 0.5 * qdd[i] * t * t
        c = [kin.points(at(t), coms) for t in (-h, 0.0, h)]
        a = (c[2] - 2 * c[1] + c[0]) / h ** 2
        R = [kin.poses(at(t))[0] for t in (-2 * h, -h, 0.0, h, 2 * h)]
        Rdot = [(R[k + 1] - R[k - 1]) / (2 * h) for k in (1, 2, 3)]

        def vee(W):
            return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)
        w = [vee(Rd @ np.swapaxes(Rk, -1, -2)) for Rd, Rk in zip(Rdot, R[1:4])]
        alpha = (w[2] - w[0]) / (2 * h)
        I = R[2] @ np.array([s.inertia_kgm2 for s in dyn.segments]) @ np.swapaxes(R[2], -1, -2)
        F = mass[:, None] * (a - GRAVITY_M_S2)
        N = np.einsum("sij,sj->si", I, alpha) + np.cross(w[1], np.einsum("sij,sj->si", I, w[1]))
        J = kin.point_jacobian(q[i], coms)
        fr = kin.frames(q[i])
        Jw = np.swapaxes(fr.axes[None] * kin.affects[..., None], -1, -2)  # (S, 3, m)
        virtual = np.einsum("sim,si->m", J, F) + np.einsum("sim,si->m", Jw, N)
        np.testing.assert_allclose(tau[i], virtual, rtol=0, atol=1e-3 * np.abs(tau[i]).max())


def test_static_gh_moment_is_the_weights_times_their_lever_arms(dyn):
    """Arm abducted 90 deg, held still: the GH moment about the thorax's anterior axis is the
    weight of humerus, forearm, hand and load times their horizontal distance from GH."""
    kin = Kinematics(dyn)
    q = np.zeros(dyn.n_coordinates)
    q[dyn.coordinate_names.index("gh_abduction")] = np.pi / 2
    res = inverse_dynamics(kin, q, 0 * q, 0 * q)
    arm = [dyn.segment_index(s) for s in ("humerus", "ulna", "radius", "hand")]
    c = kin.points(q, kin.point_set([(dyn.segments[i].name, dyn.segments[i].com_m) for i in arm]))
    gh = kin.frames(q).p[dyn.segment_index("humerus")]
    m = np.array([dyn.segments[i].mass_kg for i in arm])
    expected = np.cross(c - gh, m[:, None] * -GRAVITY_M_S2).sum(axis=0)  # what the scapula must apply
    np.testing.assert_allclose(res.joint_moment[0, dyn.segment_index("humerus")], expected, rtol=1e-12, atol=1e-12)
    lever = (c[:, 2] - gh[2])  # the arm points right (+Z): moment about X = -sum m g z
    assert expected[0] == pytest.approx(-(m * 9.80665 * lever).sum(), rel=1e-9)
    assert 10.0 < -expected[0] < 25.0, "70 kg subject, 2 kg in the hand, arm horizontal: about 15-20 N m"


def test_dumas_table_scaled_by_the_model(dyn):
    base = load_model(body_mass_kg=70.0)
    frames = isb_segment_frames(base)
    origin, A, length = frames["humerus"]
    hum = dyn.segment("humerus")
    assert hum.mass_kg == pytest.approx(0.024 * 70.0)
    com_global = hum.com_m + origin  # the humerus frame sits at GH, parallel to the thorax at q = 0
    np.testing.assert_allclose(A.T @ (com_global - origin) / length, np.array(DUMAS_2007_MALE["arm"].com_percent) / 100,
                               atol=1e-12)
    r = DUMAS_2007_MALE["arm"].radii_percent
    local = A.T @ hum.inertia_kgm2 @ A / (hum.mass_kg * length ** 2)
    assert local[0, 0] == pytest.approx((r[0] / 100) ** 2) and local[1, 1] == pytest.approx((r[1] / 100) ** 2)
    assert local[0, 2] == pytest.approx((r[4] / 100) ** 2)
    ulna, radius = dyn.segment("ulna"), dyn.segment("radius")
    assert ulna.mass_kg + radius.mass_kg == pytest.approx(0.017 * 70.0)
    hand = dyn.segment("hand")
    assert hand.mass_kg == pytest.approx(0.006 * 70.0 + 2.0)
    no_load = dynamics_model(base)
    np.testing.assert_array_equal(no_load.segment("hand").com_m, hand.com_m)
    np.testing.assert_array_equal(no_load.segment("hand").inertia_kgm2, hand.inertia_kgm2)
    for seg in ("clavicle", "scapula"):  # not in the table: the model's own
        assert dyn.segment(seg).mass_kg == base.segment(seg).mass_kg
    assert "Dumas" in dyn.metadata["inertia_source"]
    with pytest.raises(ModelError, match="hand-load-kg"):
        dynamics_model(base, hand_load_kg=-1.0)


def test_girdle_split_gives_the_contact_what_it_can_carry(dyn):
    kin = Kinematics(dyn)
    q, qd, qdd = states(dyn, n=4, seed=4)
    tau = inverse_dynamics(kin, q, qd, qdd).tau
    tau_joint, lam, normal = girdle_split(kin, q, tau)
    G = kin.G(q)
    np.testing.assert_allclose(tau_joint + np.einsum("nkm,nk->nm", G, lam), tau, atol=1e-9)
    np.testing.assert_allclose(np.einsum("nkm,nm->nk", G, tau_joint), 0.0, atol=1e-9)  # the rest is orthogonal
    arm = kin.coordinate_segment >= dyn.segment_index("humerus")
    np.testing.assert_array_equal(tau_joint[:, arm], tau[:, arm])
    # a load that is exactly a contact push: all of it goes to the contact, none to SC/AC
    lam0 = np.array([[3.0, -2.0]] * len(q))
    tj, lam1, nf = girdle_split(kin, q, np.einsum("nkm,nk->nm", G, lam0))
    np.testing.assert_allclose(lam1, lam0, atol=1e-9)
    np.testing.assert_allclose(tj, 0.0, atol=1e-9)
    e = kin.points(q, kin.contacts) - kin.centre
    np.testing.assert_allclose(nf, 2 * lam0 * np.linalg.norm(e * kin.a_diag, axis=-1))


def test_moment_table_columns(dyn):
    base = load_model(body_mass_kg=70.0)
    q, qd, qdd = states(base, n=5, seed=5)
    table = joint_moments(base, q, qd, qdd, hand_load_kg=2.0)
    tau = inverse_dynamics(Kinematics(dyn), q, qd, qdd).tau
    names = list(base.coordinate_names)
    np.testing.assert_allclose(table.column("elbow_flexion_moment_Nm"), tau[:, names.index("elbow_flexion")])
    np.testing.assert_allclose(table.column("GH_X_moment_Nm_per_kg"), table.column("GH_X_moment_Nm") / 70.0)
    for j, name in enumerate(names):
        np.testing.assert_allclose(table.column(f"{name}_generalized_force_Nm"), tau[:, j])
    # the GH moment's size is the joint moment's, whatever frame it is written in
    res = inverse_dynamics(Kinematics(dyn), q, qd, qdd)
    gh = np.stack([table.column(f"GH_{a}_moment_Nm") for a in "XYZ"], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(gh, axis=-1),
                               np.linalg.norm(res.joint_moment[:, dyn.segment_index("humerus")], axis=-1))
    assert {"TS_contact_normal_N", "AI_contact_normal_N", "sc_elevation_joint_torque_Nm"} <= set(table.columns)
    assert table.peaks()["GH_X_moment_Nm"] == pytest.approx(np.abs(table.column("GH_X_moment_Nm")).max())
