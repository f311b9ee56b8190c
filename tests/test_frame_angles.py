"""exubio.model.frame_angles.FrameAngles (the live loop's ISB angles of one frame) gives bitwise the
angles of exubio.model.angles.isb_table, whose arithmetic it repeats with its set-up done once: at
random postures over the whole range of every coordinate, at the range limits and near the gimbal
locks of the GH and HT sequences."""
import numpy as np

from exubio.model.angles import anatomical_frames, isb_table
from exubio.model.frame_angles import FrameAngles
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model


def test_frame_angles_are_isb_tables_bitwise():
    model = load_model()
    kin = Kinematics(model)
    frames = anatomical_frames(model)
    angles = FrameAngles(model, frames)
    lo, hi = model.coordinate_ranges_rad.T
    rng = np.random.default_rng(7)
    qs = [np.zeros(len(lo)), lo, hi] + list(rng.uniform(lo, hi, size=(300, len(lo))))
    qs += list(rng.uniform(-np.pi, np.pi, size=(100, len(lo))))  # beyond the ranges too
    gh = [model.coordinate_names.index(n) for n in ("gh_abduction", "gh_flexion")]
    for q in qs[:20]:  # the humerus along the thorax Y axis: HT near its gimbal lock
        locked = q.copy()
        locked[gh] = 0.0
        qs.append(locked)
    for q in qs:
        R = kin.frames(q).R
        want = isb_table(model, q, kinematics=kin, frames=frames, rotations=R)[1]
        got = angles(R)
        assert got.shape == want.shape == (15,)
        assert np.array_equal(got, want), np.abs(got - want).max()


def test_frame_inverse_is_coordinates_from_rotations():
    """FrameInverse (the live loop's inverse map of one frame) gives coordinates_from_rotations'
    coordinates: postures inside and beyond the ranges, at a spherical joint's gimbal lock, with
    and without the previous frame's coordinates."""
    from exubio.model.frame_kinematics import FrameInverse

    model = load_model()
    kin = Kinematics(model)
    inverse = FrameInverse(kin)
    lo, hi = model.coordinate_ranges_rad.T
    rng = np.random.default_rng(3)
    qs = [np.zeros(len(lo)), lo, hi] + list(rng.uniform(lo, hi, size=(300, len(lo))))
    qs += list(rng.uniform(-np.pi, np.pi, size=(200, len(lo))))
    names = model.coordinate_names
    for q in qs[:30]:  # the middle angle of each spherical joint at +-90 deg
        for name in ("sc_elevation", "ac_upward_rotation", "gh_internal_rotation"):
            locked = q.copy()
            locked[names.index(name)] = rng.choice([-1, 1]) * np.pi / 2
            qs.append(locked)
    worst, same = 0.0, 0
    for q in qs:
        R = kin.frames(q).R
        for prev in (None, q + rng.normal(scale=0.05, size=q.shape)):
            want = kin.coordinates_from_rotations(R, q_previous=prev)
            got = inverse(R, prev)
            worst = max(worst, float(np.abs(got - want).max()))
            same += np.array_equal(got, want)
    assert worst < 1e-12, worst
    assert same > 0.9 * 2 * len(qs)  # mostly bitwise the same (a batched einsum may sum in another order)


def test_frame_forward_is_kinematics_frames_bitwise():
    from exubio.model.frame_kinematics import FrameForward

    model = load_model()
    kin = Kinematics(model)
    forward = FrameForward(kin)
    lo, hi = model.coordinate_ranges_rad.T
    for q in np.random.default_rng(5).uniform(lo - 1, hi + 1, size=(200, len(lo))):
        R, p = forward(q)
        fr = kin.frames(q)
        assert np.array_equal(R, fr.R) and np.array_equal(p, fr.p)
