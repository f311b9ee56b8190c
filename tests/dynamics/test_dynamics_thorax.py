"""Joint moments of an arm on a moving thorax (issue 36 item 2): a simulated trunk leaning 20 deg
during a raise, 70 kg, 2 kg in the hand. The exact moments with the thorax's exact motion agree with
biorbd's inverse dynamics of a model whose thorax is a free-floating (6-DOF) root fed the same
motion (an independent implementation); leaving the thorax's motion out is measurably wrong; the
thorax's motion measured from its four markers (same filter and splines as the markers) equals the
exact one on noise-free markers; a noise-free LS reconstruction with it gives moments within 1 % of
their peak; a trial without thorax markers says the thorax is assumed still."""
import numpy as np
import pytest

import exubio
from exubio.dynamics.inertia import dynamics_model
from exubio.dynamics.moments import THORAX_STILL, joint_moments
from exubio.dynamics.thorax_motion import thorax_angles
from exubio.export.biomod import biomod_text
from exubio.model.angles import euler_angles
from exubio.model.load import load_model
from exubio.prep.thorax_motion import measure_thorax_motion
from exubio.synth.simulate import simulate_trial
from exubio.synth.thorax_lean import ThoraxLean

MASS, LOAD = 70.0, 2.0
MOMENTS = ("GH_X_moment_Nm", "GH_Y_moment_Nm", "GH_Z_moment_Nm", "elbow_flexion_moment_Nm",
           "forearm_pronation_moment_Nm", "wrist_flexion_moment_Nm", "wrist_radial_deviation_moment_Nm")


@pytest.fixture(scope="module")
def model():
    return load_model(body_mass_kg=MASS)


@pytest.fixture(scope="module")
def lean(model):
    return simulate_trial(model, "abduction", duration_s=5.0, rate_hz=100, thorax_lean=ThoraxLean(20.0))


def _root_states(motion):
    """biorbd's free root (translations xyz, then rotations xyz, body-fixed) from the thorax's lab
    motion: q = (origin, intrinsic X-Y-Z angles), their rates from w = E(a, b) (a', b', c') with
    E = [e_x, Rx(a) e_y, Rx(a) Ry(b) e_z] and their accelerations from w' = E q'' + E' q'."""
    ang = euler_angles(motion.rotation, "XYZ")
    out = []
    for k in range(ang.shape[0]):
        a, b, _ = ang[k]
        ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
        Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
        Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
        e1, e2, e3 = np.eye(3)[0], Rx @ np.eye(3)[1], Rx @ Ry @ np.eye(3)[2]
        E = np.column_stack([e1, e2, e3])
        rate = np.linalg.solve(E, motion.angular_velocity_rad_s[k])
        w12 = rate[0] * e1 + rate[1] * e2
        Ed = np.column_stack([np.zeros(3), rate[0] * np.cross(e1, e2), np.cross(w12, e3)])
        acc = np.linalg.solve(E, motion.angular_acceleration_rad_s2[k] - Ed @ rate)
        out.append((np.r_[motion.origin_m[k], ang[k]], np.r_[motion.velocity_m_s[k], rate],
                    np.r_[motion.acceleration_m_s2[k], acc]))
    return out


def test_exact_thorax_motion_agrees_with_biorbd_free_root(tmp_path, model, lean):
    biorbd = pytest.importorskip("biorbd")
    text = biomod_text(dynamics_model(model, hand_load_kg=LOAD))
    assert "gravity 0 -9.80665 0" in text and "segment thorax\n" in text
    text = text.replace("gravity 0 -9.80665 0", "gravity 0 0 -9.80665")  # the simulated lab: Z up
    text = text.replace("segment thorax\n", "segment thorax\n\ttranslations xyz\n\trotations xyz\n", 1)
    path = tmp_path / "free.bioMod"
    path.write_text(text, encoding="utf-8")
    bio = biorbd.Model(str(path))
    assert bio.nbQ() == 6 + len(model.coordinate_names)
    frames = range(0, lean.time_s.size, 7)
    root = _root_states(lean.thorax_motion)
    ref = np.array([bio.InverseDynamics(np.r_[root[k][0], lean.q_true[k]], np.r_[root[k][1], lean.qd_true[k]],
                                        np.r_[root[k][2], lean.qdd_true[k]]).to_array()[6:] for k in frames])
    got = joint_moments(model, lean.q_true, lean.qd_true, lean.qdd_true, hand_load_kg=LOAD, thorax=lean.thorax_motion)
    tau = np.column_stack([got.column(f"{n}_generalized_force_Nm") for n in model.coordinate_names])[list(frames)]
    np.testing.assert_allclose(tau, ref, rtol=0, atol=1e-6)
    # and the thorax-fixed answer is not biorbd's: the lean matters
    still = joint_moments(model, lean.q_true, lean.qd_true, lean.qdd_true, hand_load_kg=LOAD)
    tau_still = np.column_stack([still.column(f"{n}_generalized_force_Nm") for n in model.coordinate_names])
    assert np.abs(tau_still[list(frames)] - ref).max() > 1.0


def test_leaving_the_lean_out_is_wrong_by_a_measurable_share(model, lean):
    truth = joint_moments(model, lean.q_true, lean.qd_true, lean.qdd_true, hand_load_kg=LOAD, thorax=lean.thorax_motion)
    still = joint_moments(model, lean.q_true, lean.qd_true, lean.qdd_true, hand_load_kg=LOAD)
    share = {c: np.abs(still.column(c) - truth.column(c)).max() / np.abs(truth.column(c)).max() for c in MOMENTS}
    assert share["GH_X_moment_Nm"] > 0.10 and share["elbow_flexion_moment_Nm"] > 0.30, share
    assert "included" in truth.info["thorax"] and still.info["thorax"] == THORAX_STILL


def test_thorax_motion_from_noise_free_markers_is_the_exact_one(model, lean):
    measured = measure_thorax_motion(lean.trajectories, exubio.load_protocol(model=model))
    exact = lean.thorax_motion
    np.testing.assert_allclose(measured.rotation, exact.rotation, atol=1e-6)
    np.testing.assert_allclose(measured.origin_m, exact.origin_m, atol=1e-6)
    for name, rel in (("angular_velocity_rad_s", 1e-4), ("angular_acceleration_rad_s2", 2e-3),
                      ("acceleration_m_s2", 2e-3)):
        got, want = getattr(measured, name), getattr(exact, name)
        assert np.abs(got - want).max() < rel * np.abs(want).max(), name
    np.testing.assert_allclose(measured.gravity_m_s2, [0.0, 0.0, -9.80665])
    # the ISB thorax-to-lab angles: 20 deg of lateral flexion at the top of the raise, nothing else
    ang = np.degrees(thorax_angles(measured))
    assert ang[:, 1].max() == pytest.approx(20.0, abs=1e-3)
    assert np.abs(ang[:, [0, 2]]).max() < 1e-3


def test_noise_free_ls_with_the_measured_thorax_within_1_percent(model, lean):
    truth = joint_moments(model, lean.q_true, lean.qd_true, lean.qdd_true, hand_load_kg=LOAD, thorax=lean.thorax_motion)
    protocol = exubio.load_protocol(model=model)
    rec = exubio.reconstruct(lean.trajectories, model, protocol, method="ls")
    measured = measure_thorax_motion(lean.trajectories, protocol)
    got = joint_moments(model, rec.q_rad, rec.qd_rad_s, rec.qdd_rad_s2, hand_load_kg=LOAD, thorax=measured)
    share = {c: np.abs(got.column(c) - truth.column(c)).max() / np.abs(truth.column(c)).max() for c in MOMENTS}
    assert max(share.values()) < 0.01, share
    df = exubio.moments(rec, model, hand_load_kg=LOAD, thorax=measured)  # the API: the same table
    np.testing.assert_allclose(df["GH_X_moment_Nm"].to_numpy(), got.column("GH_X_moment_Nm"), rtol=0, atol=1e-12)
    assert "included" in df.attrs["thorax"]


def test_a_trial_without_thorax_markers_assumes_the_thorax_still(model):
    import dataclasses

    from exubio.types import ThoraxFrameSpec

    protocol = dataclasses.replace(exubio.load_protocol(model=model), thorax_frame=ThoraxFrameSpec())
    trial = simulate_trial(model, "abduction", duration_s=0.5, lab_transform=False)
    assert measure_thorax_motion(trial.trajectories, protocol) is None
