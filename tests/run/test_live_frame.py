"""A live frame's outputs in compiled calls (exubio.run.live.frame, exubio.model.live_kernels) are, bit for
bit, the batch functions and numpy steps they stand in for: the coordinates of the segment rotations
(Kinematics.coordinates_from_rotations) unwrapped as np.unwrap unwraps them and put on the run's branch
nearest its start posture, the ISB angles unwrapped against the last ones with angles and their backward
differences, the model points (Kinematics.points), the residuals (a norm over 3 columns), their mean over
the finite ones; the GH elevation to round-off (numpy's 3 x 3 products go through BLAS); over motions that wrap past +-pi, with markers missing, across a
frame without angles and a new run."""
import numpy as np
import pytest

from exubio.model.angles import anatomical_frames
from exubio.model.frame_angles import FrameAngles
from exubio.model.load import load_model
from exubio.protocol.bind import bind
from exubio.run.inputs import protocol_for_model
from exubio.run.live.frame import LiveFrame


@pytest.mark.parametrize("n", [0, 1, 2, 7, 8, 9, 15, 16, 21, 22, 127, 128, 129, 200, 256, 257, 1000, 5003])
def test_the_mean_sums_as_numpy_sums(n):
    from exubio.model.live_kernels import _numpy_sum

    rng = np.random.default_rng(n)
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)  # magnitudes apart: the order shows
    assert _numpy_sum(np.concatenate([x, [1e300]]), n) == np.add.reduce(x)


class _Reference:
    """The numpy steps of one live frame, as they were before the compiled calls."""

    def __init__(self, model, kin, points, rate, gh_axes):
        self.model, self.kin, self.points, self.rate, self.gh_axes = model, kin, points, rate, gh_axes
        self.angles = FrameAngles(model, anatomical_frames(model))
        self.last_isb = self.last_row = None

    def start_run(self, q0):
        self.q0, self.last_raw = q0, None

    def coordinates(self, R):
        raw = self.kin.coordinates_from_rotations(R[None])
        if self.last_raw is None:
            q = np.unwrap(raw, axis=0)
            self.shift = 2.0 * np.pi * np.round((q[0] - self.q0) / (2.0 * np.pi))
        else:
            q = np.unwrap(np.vstack([self.last_raw[None], raw]), axis=0)[1:] + (self.last_unwrapped - self.last_raw)
        self.last_raw, self.last_unwrapped = raw[-1], q[-1]
        return (q - self.shift)[0]

    def outputs(self, q, measured):
        fr = self.kin.frames(q)
        ang = self.angles(fr.R)
        if self.last_isb is not None:
            ang = self.last_isb + (ang - self.last_isb + np.pi) % (2 * np.pi) - np.pi
        self.last_isb = ang
        rate = (ang - self.last_row) * self.rate if self.last_row is not None else np.zeros_like(ang)
        self.last_row = ang
        pts = self.kin.points(q, self.points)
        d = pts - measured
        res = np.sqrt(np.add.reduce(d * d, axis=1))
        ok = np.isfinite(res)
        mean = float(res[ok].mean()) * 1e3 if ok.any() else np.nan
        (s, ys), (h, yh) = self.gh_axes
        gh = np.arccos(min(1.0, max(-1.0, float((fr.R[s] @ ys) @ (fr.R[h] @ yh)))))
        return fr.R, fr.p, ang, rate, pts, res, mean, gh

    def none(self):
        self.last_row = None


def test_a_live_frame_is_the_numpy_steps_bit_for_bit():
    from exubio.run.live.monitor import _long_axes

    model = load_model()
    binding = bind(model, protocol_for_model(model))
    kin, points = binding.kin, binding.points
    rate = 200.0
    frame = LiveFrame(model, kin, points, rate, _long_axes(model))
    ref = _Reference(model, kin, points, rate, _long_axes(model))
    rng = np.random.default_rng(4)
    lo, hi = np.clip(model.coordinate_ranges_rad.T, -np.pi, np.pi)
    m, k = model.n_coordinates, len(points.segment_index)
    t = np.arange(400) / rate
    # a slow motion over the ranges, plus coordinates that turn through +-pi (the unwrap's branches)
    q = 0.5 * (lo + hi) + 0.5 * (hi - lo)[None, :] * np.sin(2 * np.pi * 0.3 * t[:, None] + rng.uniform(0, 6, m))
    q[:, [2, 7, 10]] += np.linspace(0.0, 5 * np.pi, len(t))[:, None]
    R_all = kin.frames(q).R
    measured = kin.points(q, points) + rng.normal(scale=2e-3, size=(len(t), k, 3))
    measured[50:80, 3] = np.nan  # a marker missing
    measured[120:123] = np.nan  # every marker missing: the mean is NaN
    runs = {0: q[0], 200: q[200] + 2 * np.pi}  # a second run whose start posture lies a turn away
    last_q = None
    for i in range(len(t)):
        if i in runs:
            frame.start_run(runs[i])
            ref.start_run(runs[i])
        if i in (150, 151):  # frames without angles: the rates start again at zero after them
            got_isb, got_rate = frame.none()
            ref.none()
            assert np.isnan(got_isb).all() and np.isnan(got_rate).all()
            continue
        got_q, want_q = frame.coordinates(R_all[i]), ref.coordinates(R_all[i])
        assert np.array_equal(got_q, want_q), i
        got, want = frame.outputs(got_q, measured[i]), ref.outputs(want_q, measured[i])
        for name, a, b in zip(("R", "p", "isb", "rate", "points", "residuals"), got[:6], want[:6]):
            assert np.array_equal(a, b, equal_nan=True), (i, name, np.nanmax(np.abs(a - b)))
        assert got.mean_residual_mm == want[6] or (np.isnan(got.mean_residual_mm) and np.isnan(want[6])), i
        assert abs(got.gh_elevation - want[7]) < 1e-12, i  # numpy's matmul sums through BLAS, in its own order
        if i == 152:
            assert (got.rate == 0.0).all()
        if i - 1 not in runs and i - 1 not in (150, 151) and i not in runs:  # unwrapped: no step beyond half a turn
            assert np.abs(got_q - last_q).max() <= np.pi + 1e-9, i
        last_q = got_q
