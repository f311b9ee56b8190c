"""Coordinates a marker set cannot observe can be held at 0 by the protocol (`hold:`), in both methods."""
import dataclasses

import numpy as np
import pytest

from exubio.backend.exudyn_system import PFSystem, SpringSet
from exubio.errors import ModelError, ProtocolError
from exubio.model.kinematics import Kinematics
from exubio.protocol.bind import bind, tracked_points
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import DEFAULT_PROTOCOL, load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.protocol.load import load_protocol
from exubio.synth.simulate import Motion, simulate_trial

pytestmark = pytest.mark.exudyn


@pytest.fixture(scope="module")
def setup():
    model, protocol = load_model_and_protocol()
    return model, protocol


def test_held_coordinates_stay_at_zero_in_both_methods(setup):
    model, protocol = setup
    held = ("sc_posterior_rotation", "wrist_radial_deviation")
    prot = dataclasses.replace(protocol, held_coordinates=held)
    trial = simulate_trial(model, Motion.FLEXION, duration_s=2.0, rate_hz=100.0)
    targets = prepare_targets(trial.trajectories, prot)
    names = model.coordinate_names
    idx = [names.index(h) for h in held]
    pf = reconstruct(model, prot, targets, method="pf")
    ls = reconstruct(model, prot, targets, method="ls")
    for recon in (pf, ls):
        assert np.abs(recon.q_rad[:, idx]).max() < 1e-6
        assert np.abs(recon.qd_rad_s[:, idx]).max() < 1e-4  # PF: held by its joint to Exudyn's tolerance
        assert np.abs(recon.constraint).max() < 1e-9
    free = [i for i in range(len(names)) if i not in idx]
    rmse = np.sqrt(np.mean(np.rad2deg(pf.q_rad[:, free] - ls.q_rad[:, free]) ** 2, axis=0))
    assert rmse.max() < 0.5


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_exudyn_joints_with_a_held_last_coordinate_match_the_numpy_kinematics(setup, seed):
    model, protocol = setup
    kin = Kinematics(model)
    names = model.coordinate_names
    rng = np.random.default_rng(seed)
    q = rng.uniform(-0.6, 0.6, kin.n_coordinates)
    held = [names.index("sc_posterior_rotation"), names.index("wrist_radial_deviation")]
    pts = tracked_points(kin, protocol)
    springs = SpringSet.from_points(pts, stiffness_n_per_m=np.full(len(pts.names), 1500.0),
                                    damping_ns_per_m=np.full(len(pts.names), 300.0))
    bound = bind(model, dataclasses.replace(protocol, held_coordinates=tuple(names[j] for j in held)))
    system = PFSystem(bound, springs=springs, q0=q)
    assert np.abs(system.model_points(q) - kin.points(q, pts)).max() < 1e-9


def test_hold_names_must_be_model_coordinates(tmp_path, setup):
    model, _ = setup
    text = DEFAULT_PROTOCOL.read_text(encoding="utf-8")
    assert "\n# hold: none" in text  # the shipped protocol holds nothing (see the file)
    text = text.replace("\n# hold: none", "\nhold: [sc_posterior_rotaton]\n# hold: none", 1)
    bad = tmp_path / "p.yaml"
    bad.write_text(text, encoding="utf-8")
    with pytest.raises(ProtocolError, match="sc_posterior_rotaton.*sc_posterior_rotation"):
        load_protocol(bad, segments=model.segment_names, model_points={s.name: dict(s.points) for s in model.segments},
                      coordinates=model.coordinate_names)


def test_only_the_last_coordinate_of_a_joint_can_be_held(setup):
    model, protocol = setup
    kin = Kinematics(model)
    pts = tracked_points(kin, protocol)
    springs = SpringSet.from_points(pts, stiffness_n_per_m=np.full(len(pts.names), 1500.0),
                                    damping_ns_per_m=np.full(len(pts.names), 300.0))
    with pytest.raises(ModelError, match="last coordinate"):
        PFSystem(bind(model, dataclasses.replace(protocol, held_coordinates=("sc_protraction",))), springs=springs,
                 q0=np.zeros(13))
