"""Tests of exubio.prep (thorax, filtering, targets): thorax frame, gaps, zero-lag filter, spline
derivatives and the whole chain to MarkerTargets (unit trap, missing markers, real C3D smoke test)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from exubio.errors import InputError
from exubio.prep.filtering import detect_gaps, fill_short_gaps, lowpass, residual_cutoffs, valid_runs
from exubio.prep.targets import prepare_targets, spline_derivatives
from exubio.prep.thorax import thorax_frame, to_thorax_frame
from exubio.types import Gap, MarkerSpec, Protocol, ThoraxFrameSpec, Trajectories

SHARED = Path(__file__).resolve().parents[3] / "shared"
RATE = 100.0

# thorax landmarks in the ISB thorax frame (m): the frame they define is the identity
LOCAL_LANDMARKS = {
    "IJ": np.array([0.0, 0.0, 0.0]),
    "C7": np.array([-0.14, 0.03, 0.0]),
    "PX": np.array([0.0, -0.20, 0.0]),
    "T8": np.array([-0.14, -0.17, 0.0]),
}
LOCAL_MARKERS = {  # arm markers, fixed in the thorax frame except for a slow motion added below
    "ACR": np.array([-0.02, 0.01, 0.18]),
    "ELB": np.array([-0.03, -0.28, 0.22]),
    "HAND": np.array([0.15, -0.40, 0.25]),
}


def moving_thorax(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A thorax that rotates and translates in the lab: R (n, 3, 3), origin (n, 3)."""
    t = np.arange(n) / RATE
    rotvec = np.stack([0.2 * np.sin(0.7 * t), 0.5 + 0.3 * np.sin(0.4 * t), -0.1 + 0.2 * np.cos(0.5 * t)], axis=1)
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    origin = np.stack([0.5 + 0.1 * t, 1.2 + 0.02 * np.sin(t), -0.3 * np.ones(n)], axis=1)
    return rot, origin


def local_marker_motion(n: int) -> np.ndarray:
    """(n, 3, 3) marker positions in the thorax frame: slow (0.3 Hz) motion about LOCAL_MARKERS."""
    t = np.arange(n) / RATE
    base = np.stack(list(LOCAL_MARKERS.values()))
    wobble = 0.05 * np.sin(2 * np.pi * 0.3 * t)[:, None, None] * np.array([1.0, 0.5, -0.3])
    return base[None] + wobble


def make_trial(n: int = 300, *, scale: float = 1.0, source: str = "synthetic.c3d") -> tuple[Trajectories, np.ndarray]:
    """A lab-frame trial (thorax landmarks + arm markers) and the arm markers' thorax-frame truth."""
    rot, origin = moving_thorax(n)
    local = local_marker_motion(n)
    land = np.stack(list(LOCAL_LANDMARKS.values()))[None].repeat(n, axis=0)
    allpts = np.concatenate([land, local], axis=1)
    lab = np.einsum("nij,nkj->nki", rot, allpts) + origin[:, None, :]
    labels = tuple(LOCAL_LANDMARKS) + tuple(LOCAL_MARKERS)
    traj = Trajectories(labels, lab * scale, RATE, np.arange(n) / RATE, source=source)
    return traj, local


def make_protocol(*, cutoff: float | str | None = None, identity: bool = False,
                  optional_extra: bool = False) -> Protocol:
    markers = [MarkerSpec(name, seg, np.zeros(3)) for name, seg in
               zip(LOCAL_MARKERS, ("scapula", "humerus", "hand"))]
    if optional_extra:
        markers.insert(1, MarkerSpec("DELT", "humerus", np.zeros(3), optional=True))
    frame = ThoraxFrameSpec() if identity else ThoraxFrameSpec(ij="IJ", px="PX", c7="C7", t8="T8")
    return Protocol("test", tuple(markers), frame, cutoff_hz=cutoff, filter_order=2, source="test.yaml")


# --------------------------------------------------------------------------------------------
# Thorax frame
# --------------------------------------------------------------------------------------------
def test_thorax_frame_recovers_rotation_and_origin():
    n = 50
    rot, origin = moving_thorax(n)
    lab = {k: np.einsum("nij,j->ni", rot, v) + origin for k, v in LOCAL_LANDMARKS.items()}
    r_est, o_est = thorax_frame(lab["IJ"], lab["PX"], lab["C7"], lab["T8"])
    assert r_est.shape == (n, 3, 3) and o_est.shape == (n, 3)
    np.testing.assert_allclose(r_est, rot, atol=1e-12)
    np.testing.assert_allclose(o_est, origin, atol=1e-12)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", r_est, r_est), np.broadcast_to(np.eye(3), (n, 3, 3)),
                               atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(r_est), 1.0, atol=1e-14)


def test_thorax_frame_axes_directions_on_a_plain_thorax():
    # lab = thorax frame: X anterior, Y up, Z right
    r, o = thorax_frame(*(LOCAL_LANDMARKS[k] for k in ("IJ", "PX", "C7", "T8")))
    np.testing.assert_allclose(r, np.eye(3), atol=1e-15)
    # same thorax, lab axes permuted: lab x = right, y = anterior, z = up
    perm = np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]])  # columns: thorax X, Y, Z in lab coordinates
    r, _ = thorax_frame(*(perm @ LOCAL_LANDMARKS[k] for k in ("IJ", "PX", "C7", "T8")))
    np.testing.assert_allclose(r, perm, atol=1e-15)


def test_thorax_frame_nan_frames_and_degenerate_landmarks():
    ij, px, c7, t8 = (np.tile(LOCAL_LANDMARKS[k], (4, 1)) for k in ("IJ", "PX", "C7", "T8"))
    ij[2] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r, o = thorax_frame(ij, px, c7, t8)
    assert np.isnan(r[2]).all() and np.isfinite(r[[0, 1, 3]]).all()
    with pytest.raises(InputError, match="collinear"):
        thorax_frame(ij[[0]], px[[0]], ij[[0]] + [0.0, -1.0, 0.0], t8[[0]] * [0, 1, 0])


def test_to_thorax_frame_inverts_the_pose():
    n = 20
    rot, origin = moving_thorax(n)
    local = local_marker_motion(n)
    lab = np.einsum("nij,nkj->nki", rot, local) + origin[:, None]
    np.testing.assert_allclose(to_thorax_frame(lab, rot, origin), local, atol=1e-13)
    np.testing.assert_allclose(to_thorax_frame(lab, rot[0], origin[0])[0], local[0], atol=1e-13)


# --------------------------------------------------------------------------------------------
# Gaps
# --------------------------------------------------------------------------------------------
def gappy(n: int = 200) -> np.ndarray:
    t = np.arange(n) / RATE
    p = np.stack([np.sin(2 * np.pi * 0.5 * t), np.cos(2 * np.pi * 0.5 * t), t], axis=1)[:, None, :].repeat(3, axis=1)
    p = p.copy()
    p[0:5, 0] = np.nan
    p[50:60, 0] = np.nan
    p[120, 0, 1] = np.nan  # one coordinate missing: the whole sample is missing
    p[195:, 1] = np.nan
    return p


def test_valid_runs():
    assert valid_runs(np.array([1, 1, 0, 1, 0, 0, 1], bool)) == [(0, 2), (3, 4), (6, 7)]
    assert valid_runs(np.zeros(3, bool)) == []
    assert valid_runs(np.ones(3, bool)) == [(0, 3)]


def test_detect_gaps_exact():
    gaps = detect_gaps(gappy(), ("A", "B", "C"))
    assert gaps == (Gap("A", 0, 5), Gap("A", 50, 60), Gap("A", 120, 121), Gap("B", 195, 200))
    assert [g.n_frames for g in gaps] == [5, 10, 1, 5]


def test_gaps_stay_nan_through_filter_and_spline():
    p = gappy()
    missing = np.isnan(p).any(axis=2)
    f = lowpass(p, rate_hz=RATE, cutoff_hz=2.0, order=2)
    assert np.array_equal(np.isnan(f).any(axis=2), missing)
    assert np.isnan(f[missing]).all()  # the whole sample, never zero
    assert not np.any(f[~missing] == 0.0)
    t = np.arange(p.shape[0]) / RATE
    pos, vel, acc = spline_derivatives(t, f)
    for arr in (pos, vel, acc):
        assert np.array_equal(np.isnan(arr).any(axis=2), missing)
        assert np.isnan(arr[missing]).all()
    np.testing.assert_array_equal(pos[~missing], f[~missing])
    # across the 10-frame gap, the filter did not bridge: the run after it starts at the data
    np.testing.assert_allclose(f[60:70, 0, 2], p[60:70, 0, 2], atol=1e-3)


def test_lowpass_short_runs_are_left_unfiltered():
    p = np.full((100, 1, 3), np.nan)
    p[10:16, 0] = np.random.default_rng(0).normal(size=(6, 3))  # 6 samples <= padlen 9
    f = lowpass(p, rate_hz=RATE, cutoff_hz=2.0, order=2)
    np.testing.assert_array_equal(f, p)


def test_fill_short_gaps():
    x = np.arange(20.0)[:, None] * np.array([1.0, 2.0, 3.0])
    y = x.copy()
    y[0:2] = np.nan  # start: held
    y[5:8] = np.nan  # interior: linear
    y[10:16] = np.nan  # too long: stays
    y[18:] = np.nan  # end: held
    f = fill_short_gaps(y, max_gap_frames=3)
    np.testing.assert_array_equal(f[0:2], np.tile(x[2], (2, 1)))
    np.testing.assert_allclose(f[5:8], x[5:8])
    assert np.isnan(f[10:16]).all()
    np.testing.assert_array_equal(f[18:], np.tile(x[17], (2, 1)))
    assert np.isnan(y[5:8]).all()  # input untouched


# --------------------------------------------------------------------------------------------
# Filter and derivatives
# --------------------------------------------------------------------------------------------
def test_lowpass_keeps_slow_sine_without_lag_and_removes_noise():
    t = np.arange(1000) / RATE
    slow = np.sin(2 * np.pi * 0.5 * t)
    fast = 0.2 * np.sin(2 * np.pi * 15.0 * t)
    f = lowpass(slow + fast, rate_hz=RATE, cutoff_hz=2.0, order=2)
    inner = slice(100, 900)
    # amplitude within 2 %, no phase lag: the filtered signal matches the slow sine sample by sample
    assert abs(np.max(np.abs(f[inner])) - 1.0) < 0.02
    np.testing.assert_allclose(f[inner], slow[inner], atol=0.02)
    lags = np.arange(-20, 21)
    xc = [np.dot(np.roll(f, k)[inner], slow[inner]) for k in lags]
    assert lags[int(np.argmax(xc))] == 0
    assert np.std(f[inner] - slow[inner]) < 0.005  # 15 Hz attenuated by > 30x


def test_lowpass_rejects_cutoff_above_nyquist():
    with pytest.raises(InputError, match="Nyquist"):
        lowpass(np.zeros((50, 1, 3)), rate_hz=RATE, cutoff_hz=60.0, order=2)


def smooth_trajectory(t: np.ndarray) -> np.ndarray:
    """(n, 1, 3) a smooth marker path (m): slow sinusoids and a cubic drift, curved at both ends."""
    return np.stack([0.05 * np.sin(2 * np.pi * 0.4 * t + 0.3),
                     0.0025 * (t - 1.0) ** 3 - 0.03 * t,
                     0.04 * np.cos(2 * np.pi * 0.25 * t)], axis=1)[:, None, :]


def test_lowpass_does_not_bend_the_ends_of_a_smooth_trajectory():
    # 4 s at 100 Hz, 2 Hz: the filter's own attenuation of the 0.4 Hz sine is ~0.08 mm everywhere;
    # the first and last 0.2 s must not deviate more than that (odd-reflection padding: 0.57 mm)
    t = np.arange(400) / RATE
    p = smooth_trajectory(t)
    f = lowpass(p, rate_hz=RATE, cutoff_hz=2.0, order=2)
    err = np.abs(f - p).max(axis=(1, 2))
    ends = max(err[:20].max(), err[-20:].max())
    assert ends < 0.1e-3
    assert ends < 1.5 * err[50:-50].max()
    # at 6 Hz everything is within 1 micrometre, ends included (odd reflection: 70 micrometres)
    f6 = lowpass(p, rate_hz=RATE, cutoff_hz=6.0, order=2)
    assert np.abs(f6 - p).max() < 1e-6


def test_lowpass_ends_of_every_run_and_a_short_run():
    # gaps split the trajectory into runs of 100, 15 and 100 samples; each run's ends are kept,
    # the 15-sample run (shorter than the 50-sample end window at 2 Hz) is fitted whole
    t = np.arange(400) / RATE
    p = smooth_trajectory(t)
    p[100:130] = np.nan
    p[145:300] = np.nan
    f = lowpass(p, rate_hz=RATE, cutoff_hz=2.0, order=2)
    assert np.array_equal(np.isnan(f), np.isnan(p))
    for a, b, tol in [(0, 100, 0.1e-3), (130, 145, 0.02e-3), (300, 400, 0.1e-3)]:
        assert np.abs(f[a:b] - p[a:b]).max() < tol, (a, b)
    # a short run that is exactly a (steep) cubic comes back unchanged (odd reflection: 10 mm off)
    cubic = np.full((60, 1), np.nan)
    x = np.arange(12) / RATE
    cubic[20:32, 0] = 0.1 + 0.2 * x - 3.0 * x**2 + 40.0 * x**3
    np.testing.assert_allclose(lowpass(cubic, rate_hz=RATE, cutoff_hz=2.0, order=2), cubic, rtol=0, atol=1e-6)


def test_lowpass_one_cutoff_per_marker():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(300, 2, 3))
    both = lowpass(p, rate_hz=RATE, cutoff_hz=[2.0, 8.0], order=2)
    np.testing.assert_array_equal(both[:, 0], lowpass(p[:, :1], rate_hz=RATE, cutoff_hz=2.0)[:, 0])
    np.testing.assert_array_equal(both[:, 1], lowpass(p[:, 1:], rate_hz=RATE, cutoff_hz=8.0)[:, 0])
    with pytest.raises(InputError, match="Nyquist"):
        lowpass(p, rate_hz=RATE, cutoff_hz=[2.0, 50.0])


def _lowpass_time_first(p, rate_hz, cutoff_hz, order):
    """lowpass as it was written before it filtered with time along the last axis and took runs
    shared by consecutive markers as a view: each group of series (same run, same cut-off)
    indexed by a list, extended by the cubic end fits and filtered along axis 0."""
    from scipy.signal import butter, filtfilt

    from exubio.prep import filtering as pp

    s = pp.as_series(p)
    cut = np.broadcast_to(np.asarray(cutoff_hz, dtype=float), (s.shape[1],))
    out = np.full_like(s, np.nan)
    groups = {}
    for (start, stop), cols in pp._runs(s).items():
        for j in cols:
            groups.setdefault((float(cut[j]), start, stop), []).append(j)
    for (c, start, stop), cols in groups.items():
        seg = s[start:stop, cols]
        n = seg.shape[0]
        if n <= pp._min_run(order):
            out[start:stop, cols] = seg
            continue
        flat = seg.reshape(n, -1)
        period = rate_hz / c
        pad = max(int(round(pp.PAD_PERIODS * period)), 1)
        window = min(n, max(int(round(pp.FIT_PERIODS * period)), pp._MIN_FIT_SAMPLES))
        head = pp._polynomial_extension(flat[:window], pad)
        tail = pp._polynomial_extension(flat[::-1][:window], pad)[::-1]
        ext = np.concatenate([head, flat, tail], axis=0)
        filtered = filtfilt(*butter(order, c, btype="low", fs=rate_hz), ext, axis=0, padtype=None)
        out[start:stop, cols] = filtered[pad:pad + n].reshape(seg.shape)
    return out.reshape(np.shape(p))


def test_lowpass_gives_the_time_first_computation_to_the_bit():
    rng = np.random.default_rng(11)
    walk = rng.normal(scale=1e-3, size=(900, 6, 3)).cumsum(axis=0)
    gappy = walk.copy()
    gappy[100:140, 1] = np.nan  # markers 1 and 2 share their runs: one group, a slice
    gappy[100:140, 2] = np.nan
    gappy[::50, 4, 0] = np.nan  # many runs, one of them short
    gappy[600:605, 4] = np.nan
    gappy[:, 5] = np.nan  # never seen
    gappy[890:, 0] = np.nan  # a run too short to filter at the end
    for p in (walk, gappy, walk[:, 0, 0], walk[:200, :2]):
        for cutoff in (2.0, 6.5, np.linspace(2.0, 12.0, p.shape[1]) if p.ndim == 3 else 4.0):
            for order in (1, 2, 4):
                got = lowpass(p, rate_hz=RATE, cutoff_hz=cutoff, order=order)
                assert np.array_equal(got, _lowpass_time_first(p, RATE, cutoff, order), equal_nan=True)


def band_limited(n: int, k: int, rng: np.random.Generator, top_hz: float = 3.0) -> np.ndarray:
    """(n, k, 3) sums of 15 sinusoids of 0.2-``top_hz`` Hz, 5-20 mm each, random phases (m)."""
    t = np.arange(n) / RATE
    freqs = np.linspace(0.2, top_hz, 15)
    amp = rng.uniform(0.005, 0.02, (k, 3, freqs.size))
    phase = rng.uniform(0.0, 2 * np.pi, (k, 3, freqs.size))
    return (amp[None] * np.sin(2 * np.pi * freqs * t[:, None, None, None] + phase[None])).sum(axis=3)


def test_residual_cutoffs_on_a_band_limited_signal_with_white_noise():
    rng = np.random.default_rng(0)
    clean = band_limited(2000, 2, rng)  # content up to 3 Hz, 20 s at 100 Hz
    noisy = clean + rng.normal(0.0, 1e-3, clean.shape)  # 1 mm white noise
    cutoff, noise = residual_cutoffs(noisy, rate_hz=RATE)
    assert cutoff.shape == (2,) and noise.shape == (2,)
    # above the signal's band, well below Nyquist (50 Hz): inside the bounds, not on them
    assert np.all(cutoff > 3.0) and np.all(cutoff < 12.0)
    np.testing.assert_allclose(noise, 1e-3, rtol=0.1)  # the intercept of the noise line is the noise RMS

    def error(f):
        return np.sqrt(np.mean((f - clean) ** 2))

    auto = error(lowpass(noisy, rate_hz=RATE, cutoff_hz=cutoff))
    assert auto < 0.7 * error(noisy)  # removes noise ...
    assert auto < 0.1 * error(lowpass(noisy, rate_hz=RATE, cutoff_hz=2.0))  # ... and keeps the signal


def test_residual_cutoffs_bounds_and_missing_markers():
    rng = np.random.default_rng(1)
    clean = band_limited(1000, 1, rng)
    white = rng.normal(0.0, 1e-3, (1000, 1, 3))
    absent = np.full((1000, 1, 3), np.nan)
    cutoff, noise = residual_cutoffs(np.concatenate([clean, white, absent], axis=1), rate_hz=RATE)
    assert cutoff[0] == 12.0 and abs(noise[0]) < 1e-4  # noise-free: nothing to remove, the upper bound
    assert cutoff[1] == 2.0 and noise[1] == pytest.approx(1e-3, rel=0.1)  # noise only: the lower bound
    assert np.isnan(cutoff[2]) and np.isnan(noise[2])
    # at 50 Hz the noise band starts at 6.25 Hz: the cut-off stays below it; at 12.5 Hz (noise
    # band from 1.6 Hz) there is no room above the lower bound
    cutoff, _ = residual_cutoffs(clean[::2], rate_hz=50.0)
    assert cutoff[0] == pytest.approx(6.25)
    with pytest.raises(InputError, match="too slow for residual analysis"):
        residual_cutoffs(clean[::8], rate_hz=12.5)


def test_spline_derivatives_of_a_sine():
    t = np.arange(500) / RATE
    w = 2 * np.pi * 0.5
    p = np.stack([np.sin(w * t), np.cos(w * t), 0.3 * np.sin(w * t + 1.0)], axis=1)
    v = np.stack([w * np.cos(w * t), -w * np.sin(w * t), 0.3 * w * np.cos(w * t + 1.0)], axis=1)
    a = -w**2 * p
    pos, vel, acc = spline_derivatives(t, p)
    inner = slice(10, -10)
    np.testing.assert_array_equal(pos, p)
    assert np.max(np.abs(vel[inner] - v[inner])) < 1e-4 * np.max(np.abs(v))
    assert np.max(np.abs(acc[inner] - a[inner])) < 1e-4 * np.max(np.abs(a))


def test_spline_short_runs_and_resampling():
    t = np.arange(10) / RATE
    p = np.full((10, 1, 3), np.nan)
    p[2] = 1.0  # isolated sample
    p[5:7, 0] = np.array([[0.0, 0, 0], [0.01, 0.02, 0.03]])  # two samples: a line
    pos, vel, acc = spline_derivatives(t, p)
    np.testing.assert_array_equal(vel[2], 0.0)
    np.testing.assert_allclose(vel[5:7, 0], [[1.0, 2.0, 3.0]] * 2)
    np.testing.assert_allclose(acc[5:7, 0], 0.0, atol=1e-9)
    at = np.array([0.055, 0.08])
    pos, vel, _ = spline_derivatives(t, p, at=at)
    np.testing.assert_allclose(pos[0, 0], [0.005, 0.01, 0.015])
    assert np.isnan(pos[1]).all() and np.isnan(vel[1]).all()


# --------------------------------------------------------------------------------------------
# prepare_targets
# --------------------------------------------------------------------------------------------
def test_prepare_targets_removes_thorax_motion():
    traj, local = make_trial()
    targets = prepare_targets(traj, make_protocol(cutoff=None))
    assert targets.marker_names == tuple(LOCAL_MARKERS)
    assert targets.source == "synthetic.c3d"
    assert targets.gaps == ()
    np.testing.assert_allclose(targets.positions_m, local, atol=1e-12)
    np.testing.assert_array_equal(targets.time_s, traj.time_s)
    t = traj.time_s
    true_v = 0.05 * 2 * np.pi * 0.3 * np.cos(2 * np.pi * 0.3 * t)[:, None, None] * np.array([1.0, 0.5, -0.3])
    np.testing.assert_allclose(targets.velocities_m_s[5:-5], np.broadcast_to(true_v, local.shape)[5:-5], atol=1e-6)


def test_prepare_targets_filtered_and_resampled():
    traj, local = make_trial()
    targets = prepare_targets(traj, make_protocol(cutoff=2.0), resample_hz=50.0)
    np.testing.assert_allclose(targets.time_s, np.arange(150) / 50.0)
    assert targets.positions_m.shape == (150, 3, 3)
    plain = prepare_targets(traj, make_protocol(cutoff=2.0))
    for a, b in [("positions_m", "positions_m"), ("velocities_m_s", "velocities_m_s"),
                 ("accelerations_m_s2", "accelerations_m_s2")]:
        np.testing.assert_allclose(getattr(targets, a), getattr(plain, b)[::2], atol=1e-12)
    np.testing.assert_allclose(plain.positions_m, local, atol=3e-4)  # 0.3 Hz barely touched by 2 Hz
    fine = prepare_targets(traj, make_protocol(cutoff=2.0), resample_hz=400.0)
    assert fine.n_frames == 1197 and fine.time_s[-1] == pytest.approx(traj.time_s[-1])
    np.testing.assert_allclose(fine.positions_m[::4], plain.positions_m, atol=1e-12)
    np.testing.assert_allclose(fine.positions_m[2::4], 0.5 * (plain.positions_m[:-1] + plain.positions_m[1:]),
                               atol=1e-5)


def test_prepare_targets_reports_the_cutoffs_applied():
    traj, local = make_trial(200)
    assert prepare_targets(traj, make_protocol(cutoff=None)).cutoff_hz == {}
    fixed = prepare_targets(traj, make_protocol(cutoff=6.0, optional_extra=True))
    assert fixed.cutoff_hz == {"ACR": 6.0, "ELB": 6.0, "HAND": 6.0}  # DELT is absent: nothing filtered
    # auto, on thorax-frame data with 1 mm noise on ELB only: per marker, the applied cut-offs
    rng = np.random.default_rng(5)
    noisy = local + np.where(np.arange(3) == 1, 1.0, 0.0)[None, :, None] * rng.normal(0.0, 1e-3, local.shape)
    in_thorax = Trajectories(tuple(LOCAL_MARKERS), noisy, RATE, traj.time_s, source="thorax.trc")
    auto = prepare_targets(in_thorax, make_protocol(identity=True, cutoff="auto"))
    assert list(auto.cutoff_hz) == list(LOCAL_MARKERS)
    assert auto.cutoff_hz["ACR"] == auto.cutoff_hz["HAND"] == 12.0  # noise-free: the upper bound
    assert 2.0 <= auto.cutoff_hz["ELB"] < 6.0  # 1 mm noise on a 0.3 Hz motion: filtered hard
    expected = lowpass(noisy, rate_hz=RATE, cutoff_hz=list(auto.cutoff_hz.values()), order=2)
    np.testing.assert_array_equal(auto.positions_m, expected)


@pytest.mark.parametrize("cutoff, fragment", [(60.0, "Nyquist"), ("fast", "neither a number")])
def test_prepare_targets_bad_cutoff_names_protocol_and_key(cutoff, fragment):
    traj, _ = make_trial(100)
    with pytest.raises(InputError) as exc:
        prepare_targets(traj, make_protocol(cutoff=cutoff))
    msg = str(exc.value)
    assert "synthetic.c3d" in msg and "test.yaml" in msg and "filter.cutoff_hz" in msg and fragment in msg


def test_prepare_targets_does_not_mutate_input():
    traj, _ = make_trial(100)
    before = traj.positions_m.copy()
    prepare_targets(traj, make_protocol(cutoff=2.0))
    np.testing.assert_array_equal(traj.positions_m, before)


def test_prepare_targets_identity_frame_keeps_data():
    traj, local = make_trial(100)
    in_thorax = Trajectories(tuple(LOCAL_MARKERS), local, RATE, traj.time_s, source="thorax.trc")
    targets = prepare_targets(in_thorax, make_protocol(identity=True))
    np.testing.assert_allclose(targets.positions_m, local, atol=1e-15)


def test_prepare_targets_gaps_and_optional_marker():
    traj, local = make_trial(200)
    pos = traj.positions_m.copy()
    elb = traj.labels.index("ELB")
    pos[40:55, elb] = np.nan
    traj = Trajectories(traj.labels, pos, RATE, traj.time_s, source="gappy.c3d")
    targets = prepare_targets(traj, make_protocol(cutoff=2.0, optional_extra=True))
    assert targets.marker_names == ("ACR", "DELT", "ELB", "HAND")
    assert targets.gaps == (Gap("DELT", 0, 200), Gap("ELB", 40, 55))
    assert np.isnan(targets.positions_m[:, 1]).all()
    assert np.isnan(targets.velocities_m_s[40:55, 2]).all()
    assert np.isfinite(targets.accelerations_m_s2[:40, 2]).all()
    assert targets.present.sum() == 200 * 3 - 15


def test_thorax_landmark_gaps_bridged_or_propagated():
    traj, local = make_trial(200)
    pos = traj.positions_m.copy()
    pos[30:40, traj.labels.index("C7")] = np.nan  # 0.1 s: bridged
    pos[100:160, traj.labels.index("PX")] = np.nan  # 0.6 s: every marker missing there
    traj = Trajectories(traj.labels, pos, RATE, traj.time_s, source="t.c3d")
    targets = prepare_targets(traj, make_protocol(cutoff=None))
    assert targets.gaps == tuple(Gap(m, 100, 160) for m in LOCAL_MARKERS)
    assert np.isfinite(targets.positions_m[30:40]).all()
    np.testing.assert_allclose(targets.positions_m[30:40], local[30:40], atol=5e-3)


def test_thorax_landmark_all_nan():
    traj, _ = make_trial(50)
    pos = traj.positions_m.copy()
    pos[:, traj.labels.index("T8")] = np.nan
    traj = Trajectories(traj.labels, pos, RATE, traj.time_s, source="t.c3d")
    with pytest.raises(InputError, match=r"t.c3d: thorax landmark 'T8' \(thorax_frame.t8\) is missing in every frame"):
        prepare_targets(traj, make_protocol())


@pytest.mark.parametrize("scale, word", [(1000.0, "millimetres taken as metres"), (1e-3, "metres taken as millimetres")])
def test_unit_trap(scale, word):
    traj, _ = make_trial(50, scale=scale, source="units.c3d")
    with pytest.raises(InputError) as exc:
        prepare_targets(traj, make_protocol())
    assert "units.c3d" in str(exc.value) and word in str(exc.value)


def test_missing_marker_error_names_it():
    traj, _ = make_trial(50)
    keep = [i for i, lab in enumerate(traj.labels) if lab != "ELB"]
    traj = Trajectories(tuple(traj.labels[i] for i in keep), traj.positions_m[:, keep], RATE, traj.time_s,
                        source="noelb.c3d")
    with pytest.raises(InputError) as exc:
        prepare_targets(traj, make_protocol())
    assert "noelb.c3d" in str(exc.value) and "'ELB'" in str(exc.value)


@pytest.mark.parametrize("n_present, fragment", [(0, "missing in every frame"), (1, "present in only 1 frame")])
def test_marker_all_nan_or_single_frame(n_present, fragment):
    traj, _ = make_trial(50)
    pos = traj.positions_m.copy()
    hand = traj.labels.index("HAND")
    pos[n_present:, hand] = np.nan
    traj = Trajectories(traj.labels, pos, RATE, traj.time_s, source="h.c3d")
    with pytest.raises(InputError) as exc:
        prepare_targets(traj, make_protocol())
    assert "h.c3d" in str(exc.value) and "'HAND'" in str(exc.value) and fragment in str(exc.value)


# --------------------------------------------------------------------------------------------
# Real data (skipped where ../shared is absent)
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["bioptim_exo_martin_statique.c3d", "bioptim_exo_F0_boire_05.c3d"])
def test_real_c3d_smoke(name):
    path = SHARED / "data" / "c3d" / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    ezc3d = pytest.importorskip("ezc3d")
    from exubio.protocol.load import load_protocol

    c3d = ezc3d.c3d(str(path))
    labels = [lab.split(":")[-1] for lab in c3d["parameters"]["POINT"]["LABELS"]["value"]]
    assert c3d["parameters"]["POINT"]["UNITS"]["value"][0] == "mm"
    xyz = c3d["data"]["points"][:3].transpose(2, 1, 0) / 1000.0  # (n, k, 3) in m
    keep = [i for i, lab in enumerate(labels) if not lab.startswith("*")]
    rate = float(c3d["parameters"]["POINT"]["RATE"]["value"][0])
    traj = Trajectories(tuple(labels[i] for i in keep), xyz[:, keep], rate, np.arange(xyz.shape[0]) / rate,
                        source=str(path), units_in_file="mm")
    segments = ("thorax", "clavicle", "scapula", "humerus", "ulna", "radius", "hand")
    names = {"clavicle": ["CLAV_SC", "CLAV_AC"],
             "scapula": ["SCAP_Cor", "SCAP_AA", "SCAP_AC", "SCAP_IA", "SCAP_BACK", "SCAP_FRONT"],
             "humerus": ["ARM", "DELT", "EPI_lat", "EPI_med"], "ulna": ["ULNA", "ELB"], "radius": ["RADIUS"],
             "hand": ["MET2", "MET5", "SEML"]}
    points = {seg: {p: np.zeros(3) for p in pts} for seg, pts in names.items()}
    protocol = load_protocol(Path(__file__).resolve().parents[2] / "protocols" / "upper_limb_21.yaml",
                             segments=segments, model_points=points)
    targets = prepare_targets(traj, protocol)
    assert targets.positions_m.shape == (traj.n_frames, 18, 3)
    present = targets.present
    assert present[:, [i for i, m in enumerate(targets.marker_names) if m != "ELB"]].mean() > 0.9
    # in the thorax frame, the markers sit within arm's reach of IJ; the hand is below the shoulder
    dist = np.linalg.norm(targets.positions_m, axis=2)
    assert np.nanmax(dist) < 1.2 and np.nanmedian(dist) > 0.1
    clav_ac = targets.positions_m[:, targets.marker_names.index("CLAV_AC")]
    assert np.nanmedian(clav_ac[:, 2]) > 0.05  # right arm: acromion to the right (+Z) of IJ
    assert np.isfinite(targets.velocities_m_s[present]).all()
