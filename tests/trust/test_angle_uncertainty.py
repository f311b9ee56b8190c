"""Every angle's standard uncertainty (exubio.trust.angle_uncertainty): the first-order propagation
holds against the least-squares solver itself (Monte Carlo), the bound and the gimbal margin set the
status, the truth lies within +-2u on a simulation with the bone-pin artefact, and every output
carries it."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import exubio
from exubio.protocol.bind import tracked_points
from exubio.methods.ls import reconstruct_ls
from exubio.protocol.bind import held_mask
from exubio.model.angles import anatomical_table, segment_anatomical_rotations
from exubio.model.kinematics import Kinematics
from exubio.synth.simulate import simulate_trial
from exubio.trust import angle_uncertainty as AU
from exubio.protocol.bind import bind
from exubio.trust.observability import AngleStatus, angle_determinacy
from exubio.trust.sta_amplitude import shipped_amplitude
from exubio.types import MarkerTargets


def test_the_gimbal_margin_marks_first_and_third_angles_only():
    a = np.zeros((3, 22))
    a[0, 10] = np.radians(-10)  # GH Y-X'-Y'' elevation 10 deg: locked
    a[1, 10] = np.radians(-60)  # 60 deg: defined
    a[2, 13] = np.radians(80)   # Phadke X-Z'-Y'' flexion 80 deg: its Cardan lock
    a[:, 16] = np.radians(-90)  # HT elevation 90 deg: defined
    g = AU.gimbal_mask(a)
    assert g[0, 9] and g[0, 11] and not g[0, 10]
    assert not g[1, 9] and not g[1, 11]
    assert g[2, 12] and g[2, 14] and not g[2, 13]
    assert not g[:, 15].any() and not g[:, 18:].any()


def test_st_at_zero_is_not_near_its_lock():
    g = AU.gimbal_mask(np.zeros((1, 22)))
    assert not g[0, 6] and not g[0, 8]  # ST Y-X'-Z'' at 0: far from +-90
    assert g[0, 9] and g[0, 11]  # GH Y-X'-Y'' at 0 elevation: locked
    assert g[0, 15] and g[0, 17]  # HT Y-X'-Y'': the arm at the side


@pytest.fixture(scope="module")
def setting():
    model = exubio.load_model()
    protocol = exubio.load_protocol(model=model)
    kin = Kinematics(model)
    return model, protocol, kin, tracked_points(kin, protocol)


def test_the_propagated_uncertainty_is_what_the_solver_does_with_such_errors(setting):
    """Marker errors drawn from the stated covariance (1 mm noise, the bone-pin artefact at HT 54 deg
    of abduction), solved by exubio's own least squares frame by frame: the angles' spread equals the
    propagated u within the Monte-Carlo error (300 draws: +-8 % at 95 %) and the linearisation's."""
    model, protocol, kin, pts = setting
    from exubio.synth.simulate import reference_postures

    q0 = reference_postures(model)[3]  # abduction, HT 54 deg
    held = held_mask(model, protocol)
    excluded = bind(model, protocol).not_solved
    free = np.flatnonzero(~excluded)
    present = np.ones((1, len(protocol.markers)), dtype=bool)
    frames = segment_anatomical_rotations(model, q0[None], kinematics=kin)
    sigma = AU.marker_covariance(kin, pts, q0[None], present, shipped_amplitude(),
                                 anatomical={s: frames[s] for s in ("scapula", "humerus")})[0]
    skin_only = dataclasses.replace(shipped_amplitude(), girdle=None)  # the girdle's part: its own test below
    det = angle_determinacy(kin, pts, q0[None], present, protocol.weights, held=held, locked=excluded & ~held,
                            amplitude=skin_only)
    rng = np.random.default_rng(7)
    n = 300
    L = np.linalg.cholesky(sigma + 1e-14 * np.eye(sigma.shape[0]))
    draws = (L @ rng.standard_normal((sigma.shape[0], n))).T.reshape(n, -1, 3)
    P = kin.points(np.repeat(q0[None], n, axis=0), pts) + draws
    targets = MarkerTargets(np.arange(n) * 0.01, protocol.marker_names, P, np.zeros_like(P), np.zeros_like(P))
    rec = reconstruct_ls(model, protocol, targets)
    names, ang = anatomical_table(model, rec.q_rad, unwrap=False)
    _, ref = anatomical_table(model, q0)
    spread = np.degrees(np.std(np.angle(np.exp(1j * (ang - ref))), axis=0))
    u = np.degrees(det.uncertainty_rad[0])
    assert free.size > 0
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
                 "GH_phadke_Z_flexion", "HT_X_elevation", "elbow_flexion"):
        j = names.index(name)
        assert spread[j] == pytest.approx(u[j], rel=0.2), (name, spread[j], u[j])


def test_the_girdle_term_is_the_spread_of_the_angles_of_frames_turned_by_it(setting):
    """At HT 54 deg of abduction. (1) The model's scapula and humerus frames turned by random rotation
    vectors (their own axes) drawn from the positive part of the shipped girdle matrix times theta^2:
    the spread of the ST, GH and HT angles (the frames' own decomposition, not exubio's) equals
    girdle_angle_variance within the Monte-Carlo error (2000 draws: +-3 % at 95 %) and the
    linearisation's; the SC angles, whose frames do not turn, get nothing. (2) The shipped matrix,
    not positive definite (the skin takes back part of the girdle's error): each angle gets e C e^T
    (theta + theta_0)^2 with e from the frames turned by small rotations (scipy), or zero where that is
    negative, and both cases occur; with no offset, (theta / (theta + theta_0))^2 of that. (3) A model
    without a girdle gives zero."""
    model, protocol, kin, pts = setting
    from scipy.spatial.transform import Rotation

    from exubio.model.angles import ANATOMICAL_COLUMNS, angles_of_frames
    from exubio.synth.simulate import reference_postures

    def table(fr):
        sets = angles_of_frames(fr)
        return np.concatenate([sets[k] for k in sets], axis=-1)

    amp = shipped_amplitude()
    assert amp.girdle is not None and np.linalg.eigvalsh(amp.girdle)[0] < 0
    q0 = reference_postures(model)[3]
    frames = segment_anatomical_rotations(model, q0[None], kinematics=kin)
    R, _ = kin.poses(q0[None])
    theta = AU._driver([s.name for s in model.segments], R)[0]
    assert np.degrees(theta) > 30
    assert np.degrees(amp.girdle_offset_rad) >= 5  # the shipped offset (exubio.truth.girdle)
    drv = theta + amp.girdle_offset_rad
    base = table(frames)[0]
    w, V = np.linalg.eigh(amp.girdle)
    positive = dataclasses.replace(amp, girdle=(V * np.maximum(w, 0.0)) @ V.T)
    var = AU.girdle_angle_variance(kin, q0[None], positive, 22)[0]
    n = 2000
    xi = np.random.default_rng(3).multivariate_normal(np.zeros(6), positive.girdle * drv ** 2, size=n)
    turned = {s: np.repeat(F, n, axis=0) for s, F in frames.items()}
    turned["scapula"] = turned["scapula"] @ Rotation.from_rotvec(xi[:, :3]).as_matrix()
    turned["humerus"] = turned["humerus"] @ Rotation.from_rotvec(xi[:, 3:]).as_matrix()
    spread = np.std(np.angle(np.exp(1j * (table(turned) - base))), axis=0)
    for j, name in enumerate(ANATOMICAL_COLUMNS[:18]):
        if name.startswith(("ST_", "GH_phadke", "HT_X", "GH_X")):
            assert np.sqrt(var[j]) == pytest.approx(spread[j], rel=0.1), (name, np.degrees(np.sqrt(var[j])),
                                                                          np.degrees(spread[j]))
        if name.startswith("SC_"):
            assert var[j] == 0.0 and spread[j] < 1e-12, name
    E = np.zeros((18, 6))
    for i in range(6):
        seg, v = ("scapula", "humerus")[i // 3], np.zeros(3)
        v[i % 3] = 1e-6
        moved = dict(frames)
        moved[seg] = frames[seg] @ Rotation.from_rotvec(v).as_matrix()
        E[:, i] = np.angle(np.exp(1j * (table(moved)[0] - base))) / 1e-6
    quad = np.einsum("ai,ij,aj->a", E, amp.girdle, E) * drv ** 2
    shipped = AU.girdle_angle_variance(kin, q0[None], amp, 22)[0][:18]
    np.testing.assert_allclose(shipped, np.maximum(quad, 0.0), rtol=1e-3, atol=1e-9)
    no_offset = AU.girdle_angle_variance(kin, q0[None], dataclasses.replace(amp, girdle_offset_rad=0.0), 22)[0][:18]
    np.testing.assert_allclose(no_offset, shipped * (theta / drv) ** 2, rtol=1e-12, atol=1e-15)
    assert (quad < -1e-6).any() and (quad > 1e-6).any()
    none = dataclasses.replace(amp, girdle=None)
    assert not AU.girdle_angle_variance(kin, q0[None], none, 22).any()


def test_an_angle_beyond_the_bound_or_near_its_lock_is_not_measured(setting):
    """Over the reference postures (HT 10-120 deg, three planes): an ST, GH or HT angle whose u
    exceeds the bound is not measured in that posture, and the GH Y-X'-Y'' plane of elevation and
    axial rotation are not measured where GH elevation is below the margin; Phadke's sequence is."""
    model, protocol, kin, pts = setting
    from exubio.synth.simulate import reference_postures

    q = reference_postures(model)
    held = held_mask(model, protocol)
    excluded = bind(model, protocol).not_solved
    present = np.ones((q.shape[0], len(protocol.markers)), dtype=bool)
    det = angle_determinacy(kin, pts, q, present, protocol.weights, held=held, locked=excluded & ~held)
    names, ang = anatomical_table(model, q, unwrap=False)
    u = np.degrees(det.uncertainty_rad)
    for j, name in enumerate(names):
        if AU.bound_applies(name):
            assert (det.status[u[:, j] > AU.U_BOUND_DEG, j] != AngleStatus.MEASURED).all(), name
    gh_el = np.degrees(np.abs(ang[:, names.index("GH_X_elevation")]))
    low = gh_el < AU.GIMBAL_MARGIN_DEG
    assert low.any()
    for name in ("GH_Y_plane_of_elevation", "GH_Y_axial_rotation"):
        assert (det.status[low, names.index(name)] == AngleStatus.NOT_MEASURED).all()
    assert (det.status[low, names.index("GH_phadke_X_elevation")] == AngleStatus.MEASURED).all()


@pytest.mark.exudyn
def test_the_truth_lies_within_two_u_under_the_bone_pin_artefact(setting):
    """Simulated abduction with the artefact fitted on bone pins (exubio simulate --sta bone: the
    regression's mean course and its held-out residual), 1 mm noise: in at least 85 % of the measured
    frames of each shoulder angle below the truth is within +-2u (studies/uncertainty_coverage.py,
    5 seeds: 96-100 % in abduction), both methods. GH flexion in Phadke's sequence does not reach it
    in abduction (87 % over 5 seeds, 68 % above HT 90 deg: studies/README.md says why): its error
    stays within a factor 2 of u (RMS of error/u 1.3 over 5 seeds)."""
    model, protocol, kin, pts = setting
    from exubio.synth.sta_bone import load_sta_model

    sim = simulate_trial(model, "abduction", duration_s=10.0, rate_hz=50.0, noise_mm=1.0, seed=11, sta_mm=10.0,
                         sta_model=load_sta_model("bone"))
    _, truth = anatomical_table(model, sim.q_true)
    for method in ("ls", "pf"):
        rec = exubio.reconstruct(sim.trajectories, model, protocol, method=method)
        det = exubio.angle_status(rec, model, protocol)
        names, est = anatomical_table(model, rec.q_rad)
        err = np.abs(np.angle(np.exp(1j * (est - truth))))
        for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
                     "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation", "HT_X_elevation"):
            j = names.index(name)
            ok = det.status[:, j] == AngleStatus.MEASURED
            assert ok.mean() > 0.5, (method, name)
            z = err[ok, j] / det.uncertainty_rad[ok, j]
            if name == "GH_phadke_Z_flexion":
                assert np.sqrt(np.mean(z ** 2)) < 2.0, (method, name)
                continue
            assert np.mean(z <= 2) >= 0.85, (method, name, np.mean(z <= 2))


def test_every_output_carries_the_uncertainty(setting, tmp_path):
    """The CSV's <angle>_u_deg beside each angle, the .npz array and the DataFrame hold the same
    numbers, and the summary gives each measured angle's median."""
    import json

    from exubio.io.results import read_angles_csv, read_npz_arrays

    model, protocol, kin, pts = setting
    sim = simulate_trial(model, "abduction", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=3)
    rec = exubio.reconstruct(sim.trajectories, model, protocol, method="ls")
    paths = exubio.write_results(rec, tmp_path, "t", model=model, protocol=protocol, overwrite=True)
    header = next(line for line in paths["csv"].read_text().splitlines() if not line.startswith("#")).split(",")
    assert header[1:5] == ["SC_Y_protraction_deg", "SC_Y_protraction_u_deg", "SC_X_elevation_deg", "SC_X_elevation_u_deg"]
    _, names, _, u_csv = read_angles_csv(paths["csv"], uncertainty=True)
    u_npz = read_npz_arrays(paths["npz"], ("angle_uncertainty_rad",))["angle_uncertainty_rad"]
    fin = np.isfinite(u_npz)
    assert np.allclose(u_csv[fin], u_npz[fin], atol=np.radians(1e-5))
    df = exubio.to_dataframe(rec, model=model, protocol=protocol)
    assert np.allclose(df["HT_X_elevation_u_deg"].to_numpy(), np.degrees(u_npz[:, names.index("HT_X_elevation_deg")]),
                       atol=1e-5)
    summary = json.loads(paths["summary"].read_text())
    med = summary["anatomical_angles"]["median_uncertainty_deg_measured_frames"]
    assert med["HT_X_elevation"] is not None and 0 < med["HT_X_elevation"] < AU.U_BOUND_DEG


def _joint_amplitude(cross: bool):
    from exubio.trust.sta_amplitude import STAAmplitude

    C = np.diag([0.06, 0.04, 0.05, 0.006, 0.004, 0.005]) ** 2
    z = {s: np.zeros(3) for s in ("scapula", "humerus")}
    rot = {s: np.sqrt(np.diag(C)[:3]) for s in z}
    tra = {s: np.sqrt(np.diag(C)[3:]) for s in z}
    return STAAmplitude(rot, tra, z, {s: C for s in z}, {"scapula|humerus": C} if cross else {}), C


@pytest.mark.exudyn
def test_two_clusters_that_move_together_give_the_propagated_uncertainty(setting):
    """The scapula's and the humerus's skin clusters drawn as rigid motions that move together (the
    same rotation vector and translation in each bone's own axes, fully correlated) and applied to
    the markers exactly (rotations about each cluster's centroid, not linearised), solved by exubio's
    own least squares: the angles' spread is the u that carries the two clusters' cross term, and
    differs from the u that treats them as independent (the cross term is there and right)."""
    model, protocol, kin, pts = setting
    from scipy.spatial.transform import Rotation

    from exubio.synth.simulate import reference_postures

    q0 = reference_postures(model)[3]  # abduction, HT 54 deg
    held = held_mask(model, protocol)
    excluded = bind(model, protocol).not_solved
    present = np.ones((1, len(protocol.markers)), dtype=bool)
    kw = dict(held=held, locked=excluded & ~held, noise_mm=1e-6)
    amp, C = _joint_amplitude(True)
    u = np.degrees(angle_determinacy(kin, pts, q0[None], present, protocol.weights, amplitude=amp, **kw).uncertainty_rad[0])
    u_indep = np.degrees(angle_determinacy(kin, pts, q0[None], present, protocol.weights, amplitude=_joint_amplitude(False)[0],
                                           **kw).uncertainty_rad[0])
    R, _ = kin.poses(q0[None])
    names_seg = [s.name for s in model.segments]
    theta = np.arccos(np.clip((np.trace(R[0, names_seg.index("humerus")]) - 1) / 2, -1, 1))  # the driver
    frames = segment_anatomical_rotations(model, q0[None], kinematics=kin)
    P0 = kin.points(q0[None], pts)[0]
    rng = np.random.default_rng(11)
    n = 300
    xi = rng.standard_normal((n, 6)) @ np.sqrt(C) * theta  # one draw for both clusters
    P = np.repeat(P0[None], n, axis=0)
    for seg in ("scapula", "humerus"):
        sel = np.flatnonzero(np.asarray(pts.segment_index) == names_seg.index(seg))
        axes = frames[seg][0]
        c = P0[sel].mean(axis=0)
        Q = Rotation.from_rotvec(xi[:, :3] @ axes.T).as_matrix()
        P[:, sel] = c + np.einsum("nij,kj->nki", Q, P0[sel] - c) + (xi[:, 3:] @ axes.T)[:, None, :]
    targets = MarkerTargets(np.arange(n) * 0.01, protocol.marker_names, P, np.zeros_like(P), np.zeros_like(P))
    rec = reconstruct_ls(model, protocol, targets)
    names, ang = anatomical_table(model, rec.q_rad, unwrap=False)
    _, ref = anatomical_table(model, q0)
    spread = np.degrees(np.std(np.angle(np.exp(1j * (ang - ref))), axis=0))
    differs = False
    for name in ("ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation", "GH_phadke_Z_flexion",
                 "GH_phadke_Y_internal_rotation", "HT_X_elevation"):
        j = names.index(name)
        assert spread[j] == pytest.approx(u[j], rel=0.2), (name, spread[j], u[j], u_indep[j])
        differs |= abs(u_indep[j] / u[j] - 1) > 0.4
    assert differs


def test_the_shipped_cross_term_is_the_pins_and_makes_one_joint_covariance(tmp_path):
    """The scapula-humerus cross second moment shipped is what the S2M pins give when both clusters'
    rigid motions are pooled over the same frames (recomputed here from the split of each bone), the
    joint 12 x 12 covariance is positive semi-definite, and the JSON keeps it."""
    from pathlib import Path

    from exubio.trust.sta_amplitude import load_sta_amplitude
    from exubio.truth.sta_amplitude import _rest, humerus_driver, segment_sta, write_sta_amplitude
    from exubio.truth.sta_format import read_sta_trial

    amp = load_sta_amplitude()
    X = amp.cross_of("scapula", "humerus")
    np.testing.assert_allclose(amp.cross_of("humerus", "scapula"), X.T)
    J = np.block([[amp.rigid["scapula"], X], [X.T, amp.rigid["humerus"]]])
    assert np.linalg.eigvalsh(J).min() > -1e-12
    back = load_sta_amplitude(write_sta_amplitude(amp, tmp_path / "a.json"))
    np.testing.assert_allclose(back.cross_of("scapula", "humerus"), X, rtol=1e-5)
    data = Path(__file__).resolve().parents[3] / "shared" / "data" / "truth" / "sta_opendata"
    s2m = sorted(data.glob("dataSample_S2M_*.mat"))
    if len(s2m) < 4:
        pytest.skip("../shared/data/truth/sta_opendata absent")
    num, den = np.zeros((6, 6)), 0.0
    for f in s2m:
        t = read_sta_trial(f)
        rest = _rest(t, 300.0)
        th = amp.skin_driver(humerus_driver(t, rest))  # the coefficients are per unit of the skin's driver
        x = {b: np.concatenate([v["rotation"], v["translation"]], axis=1)
             for b, v in ((b, segment_sta(t, b, rest)) for b in ("scapula", "humerus"))}
        ok = np.isfinite(x["scapula"]).all(axis=1) & np.isfinite(x["humerus"]).all(axis=1)
        num += x["scapula"][ok].T @ x["humerus"][ok]
        den += float(np.sum(th[ok] ** 2))
    np.testing.assert_allclose(X, num / den, rtol=1e-4, atol=1e-10)


@pytest.mark.exudyn
def test_the_still_thorax_cost_is_what_the_solver_does_with_an_unseen_trunk(setting):
    """Trunk motions drawn from a stated second moment and applied exactly (every marker turned about
    IJ and moved with it, in the frame the run takes as the thorax), solved by exubio's own least
    squares; the truth, the bones turned by the same motion, measured in that frame: the spread of
    the angle errors is the still thorax's propagated cost (trunk_angle_variance)."""
    model, protocol, kin, pts = setting
    from scipy.spatial.transform import Rotation

    from exubio.model.angles import angles_of_frames
    from exubio.synth.simulate import reference_postures

    q0 = reference_postures(model)[3]  # abduction, HT 54 deg
    excluded = bind(model, protocol).not_solved
    free = np.flatnonzero(~excluded)
    present = np.ones((1, len(protocol.markers)), dtype=bool)
    C = np.diag([0.03, 0.04, 0.02, 0.004, 0.002, 0.004]) ** 2
    K = AU.sensitivity(kin, pts, q0[None], present, protocol.weights, free)
    table = lambda qq: anatomical_table(model, qq, kinematics=kin, unwrap=False)[1]
    from exubio.trust.observability import _angle_jacobian

    D = _angle_jacobian(table, q0[None])
    R, _ = kin.poses(q0[None])
    names_seg = [s.name for s in model.segments]
    theta = np.arccos(np.clip((np.trace(R[0, names_seg.index("humerus")]) - 1) / 2, -1, 1))
    from exubio.trust.sta_amplitude import STAAmplitude

    z = {s: np.zeros(3) for s in ("scapula", "humerus")}
    amp = STAAmplitude(z, z, z, trunk_nodes=np.array([0.3]), trunk_table=C[None])  # constant, as shipped
    u = np.sqrt(AU.trunk_angle_variance(kin, pts, q0[None], D @ K, amp)[0])
    assert theta > 0.5  # the arm is raised: the constant trunk term does not scale with it
    rng = np.random.default_rng(5)
    n = 300
    xi = rng.standard_normal((n, 6)) @ np.sqrt(C)
    Q = Rotation.from_rotvec(xi[:, :3]).as_matrix()
    P0 = kin.points(q0[None], pts)[0]
    P = np.einsum("nij,kj->nki", Q, P0) + xi[:, None, 3:]  # IJ is the thorax frame's origin
    targets = MarkerTargets(np.arange(n) * 0.01, protocol.marker_names, P, np.zeros_like(P), np.zeros_like(P))
    rec = reconstruct_ls(model, protocol, targets)
    names, ang = anatomical_table(model, rec.q_rad, unwrap=False)
    frames = segment_anatomical_rotations(model, q0[None], kinematics=kin)
    moved = {s: (F[0] if s == "thorax" else np.einsum("nij,jk->nik", Q, F[0])) for s, F in frames.items()}
    sets = angles_of_frames(moved)
    truth = np.concatenate([np.broadcast_to(sets[s], (n, 3)) for s in sets], axis=-1)
    err = np.angle(np.exp(1j * (ang[:, :18] - truth)))
    spread = np.degrees(np.sqrt(np.mean(err ** 2, axis=0)))
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
                 "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation", "HT_X_elevation", "HT_Y_axial_rotation"):
        j = names.index(name)
        assert spread[j] == pytest.approx(np.degrees(u[j]), rel=0.2, abs=0.1), (name, spread[j], np.degrees(u[j]))


def _turned(r: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rodrigues: the points r (k, 3) turned by the rotation vector w about their centroid."""
    th = np.linalg.norm(w)
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / th
    R = np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k
    c = r.mean(axis=0)
    return (r - c) @ R.T + c


def test_a_turned_cluster_turns_its_frame_and_a_shifted_one_does_not(setting):
    """The misfit term with the markers' directions (AU.misfit_angle_variance): scapula markers
    turned by 1 deg about their centroid away from the model (a bone the model does not follow) give
    each ST and GH angle an SD equal to the change of that angle when the ISB frame is turned so
    (computed here with an exact rotation, not the function's first-order one), within 5 % of the
    turn (the first-order terms: an angle that hardly changes is compared in absolute terms); the
    same markers shifted by 20 mm give nothing (with the distances alone the shift would be taken
    for a turn)."""
    from exubio.model.angles import angles_of_frames
    from exubio.synth.simulate import reference_postures

    model, protocol, kin, pts = setting
    q0 = reference_postures(model)[3][None]
    P = kin.points(q0, pts)[0]
    scap = np.flatnonzero(np.array([model.segments[i].name for i in pts.segment_index]) == "scapula")
    present = np.ones((1, len(pts.segment_index)), dtype=bool)
    expected = np.zeros((1, len(pts.segment_index)))  # no noise, no artefact: every residual is misfit
    names, _ = anatomical_table(model, q0[0])
    w = np.radians(1.0) * np.array([0.3, -0.8, 0.5]) / np.linalg.norm([0.3, -0.8, 0.5])
    frames = segment_anatomical_rotations(model, q0, kinematics=kin)
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / np.linalg.norm(w)
    Rw = np.eye(3) + np.sin(np.linalg.norm(w)) * k + (1 - np.cos(np.linalg.norm(w))) * k @ k
    bone = dict(frames, scapula=Rw @ frames["scapula"])
    sets = list(angles_of_frames(frames))
    truth = np.concatenate([angles_of_frames(bone)[s] for s in sets], axis=-1)[0]
    model_angles = np.concatenate([angles_of_frames(frames)[s] for s in sets], axis=-1)[0]
    M = P.copy()
    M[scap] = _turned(P[scap], w)
    res = np.linalg.norm(M - P, axis=1)[None]
    var = AU.misfit_angle_variance(kin, pts, q0, present, res, expected, len(names), measured_m=M[None])[0]
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
                 "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation"):
        j = names.index(name)
        err = abs(np.angle(np.exp(1j * (truth[j] - model_angles[j]))))
        assert np.sqrt(var[j]) == pytest.approx(err, abs=0.05 * np.linalg.norm(w)), name
    S = P.copy()
    S[scap] += np.array([0.0, 0.02, 0.0])
    shifted = AU.misfit_angle_variance(kin, pts, q0, present, np.linalg.norm(S - P, axis=1)[None], expected,
                                       len(names), measured_m=S[None])[0]
    assert np.abs(shifted).max() < 1e-12
    iso = AU.misfit_angle_variance(kin, pts, q0, present, np.linalg.norm(S - P, axis=1)[None], expected, len(names))[0]
    assert iso[names.index("ST_X_upward_rotation")] > np.radians(5.0) ** 2


def test_a_skin_fitted_ellipsoid_turns_the_scapula_frame_by_the_clusters_whole_rotation(setting):
    """AU.skin_ellipsoid_variance against exact rotations: the scapula's ISB frame turned by sampled
    rotation vectors of the artefact model's scapula rotation covariance (in its ISB axes, times
    d^2, d the skin's driver of the humerus's rotation from rest; scaled by 1e-2 so that first order holds) moves
    each ST and GH angle with the SD the function gives (times 1e-2), within 5 %; the thorax-relative
    humerus (HT) does not move; at rest (theta = 0) the term is zero."""
    from exubio.model.angles import angles_of_frames
    from exubio.synth.simulate import reference_postures

    model, protocol, kin, pts = setting
    q0 = reference_postures(model)[3][None]
    names, _ = anatomical_table(model, q0[0])
    var = AU.skin_ellipsoid_variance(kin, q0, shipped_amplitude(), len(names))[0]
    frames = segment_anatomical_rotations(model, q0, kinematics=kin)
    sets = list(angles_of_frames(frames))
    base = np.concatenate([angles_of_frames(frames)[s] for s in sets], axis=-1)[0]
    R, _ = kin.poses(q0)
    hum = R[0, [s.name for s in model.segments].index("humerus")]
    theta = np.arccos(np.clip((np.trace(hum) - 1) / 2, -1, 1))
    assert theta > 0.3  # a posture away from rest
    axes = frames["scapula"][0]
    d = shipped_amplitude().skin_driver(theta)  # the skin's coefficients are per unit of its driver
    Cw = axes @ shipped_amplitude().of("scapula")[0][:3, :3] @ axes.T * d ** 2
    eps = 1e-2
    rng = np.random.default_rng(7)
    ws = rng.multivariate_normal(np.zeros(3), Cw * eps ** 2, size=4000)
    moved = []
    for w in ws:
        a = np.linalg.norm(w)
        k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / a
        Rw = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k
        turned = dict(frames, scapula=Rw @ frames["scapula"])
        moved.append(np.concatenate([angles_of_frames(turned)[s] for s in sets], axis=-1)[0])
    sd = np.std(np.angle(np.exp(1j * (np.array(moved) - base))), axis=0) / eps
    for name in ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
                 "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation"):
        j = names.index(name)
        assert np.sqrt(var[j]) == pytest.approx(sd[j], rel=0.05), name
    assert var[names.index("HT_X_elevation")] == 0.0
    assert np.sqrt(var[names.index("ST_X_upward_rotation")]) > np.radians(2.0)
    assert np.abs(AU.skin_ellipsoid_variance(kin, np.zeros((1, q0.shape[1])), shipped_amplitude(), len(names))).max() < 1e-20


def test_a_calibration_that_fitted_the_ellipsoid_on_skin_poses_widens_st_and_gh_only(setting):
    """angle_determinacy with a model whose calibration record says the ellipsoid was fitted on a
    scapula trial (or several statics: AU.ellipsoid_from_skin): ST and GH angles' u grow by the skin
    term, HT and the distal angles' u stay bit for bit; a record without such a fit changes nothing."""
    import dataclasses

    from exubio.synth.simulate import reference_postures

    model, protocol, kin, pts = setting
    q = np.stack([reference_postures(model)[3], reference_postures(model)[4]])
    present = np.ones((2, len(pts.segment_index)), dtype=bool)
    b = bind(model, protocol)

    def u_of(metadata_calibration):
        m = dataclasses.replace(model, metadata={**dict(model.metadata), "calibration": metadata_calibration})
        k = Kinematics(m)
        det = angle_determinacy(k, tracked_points(k, protocol), q, present, protocol.weights, held=b.held,
                                locked=b.locked)
        return det.names, det.uncertainty_rad

    names, u0 = u_of(None)
    _, u_static = u_of({"functional": {"scapula": {"used": False, "reason": "too little rotation"}},
                        "ellipsoid_poses_mm": {"static": 0.1}})
    _, u_trial = u_of({"functional": {"scapula": {"used": True}}})
    _, u_statics = u_of({"ellipsoid_poses_mm": {"static": 0.1, "raised": 2.0}})
    assert np.array_equal(u0, u_static)
    assert np.array_equal(u_trial, u_statics)
    for j, name in enumerate(names):
        if name.startswith(("ST_", "GH_")):
            assert (u_trial[:, j] > u0[:, j]).all(), name
        elif not name.startswith(("SC_", "AC_")):
            assert np.array_equal(u_trial[:, j], u0[:, j]), name
    assert AU.ellipsoid_from_skin(None) is False
