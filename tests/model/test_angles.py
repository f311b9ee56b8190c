"""ISB angles (exubio.model.angles): Euler/Cardan round trips, gimbal lock, anatomical frames, known
rotations giving known ISB angles, and the sign conventions of Ludewig et al. 2009."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from exubio.model.angles import (
    ISB_SEQUENCES,
    anatomical_frames,
    euler_angles,
    humerothoracic_elevation,
    isb_angles,
    rotation_from_euler,
)
from exubio.errors import InputError
from exubio.model.kinematics import axis_rotation
from exubio.synth.rhythm import scapula_isb_angles
from exubio.synth.simulate import simulate_trial

TAIT_BRYAN = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
PROPER = ["XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ"]
X, Y, Z = np.eye(3)


def _random_angles(rng, n, proper, negative=False):
    a = rng.uniform(-np.pi + 1e-3, np.pi - 1e-3, (n, 3))
    if proper:
        a[:, 1] = rng.uniform(1e-3, np.pi - 1e-3, n) * (-1 if negative else 1)
    else:
        a[:, 1] = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, n)
    return a


# --------------------------------------------------------------------------------------------
# Euler / Cardan
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seq", TAIT_BRYAN + PROPER)
def test_round_trip_every_sequence(seq):
    rng = np.random.default_rng(sum(map(ord, seq)))
    a = _random_angles(rng, 500, seq[0] == seq[2])
    R = rotation_from_euler(a, seq)
    np.testing.assert_allclose(euler_angles(R, seq), a, atol=1e-10)


@pytest.mark.parametrize("seq", PROPER)
def test_proper_euler_negative_middle_branch(seq):
    rng = np.random.default_rng(7)
    a = _random_angles(rng, 300, True, negative=True)
    R = rotation_from_euler(a, seq)
    np.testing.assert_allclose(euler_angles(R, seq, negative_middle=True), a, atol=1e-10)
    # the default branch describes the same rotation with the middle angle positive
    b = euler_angles(R, seq)
    assert np.all(b[:, 1] > 0)
    np.testing.assert_allclose(rotation_from_euler(b, seq), R, atol=1e-12)


def test_sequence_is_intrinsic():
    a = np.radians([30.0, -20.0, 10.0])
    R = rotation_from_euler(a, "Y-X'-Z''")
    expected = axis_rotation(Y, a[0]) @ axis_rotation(X, a[1]) @ axis_rotation(Z, a[2])
    np.testing.assert_allclose(R, expected, atol=1e-15)


@pytest.mark.parametrize("seq,middle", [("YXZ", np.pi / 2), ("XZY", -np.pi / 2), ("YXY", 0.0), ("YXY", np.pi)])
def test_gimbal_lock_puts_everything_in_the_third_angle(seq, middle):
    R = rotation_from_euler(np.array([0.4, middle, -0.1]), seq)
    a = euler_angles(R, seq)
    assert a[0] == 0.0
    np.testing.assert_allclose(abs(a[1]), abs(middle), atol=1e-7)
    np.testing.assert_allclose(rotation_from_euler(a, seq), R, atol=1e-12)
    assert np.all(np.isfinite(a))


def test_near_gimbal_lock_still_reconstructs_the_rotation():
    for eps in (1e-4, 1e-6, 1e-8):
        a = np.array([0.3, np.pi / 2 - eps, 0.2])
        R = rotation_from_euler(a, "YXZ")
        np.testing.assert_allclose(rotation_from_euler(euler_angles(R, "YXZ"), "YXZ"), R, atol=1e-7)


@pytest.mark.parametrize("bad", ["XXY", "XY", "ABC", "XYZX", "Y-Y'-Z"])
def test_bad_sequence_raises(bad):
    with pytest.raises(InputError, match="rotation sequence"):
        euler_angles(np.eye(3), bad)


def test_bad_shapes_raise():
    with pytest.raises(InputError):
        euler_angles(np.eye(4), "XYZ")
    with pytest.raises(InputError):
        rotation_from_euler(np.zeros(2), "XYZ")


# --------------------------------------------------------------------------------------------
# Anatomical frames
# --------------------------------------------------------------------------------------------
def test_anatomical_frames_orthonormal_right_handed(model):
    frames = anatomical_frames(model)
    assert set(frames) == {"thorax", "clavicle", "scapula", "humerus"}
    for name, A in frames.items():
        np.testing.assert_allclose(A.T @ A, np.eye(3), atol=1e-12, err_msg=name)
        assert np.linalg.det(A) == pytest.approx(1.0, abs=1e-12), name


def test_anatomical_frames_follow_wu_2005(model):
    A = anatomical_frames(model)
    pts = {s.name: s.points for s in model.segments}
    # clavicle Z from SC to AC, X perpendicular to thorax Y and pointing forward
    z = pts["clavicle"]["AC"] - pts["clavicle"]["SC"]
    np.testing.assert_allclose(A["clavicle"][:, 2], z / np.linalg.norm(z), atol=1e-12)
    assert abs(A["clavicle"][:, 0] @ Y) < 1e-12 and A["clavicle"][0, 0] > 0
    # scapula Z from TS to AA, X normal to AI-AA-TS and anterior
    sc = pts["scapula"]
    z = sc["AA"] - sc["TS"]
    np.testing.assert_allclose(A["scapula"][:, 2], z / np.linalg.norm(z), atol=1e-12)
    for a, b in (("AI", "AA"), ("AI", "TS")):
        assert abs(A["scapula"][:, 0] @ (sc[b] - sc[a])) < 1e-12
    assert A["scapula"][0, 0] > 0
    # humerus Y from the elbow centre to GH, X normal to the plane EL-EM-GH and anterior
    h = pts["humerus"]
    y = h["GH"] - 0.5 * (h["EL"] + h["EM"])
    np.testing.assert_allclose(A["humerus"][:, 1], y / np.linalg.norm(y), atol=1e-9)
    assert abs(A["humerus"][:, 0] @ (h["EL"] - h["EM"])) < 1e-9
    assert A["humerus"][0, 0] > 0


def test_humerus_frame_from_registered_elbow_points(model):
    """A calibrated model registers EJC and EL, not EM: the frame uses EJC and EL - EJC."""
    hum = model.segment("humerus")
    pts = dict(hum.points)
    pts["EM"] = pts["EM"] + np.array([0.0, 0.03, 0.0])  # an unregistered EM off the plane
    moved = dataclasses.replace(model, segments=tuple(
        dataclasses.replace(s, points=pts) if s.name == "humerus" else s for s in model.segments))
    np.testing.assert_allclose(anatomical_frames(moved)["humerus"], anatomical_frames(model)["humerus"], atol=1e-12)


# --------------------------------------------------------------------------------------------
# Known motions give known ISB angles
# --------------------------------------------------------------------------------------------
def _with_segment_rotation(kin, segment, R_seg):
    """Coordinates of the reference posture with one segment's global orientation replaced."""
    model = kin.model
    R, _ = kin.poses(np.zeros(model.n_coordinates))
    R = R.copy()
    R[model.segment_index(segment)] = R_seg
    for child in model.segments[model.segment_index(segment) + 1:]:  # children keep their joint angles
        R[model.segment_index(child.name)] = R_seg @ R[model.segment_index(child.name)]
    return kin.coordinates_from_rotations(R)


def test_coronal_abduction_with_the_scapula_fixed(model, kin):
    ref = isb_angles(model, np.zeros(model.n_coordinates))
    ht0 = humerothoracic_elevation(model, np.zeros(model.n_coordinates))
    q = _with_segment_rotation(kin, "humerus", axis_rotation(-X, np.radians(60.0)))
    ang = isb_angles(model, q)
    # HT elevation: 60 deg more than in the reference posture (where the ISB humerus axis leans
    # 0.9 deg medially: the generic elbow centre is 5 mm lateral of GH), plane of elevation 0
    assert np.degrees(ht0) == pytest.approx(0.88, abs=0.01)
    assert np.degrees(humerothoracic_elevation(model, q)) == pytest.approx(60.0 + np.degrees(ht0), abs=1e-9)
    np.testing.assert_allclose(np.degrees(ang["HT"][:2]), [0.0, -60.0 - np.degrees(ht0)], atol=1e-9)
    # GH: the humerus turns by exactly 60 deg relative to the fixed scapula, mostly as (negative)
    # X angle (the ISB scapula frame is internally rotated from the thorax's, so not all of it)
    from exubio.model.angles import rotation_from_euler

    R0, R1 = rotation_from_euler(ref["GH"], "XZY"), rotation_from_euler(ang["GH"], "XZY")
    turn = np.degrees(np.arccos(np.clip((np.trace(R1 @ R0.T) - 1.0) / 2.0, -1.0, 1.0)))
    assert turn == pytest.approx(60.0, abs=1e-9)
    assert np.degrees(ang["GH"][0] - ref["GH"][0]) < -45.0
    for joint in ("SC", "AC", "ST"):
        np.testing.assert_allclose(ang[joint], ref[joint], atol=1e-12)


def test_abduction_about_the_scapula_x_axis_is_exactly_the_gh_x_angle(model, kin):
    A = anatomical_frames(model)
    ref = isb_angles(model, np.zeros(model.n_coordinates))
    axis = -(A["scapula"][:, 0])  # the scapula is in its reference orientation: its frame is A
    q = _with_segment_rotation(kin, "humerus", axis_rotation(axis, np.radians(45.0)))
    gh = isb_angles(model, q)["GH"]
    np.testing.assert_allclose(np.degrees(gh - ref["GH"]), [-45.0, 0.0, 0.0], atol=1e-9)


def test_forward_flexion_plane_of_elevation_is_90(model, kin):
    q = _with_segment_rotation(kin, "humerus", axis_rotation(Z, np.radians(90.0)))
    ht = np.degrees(isb_angles(model, q)["HT"])
    assert ht[0] == pytest.approx(90.0, abs=1.0)
    assert ht[1] == pytest.approx(-90.0, abs=1.0)


def test_clavicle_elevation_and_retraction_signs(model, kin):
    A = anatomical_frames(model)["clavicle"]
    ref = isb_angles(model, np.zeros(model.n_coordinates))["SC"]
    # raise the lateral end (rotation about the clavicle's own -X axis): X' angle decreases
    q = _with_segment_rotation(kin, "clavicle", axis_rotation(-A[:, 0], np.radians(10.0)))
    np.testing.assert_allclose(np.degrees(isb_angles(model, q)["SC"] - ref), [0.0, -10.0, 0.0], atol=1e-9)
    # move the lateral end backwards (retraction, about -Y of the thorax): Y angle decreases
    q = _with_segment_rotation(kin, "clavicle", axis_rotation(-Y, np.radians(15.0)))
    assert np.degrees(isb_angles(model, q)["SC"][0] - ref[0]) == pytest.approx(-15.0, abs=1e-9)


def test_shapes_and_humerothoracic_elevation_consistency(model):
    q = np.random.default_rng(3).normal(scale=0.3, size=(7, model.n_coordinates))
    ang = isb_angles(model, q)
    assert set(ang) == set(ISB_SEQUENCES)
    for v in ang.values():
        assert v.shape == (7, 3)
    np.testing.assert_allclose(humerothoracic_elevation(model, q), -ang["HT"][:, 1], atol=1e-9)
    one = isb_angles(model, q[2])
    for k in ang:
        assert one[k].shape == (3,)
        # equal up to whole turns (isb_angles unwraps along the frames of a sequence)
        np.testing.assert_allclose(np.angle(np.exp(1j * (one[k] - ang[k][2]))), 0.0, atol=1e-9)


def test_isb_angles_reproduce_the_rotations(model, kin):
    """Decomposing and recomposing gives the relative anatomical rotations back."""
    q = np.random.default_rng(5).normal(scale=0.4, size=(20, model.n_coordinates))
    A = anatomical_frames(model)
    R, _ = kin.poses(q)
    g = {s: R[:, model.segment_index(s)] @ A[s] for s in A}
    ang = isb_angles(model, q, unwrap=False)
    for joint, (a, b) in {"SC": ("thorax", "clavicle"), "ST": ("thorax", "scapula"), "GH": ("scapula", "humerus"),
                          "HT": ("thorax", "humerus"), "AC": ("clavicle", "scapula")}.items():
        rel = np.swapaxes(g[a], -1, -2) @ g[b]
        np.testing.assert_allclose(rotation_from_euler(ang[joint], ISB_SEQUENCES[joint]), rel, atol=1e-9)


def test_st_angles_match_the_simulation_definition(model, kin):
    q = np.random.default_rng(11).normal(scale=0.2, size=(10, model.n_coordinates))
    np.testing.assert_allclose(isb_angles(model, q, unwrap=False)["ST"], scapula_isb_angles(kin, q), atol=1e-12)


def test_signs_during_simulated_abduction_match_ludewig(model):
    """During arm raising Ludewig's ST upward rotation (X') and GH elevation (X) become more
    negative, ST posterior tilt (Z'') and SC posterior rotation (Z'') more positive, and the
    clavicle retracts (SC Y more negative). The simulated abduction follows that rhythm."""
    trial = simulate_trial(model, "abduction", duration_s=2.5, rate_hz=20)  # 10 -> 120 deg
    ang = {k: np.degrees(v) for k, v in isb_angles(model, trial.q_true).items()}
    ht = np.degrees(humerothoracic_elevation(model, trial.q_true))
    lo, hi = int(np.argmin(ht)), int(np.argmax(ht))
    assert ht[hi] - ht[lo] > 100
    assert ang["ST"][hi, 1] < ang["ST"][lo, 1] - 10  # upward rotation: negative
    assert ang["ST"][hi, 2] > ang["ST"][lo, 2] + 10  # posterior tilt: positive
    assert ang["GH"][hi, 0] < ang["GH"][lo, 0] - 60  # GH elevation: negative
    assert ang["SC"][hi, 0] < ang["SC"][lo, 0] - 10  # retraction: negative
    assert ang["SC"][hi, 2] > ang["SC"][lo, 2] + 10  # posterior rotation: positive
    assert abs(ang["HT"][hi, 0]) < 5  # coronal plane: plane of elevation ~0
