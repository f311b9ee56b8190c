"""The live loop's one-frame kernels against the batch functions they stand in for: FrameAngles
(exubio.model.frame_angles) gives exubio.model.angles.isb_table's angles (its numpy reference bitwise,
its compiled kernel to round-off), FrameInverse (exubio.model.frame_kinematics)
coordinates_from_rotations' coordinates to round-off, the causal thorax frame of one frame
exubio.prep.thorax.thorax_frame's to round-off: random postures over and beyond every range, at the
range limits and at the gimbal locks."""
import numpy as np

from exubio.model.angles import anatomical_frames, isb_table
from exubio.model.frame_angles import FrameAngles
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model


def test_frame_angles_are_isb_tables():
    model = load_model()
    kin = Kinematics(model)
    frames = anatomical_frames(model)
    angles = FrameAngles(model, frames)
    lo, hi = np.clip(model.coordinate_ranges_rad.T, -np.pi, np.pi)  # a half turn each way where unbounded
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
        assert np.array_equal(angles.numpy(R), want)  # the numpy reference: isb_table's operations
        got = angles(R)  # the compiled kernel: to round-off (an angle at -pi may come out at +pi)
        assert got.shape == want.shape == (15,)
        diff = np.abs(got - want)
        assert np.minimum(diff, 2 * np.pi - diff).max() < 1e-12, diff.max()


def test_frame_inverse_is_coordinates_from_rotations():
    """FrameInverse (the live loop's inverse map of one frame) gives coordinates_from_rotations'
    coordinates: postures inside and beyond the ranges, at a spherical joint's gimbal lock, with
    and without the previous frame's coordinates."""
    from exubio.model.frame_kinematics import FrameInverse

    model = load_model()
    kin = Kinematics(model)
    inverse = FrameInverse(kin)
    lo, hi = np.clip(model.coordinate_ranges_rad.T, -np.pi, np.pi)  # a half turn each way where unbounded
    rng = np.random.default_rng(3)
    qs = [np.zeros(len(lo)), lo, hi] + list(rng.uniform(lo, hi, size=(300, len(lo))))
    qs += list(rng.uniform(-np.pi, np.pi, size=(200, len(lo))))
    names = model.coordinate_names
    for q in qs[:30]:  # the middle angle of each spherical joint at +-90 deg
        for name in ("sc_elevation", "ac_upward_rotation", "gh_internal_rotation"):
            locked = q.copy()
            locked[names.index(name)] = rng.choice([-1, 1]) * np.pi / 2
            qs.append(locked)
    middle = [names.index(n) for n in ("sc_elevation", "ac_upward_rotation", "gh_internal_rotation")]
    for q in qs:
        R = kin.frames(q).R
        # FrameInverse is the compiled kernel (exubio.model.kernels) that sums in its own order: R's
        # round-off (1e-16) reaches the first and last angle of a spherical joint times 1 / cos of
        # its middle angle (a random posture 5e-4 deg from the lock: 2e-11 rad)
        tol = 1e-12 + 1e-15 / max(np.abs(np.cos(q[middle])).min(), 1e-5)  # at the lock both take its branch
        for prev in (None, q + rng.normal(scale=0.05, size=q.shape)):
            want = kin.coordinates_from_rotations_numpy(R, q_previous=prev)
            got = inverse(R, prev)
            assert np.array_equal(kin.coordinates_from_rotations(R, q_previous=prev), got)  # the same kernel
            assert np.abs(got - want).max() <= tol, (np.degrees(q), got - want)


def test_thorax_frame_of_one_frame_is_thorax_frame():
    """The live loop's thorax frame of one frame (plain floats) is exubio.prep.thorax.thorax_frame's
    to round-off, and it refuses the same degenerate landmarks."""
    import pytest

    from exubio.errors import InputError
    from exubio.prep.thorax import thorax_frame
    from exubio.run.live.causal import thorax_frame_one

    rng = np.random.default_rng(11)
    base = np.array([[0.0, 0.0, 0.0], [0.02, -0.18, 0.0], [-0.12, 0.02, 0.0], [-0.14, -0.16, 0.0]])  # IJ PX C7 T8
    for _ in range(300):
        rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        lm = (base + rng.normal(scale=0.02, size=base.shape)) @ rot.T + rng.normal(size=3)
        R, origin = thorax_frame(*lm)
        R1, origin1 = thorax_frame_one(*lm)
        assert np.abs(R1 - R).max() < 1e-14 and np.array_equal(origin1, origin)
    collinear = np.array([[0.0, 0.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.1, 0.0], [0.0, -0.3, 0.0]])
    with pytest.raises(InputError):
        thorax_frame(*collinear)
    assert thorax_frame_one(*collinear) is None
