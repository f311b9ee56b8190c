"""Left arm and both arms: a left arm is mirrored through the thorax's sagittal plane onto the
right-arm model (protocol ``side: left``), so a right-arm trial mirrored and relabelled as a left
arm gives the same angles; a trial with both arms is reconstructed as two chains, one protocol per
arm, and each recovers its own truth."""
from __future__ import annotations


import numpy as np
import pytest
import yaml

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.angles import anatomical_table
from exubio.io.results import read_angles_csv
from exubio.model.load import load_model
from exubio.run.pipeline import reconstruct
from exubio.prep.targets import prepare_targets
from exubio.protocol.load import read_protocol_mapping
from exubio.io.resources import shipped_file
from exubio.synth.simulate import simulate_trial
from exubio.types import Trajectories

pytestmark = pytest.mark.exudyn

BASE = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols")
MIRROR = np.diag([1.0, 1.0, -1.0])


def _arm_protocol(tmp_path, side: str, prefix: str):
    """upper_limb_21 for one arm whose arm markers are labelled ``prefix + name``."""
    data = read_protocol_mapping(BASE)
    data.pop("extends", None)
    data["name"] = f"upper_limb_21_{side}"
    data["side"] = side
    for name, spec in data["markers"].items():
        if prefix and spec.get("segment") != "thorax":
            spec["aliases"] = [prefix + name] + [prefix + a for a in spec.get("aliases", [])]
    path = tmp_path / f"{side}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _mirrored(traj: Trajectories, sim, prefix: str, keep=()) -> Trajectories:
    """The trial mirrored through its thorax's sagittal plane (in the lab: p -> o + R S R^T (p - o)),
    arm markers relabelled with ``prefix``."""
    R, o = sim.lab_rotation, sim.lab_origin_m
    pos = (traj.positions_m - o) @ R @ MIRROR @ R.T + o
    labels = tuple(lb if lb in keep else prefix + lb for lb in traj.labels)
    return Trajectories(labels=labels, positions_m=pos, rate_hz=traj.rate_hz, time_s=traj.time_s,
                        source="mirrored", units_in_file="m")


THORAX = ("IJ", "PX", "C7", "T8", "T10", "XYP", "MAN")


@pytest.mark.parametrize("method", ["ls", "pf"])
def test_mirrored_right_arm_read_as_left_gives_the_same_angles(tmp_path, method):
    model = load_model()
    sim = simulate_trial(model, "abduction", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, sta_mm=5.0, seed=4)
    right = reconstruct(model, _load(tmp_path, "right", ""), prepare_targets(sim.trajectories, _load(tmp_path, "right", "")),
                        method=method)
    left_protocol = _load(tmp_path, "left", "L_")
    left_traj = _mirrored(sim.trajectories, sim, "L_", keep=THORAX)
    left = reconstruct(model, left_protocol, prepare_targets(left_traj, left_protocol), method=method)
    assert np.abs(np.degrees(left.q_rad - right.q_rad)).max() <= 1e-6


def _load(tmp_path, side, prefix):
    from exubio.run.inputs import protocol_for_model

    return protocol_for_model(load_model(), _arm_protocol(tmp_path, side, prefix))


def test_two_arm_trial_recovers_both_truths(tmp_path):
    model = load_model()
    a = simulate_trial(model, "abduction", duration_s=2.0, rate_hz=50.0, seed=5)
    b = simulate_trial(model, "flexion", duration_s=2.0, rate_hz=50.0, seed=6)
    assert np.allclose(a.lab_rotation, b.lab_rotation) and np.allclose(a.lab_origin_m, b.lab_origin_m)
    keep = [i for i, lb in enumerate(a.trajectories.labels) if lb in THORAX]
    arm_a = [i for i, lb in enumerate(a.trajectories.labels) if lb not in THORAX]
    left = _mirrored(b.trajectories, b, "L_", keep=THORAX)
    arm_b = [i for i, lb in enumerate(left.labels) if lb.startswith("L_")]
    labels = tuple(a.trajectories.labels[i] for i in keep) + tuple("R_" + a.trajectories.labels[i] for i in arm_a) \
        + tuple(left.labels[i] for i in arm_b)
    pos = np.concatenate([a.trajectories.positions_m[:, keep], a.trajectories.positions_m[:, arm_a],
                          left.positions_m[:, arm_b]], axis=1)
    both = Trajectories(labels=labels, positions_m=pos, rate_hz=50.0, time_s=a.time_s, source="two arms",
                        units_in_file="m")
    c3d = write_c3d(tmp_path / "both.c3d", both)
    out = tmp_path / "out"
    code = main(["-q", "reconstruct", str(c3d), "--method", "ls", "--no-report", "--out", str(out),
                 "--protocol", str(_arm_protocol(tmp_path, "right", "R_")),
                 "--protocol", str(_arm_protocol(tmp_path, "left", "L_"))])
    assert code in (0, 1)  # the verdict may be "check" on a 2-s trial; the angles are what is tested
    for side, sim in (("right", a), ("left", b)):
        _, names, ang = read_angles_csv(out / side / "both.ls.csv")
        _, truth = anatomical_table(load_model(), sim.q_true)
        err = np.degrees(np.abs(np.angle(np.exp(1j * (ang - truth)))))
        from exubio.io.results import read_npz_arrays

        status = read_npz_arrays(out / side / "both.ls.npz", ("angle_status",))["angle_status"]
        measured = status == 0  # per frame: the gimbal margin and the uncertainty bound take some frames
        assert int(measured.any(axis=0).sum()) >= 18
        assert np.where(measured, err, 0.0).max() < 0.5, (side, names[int(np.argmax(np.where(measured, err, 0).max(axis=0)))])
        head = (out / side / "both.ls.csv").read_text(encoding="utf-8").splitlines()
        assert any(("LEFT arm" in ln) == (side == "left") for ln in head if ln.startswith("#") and "arm" in ln)


def test_two_protocols_for_one_arm_are_refused(tmp_path, capsys):
    p = _arm_protocol(tmp_path, "right", "R_")
    code = main(["-q", "reconstruct", str(tmp_path / "missing.c3d"), "--method", "ls", "--out", str(tmp_path / "o"),
                 "--protocol", str(p), "--protocol", str(p)])
    assert code == 2 and "both for the right arm" in capsys.readouterr().err


def test_side_must_be_right_or_left(tmp_path):
    from exubio.errors import ProtocolError
    from exubio.run.inputs import protocol_for_model

    data = read_protocol_mapping(BASE)
    data["side"] = "both"
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ProtocolError, match="side"):
        protocol_for_model(load_model(), path)
