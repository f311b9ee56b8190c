"""Functional joint centres and axes (exubio.calibration.functional, .cluster) on simulated
segments with a known centre / axis: SCoRE, SARA, the cluster pose fit and the path-axis fit."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from exubio.calibration.cluster import cluster_poses, cluster_reference
from exubio.calibration.functional import FunctionalAxis, FunctionalCentre, path_axis, relative_rotation_range_deg, sara, score
from exubio.errors import InputError

NOISE_M = 1e-3
# segment 1 (scapula-like cluster) and segment 2 (humerus-like cluster, 5-16 cm from the centre)
REF1 = np.array([[0.05, 0.0, 0.0], [0.0, 0.06, 0.0], [0.0, 0.0, 0.07], [0.04, 0.04, -0.03]])
REF2 = np.array([[0.03, 0.05, 0.02], [-0.03, 0.10, 0.0], [0.0, 0.15, 0.04], [0.02, 0.12, -0.04]])
C1 = np.array([0.02, -0.03, 0.01])  # joint centre in segment 1's frame
C2 = np.array([0.0, 0.15, 0.01])  # the same point in segment 2's frame
AXIS = np.array([1.0, 0.3, -0.2]) / np.linalg.norm([1.0, 0.3, -0.2])  # hinge axis, segment 1's frame


def _simulate(seed, n=400, rel_amp_deg=(50.0, 50.0, 50.0), prox_amp_deg=0.0, hinge_axis=None, noise=NOISE_M):
    """Markers of two clusters joined at C1 (seg 1) = C2 (seg 2), with 1 mm noise.

    Relative rotation: a rotation vector uniform in +-rel_amp_deg per component (ball joint), or
    about ``hinge_axis`` (segment 1's frame) by an angle uniform in +-rel_amp_deg[0] (hinge).
    The proximal segment rotates by +-prox_amp_deg per component and translates by +-2 cm."""
    rng = np.random.default_rng(seed)
    Rp = Rotation.from_rotvec(np.deg2rad(rng.uniform(-1, 1, (n, 3)) * prox_amp_deg))
    t1 = rng.uniform(-0.02, 0.02, (n, 3)) if prox_amp_deg else np.zeros((n, 3))
    if hinge_axis is None:
        Rrel = Rotation.from_rotvec(np.deg2rad(rng.uniform(-1, 1, (n, 3)) * np.asarray(rel_amp_deg)))
    else:
        theta = np.deg2rad(rng.uniform(-1, 1, n) * rel_amp_deg[0])
        Rrel = Rotation.from_rotvec(theta[:, None] * hinge_axis)
    R1 = Rp.as_matrix()
    R2 = (Rp * Rrel).as_matrix()
    t2 = np.einsum("nab,b->na", R1, C1) + t1 - np.einsum("nab,b->na", R2, C2)
    m1 = np.einsum("nab,kb->nka", R1, REF1) + t1[:, None] + rng.normal(0, noise, (n, 4, 3))
    m2 = np.einsum("nab,kb->nka", R2, REF2) + t2[:, None] + rng.normal(0, noise, (n, 4, 3))
    return m1, m2, (R1, t1, R2, t2)


def _poses(m1, m2):
    R1, t1, _ = cluster_poses(REF1, m1)
    R2, t2, _ = cluster_poses(REF2, m2)
    return R1, t1, R2, t2


def _line_distance(point, on_line, direction):
    d = point - on_line
    return float(np.linalg.norm(d - (d @ direction) * direction))


def _angle_deg(a, b):
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b)))))


# --------------------------------------------------------------------------------------------
# cluster poses
# --------------------------------------------------------------------------------------------
def test_cluster_poses_recovers_exact_poses_and_rms():
    m1, _, (R1, t1, _, _) = _simulate(0, n=50, noise=0.0)
    R, t, rms = cluster_poses(REF1, m1)
    assert np.allclose(R, R1, atol=1e-12)
    assert np.allclose(t, t1, atol=1e-12)
    assert np.all(rms < 1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_cluster_poses_noise_rms_and_missing_frames():
    m1, _, (R1, t1, _, _) = _simulate(1, n=300)
    m1[5, :2] = np.nan  # 2 markers left: no pose
    m1[6, 0] = np.nan  # 3 left: pose
    m1[7] = np.nan
    R, t, rms = cluster_poses(REF1, m1)
    assert np.isnan(R[5]).all() and np.isnan(t[5]).all() and np.isnan(rms[5])
    assert np.isnan(R[7]).all()
    assert np.isfinite(R[6]).all()
    good = np.isfinite(rms)
    assert good.sum() == 298
    # 4 markers, 3 coordinates each, 6 pose parameters fitted: E[rms^2] = sigma^2 (12 - 6) / 4
    assert np.sqrt(np.mean(rms[good] ** 2)) == pytest.approx(NOISE_M * math.sqrt(6 / 4), rel=0.1)
    ang = Rotation.from_matrix(np.einsum("nji,njk->nik", R[good], R1[good])).magnitude()
    # ~1 mm noise on a cluster ~5 cm across: about 1-2 deg of orientation error
    assert np.degrees(np.sqrt(np.mean(ang ** 2))) < 2.5


def test_cluster_poses_rejects_bad_reference():
    with pytest.raises(InputError, match="collinear"):
        cluster_poses(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), np.zeros((4, 3, 3)))
    with pytest.raises(InputError, match="reference markers but"):
        cluster_poses(REF1, np.zeros((4, 3, 3)))


def test_cluster_reference_is_centred_at_first_complete_frame():
    m1, _, _ = _simulate(2, n=10)
    m1[0, 1] = np.nan
    ref = cluster_reference(m1)
    assert np.allclose(ref.mean(axis=0), 0.0)
    assert np.allclose(ref, m1[1] - m1[1].mean(axis=0))


# --------------------------------------------------------------------------------------------
# SCoRE
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("amp", [40.0, 60.0])
def test_score_centre_within_2mm(seed, amp):
    m1, m2, _ = _simulate(seed, rel_amp_deg=(amp, amp, amp), prox_amp_deg=15.0)
    res = score(*_poses(m1, m2))
    assert isinstance(res, FunctionalCentre)
    assert np.linalg.norm(res.centre_local1 - C1) < 2e-3
    assert np.linalg.norm(res.centre_local2 - C2) < 2e-3
    # the mismatch of the two images is pose noise, millimetre-sized
    assert 0 < res.rms_m < 3e-3
    assert res.n_frames_used == 400 and res.n_frames_skipped == 0
    assert res.rotation_range_deg > 60.0
    assert res.spread_deg > 20.0
    # global centre: midpoint of the two images, close to the true centre in every frame
    _, _, (R1, t1, _, _) = _simulate(seed, rel_amp_deg=(amp, amp, amp), prox_amp_deg=15.0)
    true = np.einsum("nab,b->na", R1, C1) + t1
    assert np.nanmax(np.linalg.norm(res.centre_global - true, axis=1)) < 6e-3


def test_score_exact_without_noise():
    m1, m2, poses = _simulate(7, n=30, noise=0.0)
    res = score(*poses)
    assert np.allclose(res.centre_local1, C1, atol=1e-10)
    assert np.allclose(res.centre_local2, C2, atol=1e-10)
    assert res.rms_m < 1e-10


def test_score_is_symmetric_in_the_segments():
    m1, m2, _ = _simulate(11, prox_amp_deg=20.0)
    R1, t1, R2, t2 = _poses(m1, m2)
    a = score(R1, t1, R2, t2)
    b = score(R2, t2, R1, t1)
    assert np.allclose(a.centre_local1, b.centre_local2, atol=1e-9)
    assert np.allclose(a.centre_local2, b.centre_local1, atol=1e-9)
    assert np.allclose(a.centre_global, b.centre_global, atol=1e-9)
    assert a.rms_m == pytest.approx(b.rms_m, rel=1e-9)
    assert a.rotation_range_deg == pytest.approx(b.rotation_range_deg, rel=1e-9)
    assert a.condition == pytest.approx(b.condition, rel=1e-9)


def test_score_too_little_motion_raises():
    m1, m2, _ = _simulate(3, rel_amp_deg=(4.0, 4.0, 4.0))
    poses = _poses(m1, m2)
    with pytest.raises(InputError, match=r"SCoRE: the two segments rotate by only \d+\.\d deg.*need at least 20"):
        score(*poses)
    # the threshold is a parameter: it can be lowered on purpose
    assert score(*poses, min_range_deg=5.0, min_spread_deg=0.0).n_frames_used == 400


def test_score_planar_motion_raises():
    """A hinge motion leaves the centre undetermined along the hinge axis: flagged, not trusted."""
    m1, m2, _ = _simulate(4, rel_amp_deg=(60.0,), hinge_axis=AXIS)
    with pytest.raises(InputError, match="nearly planar"):
        score(*_poses(m1, m2))


def test_score_spread_is_the_off_axis_rotation():
    """s_min/s_max = tan(phi/2), phi the rms rotation off the main axis (exact without noise for a
    rotation about a main axis plus a small constant tilt)."""
    n = 200
    theta = np.linspace(-1.0, 1.0, n)
    tilt = np.deg2rad(8.0)
    Rrel = Rotation.from_rotvec(np.c_[theta, np.full(n, tilt) * np.sign(np.sin(7 * theta)), np.zeros(n)])
    R1 = np.repeat(np.eye(3)[None], n, axis=0)
    R2 = Rrel.as_matrix()
    t1 = np.zeros((n, 3))
    t2 = -np.einsum("nab,b->na", R2, C2)
    res = score(R1, t1, R2, t2, min_spread_deg=0.0)
    assert 3.0 < res.spread_deg < 9.0
    assert np.allclose(res.centre_local2, C2, atol=1e-9)


def test_score_skips_and_counts_nan_frames():
    m1, m2, _ = _simulate(5, prox_amp_deg=10.0)
    full = score(*_poses(m1, m2))
    m1[10:20, :2] = np.nan  # segment 1: 2 markers left in frames 10-19
    m2[30:35] = np.nan  # segment 2: nothing in frames 30-34
    m2[40, 3] = np.nan  # 3 markers left: still a pose
    res = score(*_poses(m1, m2))
    assert res.n_frames_skipped == 15
    assert res.n_frames_used == 385
    assert np.isnan(res.centre_global[10:20]).all() and np.isnan(res.centre_global[30:35]).all()
    assert np.isfinite(res.centre_global[40]).all()
    assert np.linalg.norm(res.centre_local1 - C1) < 2e-3
    assert np.linalg.norm(res.centre_local1 - full.centre_local1) < 1e-3


def test_score_too_few_frames_and_bad_shapes_raise():
    m1, m2, _ = _simulate(6, n=10)
    R1, t1, R2, t2 = _poses(m1, m2)
    R1[2:] = np.nan
    with pytest.raises(InputError, match="only 2 of 10 frames"):
        score(R1, t1, R2, t2)
    with pytest.raises(InputError, match="poses must be"):
        score(R1[:, :2], t1, R2, t2)
    with pytest.raises(InputError, match="not a rotation matrix"):
        score(2 * R2, t1, R2, t2)


def test_score_to_dict_in_mm_and_deg():
    m1, m2, _ = _simulate(8)
    res = score(*_poses(m1, m2))
    d = res.to_dict()
    assert d["method"] == "SCoRE"
    assert d["centre_local1_mm"] == pytest.approx(list(res.centre_local1 * 1e3), abs=1e-3)
    assert d["rms_mm"] == pytest.approx(res.rms_m * 1e3, abs=1e-3)
    assert d["n_frames_used"] == 400
    with pytest.raises(AttributeError):
        res.rms_m = 0.0  # frozen


# --------------------------------------------------------------------------------------------
# SARA
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("prox", [0.0, 20.0])
def test_sara_axis_within_2deg_and_2mm(seed, prox):
    m1, m2, _ = _simulate(seed, rel_amp_deg=(60.0,), prox_amp_deg=prox, hinge_axis=AXIS)
    res = sara(*_poses(m1, m2))
    assert isinstance(res, FunctionalAxis) and res.method == "SARA"
    assert _angle_deg(res.direction_local1, AXIS) < 2.0
    assert _line_distance(res.point_local1, C1, AXIS) < 2e-3
    # in segment 2's frame: the axis is R_rel^T AXIS = AXIS (a hinge leaves its axis fixed), through C2
    assert _angle_deg(res.direction_local2, AXIS) < 2.0
    assert _line_distance(res.point_local2, C2, AXIS) < 2e-3
    assert res.range_deg == pytest.approx(120.0, abs=6.0)
    assert res.off_axis_rms_deg < 3.0
    assert res.condition < 0.1
    assert res.rms_m < 3e-3
    assert res.n_frames_used == 400


def test_sara_is_symmetric_in_the_segments():
    m1, m2, _ = _simulate(9, rel_amp_deg=(60.0,), prox_amp_deg=20.0, hinge_axis=AXIS)
    R1, t1, R2, t2 = _poses(m1, m2)
    a = sara(R1, t1, R2, t2)
    b = sara(R2, t2, R1, t1)
    assert _angle_deg(a.direction_local1, b.direction_local2) < 1e-6
    assert _angle_deg(a.direction_local2, b.direction_local1) < 1e-6
    assert np.allclose(a.point_local1, b.point_local2, atol=1e-9)
    assert np.allclose(a.point_local2, b.point_local1, atol=1e-9)
    assert a.range_deg == pytest.approx(b.range_deg, abs=1e-6)
    assert a.condition == pytest.approx(b.condition, rel=1e-9)


def test_sara_direction_hint_sets_the_sign():
    m1, m2, _ = _simulate(10, rel_amp_deg=(60.0,), hinge_axis=AXIS)
    poses = _poses(m1, m2)
    assert sara(*poses, direction_hint=AXIS).direction_local1 @ AXIS > 0
    res = sara(*poses, direction_hint=-AXIS)
    assert res.direction_local1 @ AXIS < 0 and res.direction_local2 @ AXIS < 0


def test_sara_too_little_motion_raises():
    m1, m2, _ = _simulate(12, rel_amp_deg=(5.0,), hinge_axis=AXIS)
    with pytest.raises(InputError, match=r"SARA: the rotation about the fitted axis spans only .*need at least 20"):
        sara(*_poses(m1, m2))


def test_sara_ball_motion_raises():
    m1, m2, _ = _simulate(13, rel_amp_deg=(60.0, 60.0, 60.0))
    with pytest.raises(InputError, match="not about a single axis"):
        sara(*_poses(m1, m2))


def test_sara_skips_and_counts_nan_frames():
    m1, m2, _ = _simulate(14, rel_amp_deg=(60.0,), prox_amp_deg=10.0, hinge_axis=AXIS)
    m1[0:7] = np.nan
    m2[50, 1:] = np.nan
    res = sara(*_poses(m1, m2))
    assert (res.n_frames_used, res.n_frames_skipped) == (392, 8)
    assert np.isnan(res.point_global[:7]).all() and np.isnan(res.point_global[50]).all()
    assert np.isfinite(res.point_global[7:50]).all()
    assert _angle_deg(res.direction_local1, AXIS) < 2.0
    assert _line_distance(res.point_local1, C1, AXIS) < 2e-3
    d = res.to_dict()
    assert d["method"] == "SARA" and d["n_frames_skipped"] == 8


# --------------------------------------------------------------------------------------------
# path axis
# --------------------------------------------------------------------------------------------
def _hinge_path(seed, amp_deg, n=400, points=((0.02, -0.25, 0.05),)):
    rng = np.random.default_rng(seed)
    theta = np.deg2rad(rng.uniform(-amp_deg, amp_deg, n))
    rot = Rotation.from_rotvec(theta[:, None] * AXIS)
    pts = np.stack([rot.apply(np.asarray(p) - C1) + C1 for p in points], axis=1)
    return pts + rng.normal(0, NOISE_M, pts.shape)


@pytest.mark.parametrize("seed", [0, 1])
def test_path_axis_single_point(seed):
    pts = _hinge_path(seed, 60.0)
    pts[3] = np.nan
    res = path_axis(pts)
    assert res.method == "path"
    assert _angle_deg(res.direction_local1, AXIS) < 1.0
    assert _line_distance(res.point_local1, C1, AXIS) < 2e-3
    assert res.range_deg == pytest.approx(120.0, abs=5.0)
    assert (res.n_frames_used, res.n_frames_skipped) == (399, 1)
    assert abs(res.point_local1 @ res.direction_local1) < 1e-12  # nearest point to the origin
    assert res.to_dict()["point_local2_mm"] is None


def test_path_axis_two_points_and_too_small_arc():
    pts = _hinge_path(2, 45.0, points=((0.02, -0.25, 0.05), (-0.02, -0.03, 0.0)))
    res = path_axis(pts)
    assert _angle_deg(res.direction_local1, AXIS) < 1.0
    assert _line_distance(res.point_local1, C1, AXIS) < 3e-3
    with pytest.raises(InputError, match="turn by only"):
        path_axis(_hinge_path(3, 20.0))


def test_relative_rotation_range():
    n = 50
    R1 = np.repeat(np.eye(3)[None], n, axis=0)
    R2 = Rotation.from_rotvec(np.c_[np.linspace(-0.3, 0.5, n), np.zeros((n, 2))]).as_matrix()
    assert relative_rotation_range_deg(R1, R2) == pytest.approx(math.degrees(0.8), abs=1e-9)
