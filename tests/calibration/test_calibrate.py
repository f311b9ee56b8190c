"""Static calibration against known truths (a subject model made by scaling the generic one and
moving its markers), the model file round trip, and the robustness of the whole pipeline on small
trial files the tests write themselves (extra and prefixed labels, gaps anywhere, missing markers)."""
import dataclasses

import numpy as np
import pytest

from exubio.calibration import (
    CalibrationReport,
    calibrate_model,
    calibrated_protocol,
    find_still_frames,
    fit_ellipsoid,
    format_report,
    parse_frames,
    scale_model,
)
from exubio.errors import InputError
from exubio.trust.evaluate import residual_statistics
from exubio.io.c3d import write_c3d
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model, save_model
from exubio.run.pipeline import reconstruct, reconstruct_file
from exubio.run.inputs import load_model_and_protocol, load_session
from exubio.prep.targets import prepare_targets
from exubio.protocol.load import load_protocol
from exubio.io.resources import shipped_file
from exubio.synth.simulate import simulate_trial
from exubio.types import Trajectories

pytestmark = pytest.mark.exudyn

TRUE_SCALE = {"thorax": 1.05, "humerus": 1.10, "ulna": 0.95, "radius": 0.95, "hand": 1.05}
MARKER_SHIFT_M = 0.005  # every marker of the subject sits 5 mm (random direction) off the generic one
TRC_PROTOCOL = shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols")


@pytest.fixture(scope="module")
def generic():
    return load_model_and_protocol()


@pytest.fixture(scope="module")
def subject(generic):
    """The 'true' subject: the generic model scaled by TRUE_SCALE, markers moved by 5 mm."""
    model, protocol = generic
    truth = scale_model(model, TRUE_SCALE)
    rng = np.random.default_rng(0)
    markers = set(protocol.marker_names)
    segments = []
    for seg in truth.segments:
        points = dict(seg.points)
        for name in points:
            if name in markers:
                d = rng.normal(size=3)
                points[name] = points[name] + MARKER_SHIFT_M * d / np.linalg.norm(d)
        segments.append(dataclasses.replace(seg, points=points))
    return dataclasses.replace(truth, segments=tuple(segments))


@pytest.fixture(scope="module")
def calibrated(generic, subject):
    """The generic model calibrated on the first 0.2 s of a simulated abduction of the subject."""
    model, protocol = generic
    static = simulate_trial(subject, "abduction", duration_s=0.5, rate_hz=100.0)
    cal, report = calibrate_model(model, protocol, static.trajectories, frames=slice(0, 20))
    return cal, report, static


def test_scale_factors_are_recovered(calibrated):
    _, report, _ = calibrated
    for seg, s in report.scale_factors.items():
        assert s == pytest.approx(TRUE_SCALE.get(seg, 1.0), rel=0.03), (seg, s)
    assert report.thorax_scale_measured
    assert report.scale_factors["ulna"] == report.scale_factors["radius"]  # one forearm factor


def test_marker_positions_are_recovered_within_a_few_mm(generic, subject, calibrated):
    _, protocol = generic
    cal, report, _ = calibrated
    err = {}
    for m in report.markers:
        assert m.registered and m.point == m.name
        err[m.name] = np.linalg.norm(cal.segment(m.segment).points[m.point] - subject.segment(m.segment).points[m.name])
    err_mm = np.array(list(err.values())) * 1000
    assert err_mm.max() < 6.0, err
    assert err_mm.mean() < 4.0, err  # 3.54 mm: the static pose keeps the held sc_posterior_rotation at 0
    # the generic model was 5 mm off everywhere (plus the scaling): that is what the offsets report
    offsets = np.array([m.generic_offset_mm for m in report.markers])
    assert np.all((offsets > 0.5) & (offsets < 12.0)), offsets


def test_ellipsoid_passes_through_the_contact_points_at_the_static_pose(calibrated):
    cal, report, _ = calibrated
    kin = Kinematics(cal)
    assert np.abs(kin.g(report.static_q_rad)).max() < 1e-10
    assert report.constraint_abs < 1e-10
    # radii keep the generic ratios
    generic_radii = load_model().ellipsoid.radii_m
    ratio = cal.ellipsoid.radii_m / generic_radii
    assert np.ptp(ratio) < 1e-12


def test_calibration_residual_is_reported_per_marker(calibrated):
    cal, report, _ = calibrated
    res = report.residual_mm
    assert set(res) == {m.name for m in report.markers}
    assert all(np.isfinite(v) and 0 <= v < 1.0 for v in res.values())  # noise-free static frames
    assert report.mean_residual_mm < 1.0
    assert cal.metadata["calibration"]["markers"]["EPI_lat"]["residual_mm"] == pytest.approx(res["EPI_lat"], abs=1e-3)
    text = format_report(report)
    assert "EPI_lat" in text and "calibration residual" in text


def test_model_file_round_trip(tmp_path, generic, calibrated):
    _, protocol = generic
    cal, report, _ = calibrated
    path = save_model(cal, tmp_path / "subject.yaml", calibration=report.to_dict())
    back = load_model(path)
    assert back.segment_names == cal.segment_names
    assert back.coordinate_names == cal.coordinate_names
    for a, b in zip(cal.segments, back.segments):
        assert set(a.points) == set(b.points), a.name
        for name in a.points:
            np.testing.assert_allclose(b.points[name], a.points[name], rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.com_m, a.com_m, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.inertia_kgm2, a.inertia_kgm2, rtol=1e-9, atol=1e-15)
        assert b.mass_kg == pytest.approx(a.mass_kg, rel=1e-12)
        if a.joint is not None:
            np.testing.assert_allclose(b.joint.centre_m, a.joint.centre_m, rtol=0, atol=1e-9)
            np.testing.assert_allclose(b.joint.axes, a.joint.axes, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.ellipsoid.centre_m, cal.ellipsoid.centre_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.ellipsoid.radii_m, cal.ellipsoid.radii_m, rtol=0, atol=1e-9)
    recorded = back.metadata["calibration"]
    assert recorded["scale_factors"]["humerus"] == pytest.approx(report.scale_factors["humerus"], abs=1e-6)
    assert recorded["frames"]["start"] == 0 and recorded["frames"]["stop"] == 20
    assert set(recorded["markers"]) == set(protocol.marker_names)
    # the protocol, loaded against the file's points, picks up the calibrated positions
    reloaded = load_protocol(protocol.source, segments=back.segment_names,
                             model_points={s.name: dict(s.points) for s in back.segments})
    for m, c in zip(reloaded.markers, calibrated_protocol(protocol, cal).markers):
        np.testing.assert_allclose(m.local_position_m, c.local_position_m, rtol=0, atol=1e-9)
    # body mass still scales the inertia of a written model
    heavier = load_model(path, body_mass_kg=2 * cal.body_mass_kg)
    assert heavier.segment("humerus").mass_kg == pytest.approx(2 * cal.segment("humerus").mass_kg)


def test_calibrated_model_tracks_the_subject_better_than_the_generic(generic, subject, calibrated):
    model, protocol = generic
    cal, _, _ = calibrated
    trial = simulate_trial(subject, "abduction", duration_s=5.0, rate_hz=100.0, noise_mm=1.0, seed=3)
    targets = prepare_targets(trial.trajectories, protocol)
    gen = reconstruct(model, protocol, targets, method="ls")
    sub = reconstruct(cal, calibrated_protocol(protocol, cal), targets, method="ls")
    r_gen, r_sub = residual_statistics(gen), residual_statistics(sub)
    assert r_sub["mean"] < 0.2 * r_gen["mean"], (r_sub["mean"], r_gen["mean"])
    assert r_sub["max_frame_mean"] < 3.0
    assert np.abs(sub.constraint).max() < 1e-8
    # and the joint angles come closer to the truth
    rmse = lambda rec: np.sqrt(np.mean(np.rad2deg(rec.q_rad - trial.q_true) ** 2))
    assert rmse(sub) < rmse(gen)


def test_joint_centre_markers_are_registered_beside_the_joint(generic, tmp_path):
    """The TRC set ties gu to GH and centelbow to EJC: the calibration registers them as points of
    their own and leaves the joint centres; ts and ai become the ellipsoid contact points."""
    model, _ = generic
    protocol = load_protocol(TRC_PROTOCOL, segments=model.segment_names,
                             model_points={s.name: dict(s.points) for s in model.segments})
    sim = simulate_trial(model, "flexion", duration_s=0.3, rate_hz=100.0, lab_transform=False,
                         marker_names=("AA", "TS", "AI", "GH", "EL", "EJC", "IJ", "C7", "PX", "T8"))
    pos = sim.trajectories.positions_m
    thorax = np.stack([pos[:, 6], 0.5 * (pos[:, 6] + pos[:, 7]), 0.5 * (pos[:, 8] + pos[:, 9])], axis=1)
    traj = dataclasses.replace(sim.trajectories, positions_m=np.concatenate([pos[:, :6], thorax], axis=1),
                               labels=("aa", "ts", "ai", "gu", "EpL", "centelbow", "ij", "centijc7", "centpxt8"))
    cal, report = calibrate_model(model, protocol, traj, frames=slice(0, 10))
    points = {m.name: m.point for m in report.markers}
    assert points == {"aa": "AA", "ts": "TS", "ai": "AI", "gu": "gu", "EpL": "EL", "centelbow": "centelbow"}
    hum, gen_hum = cal.segment("humerus"), scale_model(model, report.scale_factors).segment("humerus")
    np.testing.assert_allclose(hum.points["GH"], 0.0, atol=1e-15)  # GH is still the humerus origin
    np.testing.assert_allclose(cal.segment("ulna").joint.centre_m, gen_hum.points["EJC"], atol=1e-12)
    # forearm and hand carry no marker: not scaled
    assert report.scale_factors["ulna"] == report.scale_factors["hand"] == 1.0
    # noise-free truth = generic model: gu lands (nearly) on GH, and the protocol binds to it
    assert np.linalg.norm(hum.points["gu"]) < 0.003
    bound = calibrated_protocol(protocol, cal)
    np.testing.assert_array_equal(bound.markers[protocol.marker_names.index("gu")].local_position_m, hum.points["gu"])
    # from the model file: the protocol loaded against its points ties gu to the joint centre GH;
    # calibrated_protocol rebinds it to the registered point the file records
    back = load_model(save_model(cal, tmp_path / "trc_subject.yaml", calibration=report.to_dict()))
    from_file = load_protocol(TRC_PROTOCOL, segments=back.segment_names,
                              model_points={s.name: dict(s.points) for s in back.segments})
    np.testing.assert_array_equal(from_file.markers[3].local_position_m, back.segment("humerus").points["GH"])
    rebound = calibrated_protocol(from_file, back)
    for a, b in zip(rebound.markers, bound.markers):
        np.testing.assert_allclose(a.local_position_m, b.local_position_m, rtol=0, atol=1e-9)
    kin = Kinematics(cal)
    contacts = kin.points(report.static_q_rad, kin.contacts)
    static = np.nanmean(prepare_targets(traj, protocol).positions_m[:10], axis=0)
    np.testing.assert_allclose(contacts, static[[1, 2]], atol=1e-12)  # ts, ai
    assert np.abs(kin.g(report.static_q_rad)).max() < 1e-10


def test_a_marker_absent_from_the_calibration_frames(generic, subject):
    model, protocol = generic
    static = simulate_trial(subject, "abduction", duration_s=0.3, rate_hz=100.0)
    pos = static.trajectories.positions_m.copy()
    traj = static.trajectories
    pos[:, traj.index("ELB")] = np.nan  # optional: keeps its scaled generic position
    cal, report = calibrate_model(model, protocol, dataclasses.replace(traj, positions_m=pos), frames=slice(0, 20))
    elb = next(m for m in report.markers if m.name == "ELB")
    assert not elb.registered and np.isnan(elb.residual_mm)
    expected = model.segment("ulna").points["ELB"] * report.scale_factors["ulna"]
    # the registered model frame differs from the scaled generic one only by the static pose error
    assert np.linalg.norm(cal.segment("ulna").points["ELB"] - expected) < 0.01
    pos[:25, traj.index("SEML")] = np.nan  # not optional: a clear error naming it
    with pytest.raises(InputError, match="SEML.*calibration frames 0:20"):
        calibrate_model(model, protocol, dataclasses.replace(traj, positions_m=pos), frames=slice(0, 20))


def test_static_frames():
    assert parse_frames("10:60") == slice(10, 60)
    assert parse_frames(":50") == slice(None, 50)
    assert parse_frames(None) is None and parse_frames("") is None
    for bad in ("10", "a:b", "1:2:0"):
        with pytest.raises(InputError, match="static-frames"):
            parse_frames(bad)


def test_still_frames_are_found(generic):
    model, protocol = generic
    sim = simulate_trial(model, "abduction", duration_s=4.0, rate_hz=100.0)
    pos = sim.trajectories.positions_m.copy()
    pos[100:250] = pos[100]  # hold the pose for 1.5 s (the 2 Hz filter blurs its edges)
    targets = prepare_targets(dataclasses.replace(sim.trajectories, positions_m=pos), protocol)
    found = find_still_frames(targets)
    assert 100 <= found.start and found.stop <= 250 and found.stop - found.start >= 50, found


def test_ellipsoid_fit_keeps_ratios_and_moves_in_the_sagittal_plane():
    ell = load_model().ellipsoid
    contacts = np.array([[-0.14, -0.02, 0.09], [-0.13, -0.15, 0.10]])
    fitted, k = fit_ellipsoid(ell, contacts)
    d = (contacts - fitted.centre_m) / fitted.radii_m
    np.testing.assert_allclose((d * d).sum(axis=1), 1.0, atol=1e-12)
    assert fitted.centre_m[2] == ell.centre_m[2]
    np.testing.assert_allclose(fitted.radii_m / ell.radii_m, k)


# --------------------------------------------------------------------------------------------
# Robustness of the pipeline on small files
# --------------------------------------------------------------------------------------------
GAPS = {  # marker -> missing frames [start, stop) of the 100-frame test trial
    "CLAV_SC": (0, 8),  # at the very start
    "MET2": (94, 100),  # at the very end
    "DELT": (50, 51),  # one frame
    "SCAP_FRONT": (20, 70),  # half the trial
}


def _messy_trial(model, path, *, drop=(), never=()) -> Trajectories:
    """A 2 s, 50 Hz abduction written as C3D with 'Subject:' prefixes, two extra labelled
    markers, an unlabelled one, the gaps of GAPS, markers in ``drop`` left out and markers in
    ``never`` present but missing in every frame."""
    sim = simulate_trial(model, "abduction", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=5)
    t = sim.trajectories
    pos = t.positions_m.copy()
    for name, (a, b) in GAPS.items():
        pos[a:b, t.index(name)] = np.nan
    for name in never:
        pos[:, t.index(name)] = np.nan
    keep = [i for i, lab in enumerate(t.labels) if lab not in drop]
    extra = pos[:, [t.index("ARM")]] + np.array([0.0, 0.05, 0.0])
    labels = [f"Subject:{t.labels[i]}" for i in keep] + ["Subject:EXTRA_1", "Subject:KNEE", "*12"]
    pos = np.concatenate([pos[:, keep], extra, extra + 0.1, extra - 0.1], axis=1)
    write_c3d(path, Trajectories(tuple(labels), pos, t.rate_hz, t.time_s, source="test"))
    return t


@pytest.fixture(scope="module")
def messy_results(tmp_path_factory, generic):
    model, _ = generic
    folder = tmp_path_factory.mktemp("messy")
    trial = folder / "messy.c3d"
    _messy_trial(model, trial)
    return reconstruct_file(trial, folder / "out", methods=["ls", "pf"])


def test_extra_and_prefixed_labels(messy_results):
    for recon, summ in ((o.reconstruction, o.summary) for o in messy_results):
        assert set(summ["unused_trial_labels"]) >= {"EXTRA_1", "KNEE", "*12"}
        assert "ARM" in recon.marker_names  # 'Subject:ARM' found as ARM


@pytest.mark.parametrize("which", [0, 1], ids=["ls", "pf"])
def test_gaps_anywhere_are_handled_and_reported(messy_results, which):
    recon, summ = messy_results[which].reconstruction, messy_results[which].summary
    gaps = {(g["marker"], g["start_frame"], g["stop_frame"]) for g in summ["gaps"]}
    assert gaps == {(m, a, b) for m, (a, b) in GAPS.items()}
    assert np.isfinite(recon.q_rad).all() and np.isfinite(recon.qd_rad_s).all()
    assert np.abs(recon.constraint).max() < 1e-8
    for name, (a, b) in GAPS.items():
        j = recon.marker_names.index(name)
        assert np.isnan(recon.residuals_m[a:b, j]).all()
        assert np.isfinite(np.delete(recon.residuals_m[:, j], np.arange(a, b))).all()
    assert summ["residual_mm"]["max_frame_mean"] < 5.0  # generic model on its own simulation
    assert summ["frames"]["converged"] == recon.n_frames


def test_a_protocol_marker_that_never_appears(tmp_path, generic):
    """No SEML label, or a SEML without a sample: left out with a check naming it (the hand keeps
    MET2 and MET5, which still measure the wrist)."""
    model, protocol = generic
    for kind, name in (("drop", "no_seml"), ("never", "nan_seml")):
        trial = tmp_path / f"{name}.c3d"
        _messy_trial(model, trial, **{kind: ("SEML",)})
        (outcome,) = reconstruct_file(trial, tmp_path / f"out_{name}", methods=["ls"])
        recon, summ = outcome.reconstruction, outcome.summary
        reasons = [r for r in summ["quality"]["reasons"] if r["code"] == "missing_marker"]
        assert reasons and "SEML" in reasons[0]["message"] and summ["quality"]["verdict"] != "ok"
        assert np.isnan(recon.residuals_m[:, recon.marker_names.index("SEML")]).all()
    # unless the protocol marks it optional (ELB already is)
    text = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols").read_text(encoding="utf-8")
    text = text.replace("SEML:       {segment: hand, point: SEML}", "SEML:       {segment: hand, point: SEML, optional: true}")
    custom = tmp_path / "optional_seml.yaml"
    custom.write_text(text, encoding="utf-8")
    trial = tmp_path / "no_seml_elb.c3d"
    _messy_trial(model, trial, drop=("SEML", "ELB"))
    (outcome,) = reconstruct_file(trial, tmp_path / "out2", methods=["ls"], session=load_session(protocol_path=custom))
    recon, summ = outcome.reconstruction, outcome.summary
    assert np.isnan(recon.residuals_m[:, recon.marker_names.index("SEML")]).all()
    assert summ["residual_mm"]["per_marker_rmse"]["SEML"] is None
    assert np.abs(recon.constraint).max() < 1e-8


def test_report_is_a_dataclass_with_plain_data(calibrated):
    _, report, _ = calibrated
    assert isinstance(report, CalibrationReport)
    d = report.to_dict()
    import json

    json.dumps(d)  # plain data only
    assert d["residual_mm"]["mean"] == pytest.approx(report.mean_residual_mm)


def test_the_report_says_how_the_fits_stopped(calibrated):
    """Every fit of the calibration says why it stopped (exubio.types.StopReason labels); on the
    simulated subject they all converge and the quality verdict has nothing to say about them."""
    from exubio.trust import quality as Q
    from exubio.calibration import SCALE_BOUNDS

    cal, report, _ = calibrated
    d = report.to_dict()
    assert d["fit_stop"] == {"start_pose": "converged", "pose_and_scales": "converged", "reweighting": "converged"}
    assert cal.metadata["calibration"]["fit_stop"] == d["fit_stop"]
    assert not [r for r in Q.calibration_reasons(report, scale_bounds=SCALE_BOUNDS) if r.code == "calibration_fit"]
    assert "stopped before converging" not in format_report(report)


@pytest.mark.parametrize("fit, stop", [("pose_and_scales", "max_iterations"), ("pose_and_scales", "damping_exhausted"),
                                       ("reweighting", "max_iterations"), ("pose of raised.c3d", "not_finite")])
def test_a_fit_that_did_not_converge_is_a_check(calibrated, fit, stop):
    """A final fit, the robust reweighting or a further static's pose that stopped before
    converging makes the calibration a 'check' that names it; a start posture that did not
    converge is not judged (it only seeds the final fit)."""
    import dataclasses as dc

    from exubio.trust import quality as Q
    from exubio.calibration import SCALE_BOUNDS

    _, report, _ = calibrated
    d = dc.replace(report, fit_stop={**report.fit_stop, fit: stop})
    found = [r for r in Q.calibration_reasons(d, scale_bounds=SCALE_BOUNDS) if r.code == "calibration_fit"]
    assert len(found) == 1 and found[0].level == "check" and stop.replace("_", " ") in found[0].message
    assert "stopped before converging" in format_report(dc.replace(report, fit_stop={**report.fit_stop, fit: stop}))
    seed = dc.replace(report, fit_stop={**report.fit_stop, "start_pose": "damping_exhausted"})
    assert not [r for r in Q.calibration_reasons(seed, scale_bounds=SCALE_BOUNDS) if r.code == "calibration_fit"]


def test_written_inertia_keys_are_checked(tmp_path, calibrated):
    """The explicit inertia form save_model writes (com_mm, inertia_kgm2_per_kg) is validated."""
    from exubio.errors import ModelError

    cal, report, _ = calibrated
    path = save_model(cal, tmp_path / "m.yaml", calibration=None)
    text = path.read_text(encoding="utf-8")
    assert "com_mm" in text and "com_between" not in text
    both = text.replace("    com_mm:", "    com_between: [GH, EJC]\n    com_mm:", 1)
    with pytest.raises(ModelError, match="com_mm"):
        load_model(_write(tmp_path, "both.yaml", both))
    bad = text.replace("inertia_kgm2_per_kg:\n    - [", "inertia_kgm2_per_kg:\n    - [1.0, ", 1)
    with pytest.raises(ModelError, match="inertia_kgm2_per_kg"):
        load_model(_write(tmp_path, "bad.yaml", bad))


def _write(folder, name, text):
    p = folder / name
    p.write_text(text, encoding="utf-8")
    return p


def test_anatomical_fit_jacobian_matches_finite_differences(generic):
    """d(model points)/d(q, scale factors) of the anatomical fit against central differences at
    random poses and scale factors."""
    from exubio.calibration.posefit import _Anchor
    from exubio.calibration.scaling import _groups

    model, protocol = generic
    group_of = _groups(model, {"ulna": "forearm", "radius": "forearm"})
    groups = list(dict.fromkeys(group_of.values()))
    seg_index = np.array([model.segment_index(m.segment) for m in protocol.markers])
    local = np.array([m.local_position_m for m in protocol.markers])
    rng = np.random.default_rng(7)
    anchor = _Anchor(model=model, seg_index=seg_index, local_generic=local, target=np.zeros((len(local), 3)),
                     groups=groups, group_of=group_of, fixed={"thorax": 1.07}, prior_q=np.zeros(model.n_coordinates))
    w = np.ones(len(local))
    h = 1e-6
    for _ in range(3):
        q = rng.uniform(-1.0, 1.0, model.n_coordinates)
        s = {g: (1.07 if g == "thorax" else float(rng.uniform(0.8, 1.2))) for g in groups}
        _, e, J = anchor.evaluate(q, s, w, jacobian=True)
        # the points themselves: the scaled model's forward kinematics
        kin, pts = anchor.points(s)
        np.testing.assert_allclose(e, kin.points(q, pts), rtol=0, atol=1e-12)
        fd = []
        for j in range(model.n_coordinates):
            dq = np.zeros_like(q)
            dq[j] = h
            fd.append((anchor.evaluate(q + dq, s, w, jacobian=False)[1] - anchor.evaluate(q - dq, s, w, jacobian=False)[1]) / (2 * h))
        for g in anchor.free:
            up, dn = dict(s), dict(s)
            up[g] += h
            dn[g] -= h
            fd.append((anchor.evaluate(q, up, w, jacobian=False)[1] - anchor.evaluate(q, dn, w, jacobian=False)[1]) / (2 * h))
        np.testing.assert_allclose(J, np.stack(fd, axis=2), rtol=0, atol=1e-8)


def _subject_with_gh_moved(model, shift_m):
    """The generic model with its glenohumeral centre moved by ``shift_m`` (3,) in the scapula frame."""
    seg = model.segment("humerus")
    joint = dataclasses.replace(seg.joint, centre_m=np.asarray(seg.joint.centre_m) + shift_m)
    return dataclasses.replace(model, segments=tuple(dataclasses.replace(s, joint=joint) if s.name == "humerus" else s
                                                     for s in model.segments))


def test_functional_gh_centre_is_found_by_score_and_used(generic):
    """A subject whose glenohumeral centre is 15 mm from the generic one (lateral and down): the
    static pose alone leaves it where the generic model has it relative to the scapula markers; a
    functional trial (abduction then flexion, 1 mm noise) puts it within 2 mm of the truth."""
    from exubio.model.kinematics import Kinematics
    from exubio.types import Trajectories

    model, protocol = generic
    subject = _subject_with_gh_moved(model, np.array([0.0, -0.009, 0.012]))
    static = simulate_trial(subject, "abduction", duration_s=0.3, rate_hz=100.0, noise_mm=0.5, seed=4)
    parts = [simulate_trial(subject, m, duration_s=5.0, rate_hz=100.0, noise_mm=1.0, seed=5 + i)
             for i, m in enumerate(("abduction", "flexion"))]
    traj = parts[0].trajectories
    functional = Trajectories(labels=traj.labels, positions_m=np.concatenate([p.trajectories.positions_m for p in parts]),
                              rate_hz=traj.rate_hz, time_s=np.arange(1000) / traj.rate_hz, source="functional")
    f_targets = prepare_targets(functional, protocol)
    q_static = static.q_true[:20].mean(axis=0)
    truth = Kinematics(subject).frames(q_static).p[subject.segment_index("humerus")]
    errors = {}
    for label, f in (("static only", None), ("functional", f_targets)):
        cal, report = calibrate_model(model, protocol, static.trajectories, frames=slice(0, 20), functional=f)
        errors[label] = np.linalg.norm(np.array(report.joint_centres_mm["gh"]) / 1000 - truth) * 1000
        if f is not None:
            gh = report.functional["gh"]
            assert gh["used"] and gh["rotation_range_deg"] > 20.0, gh
    assert errors["functional"] < 2.0, errors
    assert errors["static only"] > 5.0, errors  # the functional trial is what found it


def test_a_second_static_pose_fits_the_ellipsoid_through_both(generic):
    """A generic ellipsoid of the wrong shape (radii x 1.25, 0.85, 1.1): calibrated on the arm-down
    static alone it passes through that pose's contact points only, and the subject's scapula at
    120 deg of abduction lies off it; given the raised pose too (more_statics), the ellipsoid is
    fitted through both poses' contact points and the subject's true contact points of both lie
    close to it."""
    from exubio.calibration.ellipsoid import surface_distance
    from exubio.model.kinematics import Kinematics
    from exubio.types import Trajectories

    subject, protocol = generic
    wrong = dataclasses.replace(subject, ellipsoid=dataclasses.replace(
        subject.ellipsoid, radii_m=np.asarray(subject.ellipsoid.radii_m) * np.array([1.25, 0.85, 1.1])))
    trial = simulate_trial(subject, "abduction", duration_s=5.0, rate_hz=100.0)
    top = int(np.argmax(trial.q_true[:, subject.coordinate_names.index("gh_abduction")]))

    def still(i, name):
        tr = trial.trajectories
        return Trajectories(labels=tr.labels, positions_m=np.repeat(tr.positions_m[i:i + 1], 40, axis=0),
                            rate_hz=tr.rate_hz, time_s=np.arange(40) / tr.rate_hz, source=name)

    kin = Kinematics(subject)
    truth = {"down": kin.points(trial.q_true[0], kin.contacts), "raised": kin.points(trial.q_true[top], kin.contacts)}
    off = {}
    for label, extra in (("one static", ()), ("two statics", (prepare_targets(still(top, "raised"), protocol),))):
        cal, report = calibrate_model(wrong, protocol, still(0, "down"), more_statics=extra)
        off[label] = {k: float(np.abs(surface_distance(cal.ellipsoid, p)).max() * 1000) for k, p in truth.items()}
        assert len(report.ellipsoid_poses_mm) == 1 + len(extra)
    assert off["one static"]["down"] < 0.5 and off["one static"]["raised"] > 5.0, off
    assert max(off["two statics"].values()) < 0.5 * off["one static"]["raised"], off
    # a raised static of the arm-down static's own name is still a second pose, of the report and of u
    from exubio.trust.angle_uncertainty import ellipsoid_from_skin

    cal, report = calibrate_model(wrong, protocol, still(0, "down"), more_statics=[prepare_targets(still(top, "down"), protocol)])
    assert list(report.ellipsoid_poses_mm) == ["down", "down (2)"]
    assert ellipsoid_from_skin(cal.metadata["calibration"]) and ellipsoid_from_skin(report)


@pytest.mark.parametrize("what, inject", [
    ("calibration residual", "residuals"),
    ("static pose coordinate gh_flexion", "pose"),
])
def test_a_nan_anywhere_in_the_calibration_is_an_error_naming_it(generic, calibrated, monkeypatch, what, inject):
    """A calibration whose numbers went NaN printed "calibration residual: mean nan mm" and carried on
    (PF then diverged at t = 0): now the first non-finite number is named in a ReconstructionError."""
    import exubio.calibration.core as core
    from exubio.errors import ReconstructionError

    model, protocol = generic
    traj = calibrated[2].trajectories  # the static trial that calibrates cleanly (fixture)
    if inject == "residuals":  # the LS solve of the calibration frames gives NaN for one marker
        original = core._calibration_residuals

        def nan_residual(*args, **kwargs):
            r = original(*args, **kwargs)
            r[3] = np.nan
            return r

        monkeypatch.setattr(core, "_calibration_residuals", nan_residual)
        name = protocol.markers[3].name
        match = rf"marker {name}'s calibration residual is not a finite number"
    else:  # the fitted static pose has a NaN coordinate
        original_fit = core._robust_fit

        def nan_pose(*args, **kwargs):
            q, factors, robust, outcome = original_fit(*args, **kwargs)
            q = q.copy()
            q[model.coordinate_names.index("gh_flexion")] = np.nan
            return q, factors, robust, outcome

        monkeypatch.setattr(core, "_robust_fit", nan_pose)
        match = "static pose coordinate gh_flexion is not a finite number"
    with pytest.raises(ReconstructionError, match=rf"calibration on .*frames 0:20: the {match}"):
        calibrate_model(model, protocol, traj, frames=slice(0, 20))
    assert what in match
