"""The report's curves are drawn thinned to their envelope (exubio.report.page_figures._envelope):
every bin keeps its minimum and maximum, every gap (NaN) keeps its edges, and what is drawn from the
thinned curves lies within one pixel of what every sample draws at the resolution of the report's
PNG, and within 2.5 pixels (less than one of those) at three times it. The curves are the filtered
angles a trial gives (a Butterworth low pass of a noisy motion with spikes), with gaps."""
from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy.ndimage import distance_transform_edt
from scipy.signal import butter, filtfilt

from exubio.report.page_figures import PLOT_POINTS, _envelope
from exubio.report.rhythm_page import CYCLE_BIN_DEG, _cycle_points, _phase_curves
from exubio.scapulohumeral.table import TrialRhythm


def _signal(n: int, seed: int) -> np.ndarray:
    """A motion at 200 Hz with noise and single-sample spikes, low-passed at 6 Hz, with gaps of 1 to
    30 samples."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 25.0, n)
    y = 40 * np.sin(2 * np.pi * t / 6) + rng.normal(0, 1.0, n)
    y[rng.choice(n, 12, replace=False)] += rng.choice([-25.0, 25.0], 12)
    y = filtfilt(*butter(2, 6.0 / 100.0), y)
    for start, length in zip(rng.choice(n - 40, 8, replace=False), (1, 1, 2, 3, 5, 12, 30, 7)):
        y[start:start + length] = np.nan
    return y


def test_every_bins_extremes_and_every_gap_edge_are_kept():
    n = 5003  # not a multiple of the bin size: the tail is kept whole
    t = np.arange(n) / 200.0
    lo, hi = _signal(n, 1) - 3.0, _signal(n, 2) + 3.0
    tt, ll, hh = _envelope(t, lo, hi, keep=2)
    assert len(tt) < n / 3 and np.all(np.diff(tt) > 0)
    kept = np.searchsorted(t, tt)
    k = int(np.ceil(n / (PLOT_POINTS // 2)))
    for y in (lo, hi):
        for b in range(n // k):
            block = y[b * k:(b + 1) * k]
            if np.isfinite(block).any():
                for extreme in (np.nanargmin(block), np.nanargmax(block)):
                    assert b * k + extreme in kept
        finite = np.isfinite(y)
        for edge in np.flatnonzero(finite[1:] != finite[:-1]):
            assert edge in kept and edge + 1 in kept  # the gap starts and ends where it does
    np.testing.assert_array_equal(ll, lo[kept])
    np.testing.assert_array_equal(hh, hi[kept])
    short = t[:PLOT_POINTS]
    assert _envelope(short, lo[:PLOT_POINTS])[0] is short  # short curves are drawn whole


def _inked(artist, how, limits, rect, dpi) -> np.ndarray:
    """The pixels ``artist(ax, how)`` inks (darker than 95 % white) in axes of limits ``limits``
    and of the size of ``rect`` on an A4 page (figure fractions; only the axes are drawn)."""
    fig = Figure(figsize=(11.69 * rect[2], 8.27 * rect[3]), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    artist(ax, how)
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].min(axis=2) < 0.95 * 255


def _apart_px(a: np.ndarray, b: np.ndarray) -> float:
    """How far (pixels) an inked pixel of one drawing lies from the nearest inked pixel of the other."""
    assert a.any() and b.any()
    return float(max(distance_transform_edt(~b)[a].max(), distance_transform_edt(~a)[b].max()))


def test_page_ones_thinned_curve_and_band_draw_what_every_sample_draws():
    """Page 1's key angles: a curve where measured, grey where not, its +-2u band; 5000 frames in
    the picture's place on an A4 page, at the PNG's resolution and at three times it."""
    n = 5000
    t = np.arange(n) / 200.0
    y = _signal(n, 3)
    ok = np.ones(n, dtype=bool)
    ok[1200:1260] = ok[3001] = False
    band = 2.0 + np.abs(np.sin(t))

    artists = (lambda ax, f: ax.plot(*f(t, np.where(ok, y, np.nan)), color="tab:blue", lw=1.4),
               lambda ax, f: ax.fill_between(*f(t, np.where(ok, y - band, np.nan), np.where(ok, y + band, np.nan),
                                                keep=2), color="tab:blue", alpha=0.15, lw=0),
               lambda ax, f: ax.plot(*f(t, np.where(ok, np.nan, y)), color="silver", lw=1.4))
    every = (lambda *a, **k: a)
    for artist in artists:
        for dpi, apart in ((110, 1.0), (330, 2.5)):
            inked = [_inked(artist, f, ((0, 25), (-80, 80)), (0.07, 0.06, 0.66, 0.25), dpi) for f in (every, _envelope)]
            assert _apart_px(*inked) <= apart, dpi


def test_a_phases_cycles_thinned_by_elevation_draw_what_every_sample_draws():
    """Two raising cycles of 600 frames over 110 deg of HT elevation (one with frames not
    measured), as the rhythm page draws a phase (_phase_curves: each cycle thinned, a break between
    cycles), in a rhythm panel's place, against each cycle drawn from every sample."""
    n = 600
    rng = np.random.default_rng(4)
    low_pass = butter(2, 6.0 / 100.0)
    ht = np.concatenate([np.linspace(10.0, 120.0, n) + filtfilt(*low_pass, rng.normal(0, 0.5, n)) for _ in range(2)])
    y = -0.4 * ht + filtfilt(*low_pass, rng.normal(0, 1.0, 2 * n))
    ok = np.ones(2 * n, dtype=bool)
    ok[400:430] = False
    u = 1.0 + 0.02 * ht
    cycle = np.repeat([0, 1], n)
    r = TrialRhythm(time_s=np.arange(2 * n) / 200.0, ht_deg=ht, plane_deg=np.zeros(2 * n), phase=np.ones(2 * n, int),
                    cycle=cycle, names=("ST_X_upward_rotation",), values_deg=y[:, None], u_deg=u[:, None],
                    measured=ok[:, None])
    h, grey, shown, lo, hi = _phase_curves(r, 0, 1.0, [np.flatnonzero(cycle == c) for c in (0, 1)])
    assert np.isnan(h).sum() == 1 and len(h) < n  # one break between the cycles; thinned
    assert _cycle_points(ht[:n]) == 2 * int(np.ceil(np.ptp(ht[:n]) / CYCLE_BIN_DEG))

    def every(ax, which):
        for c in (0, 1):
            sel = cycle == c
            ys = {"shown": np.where(ok, y, np.nan), "grey": np.where(ok, np.nan, y)}
            if which == "band":
                ax.fill_between(ht[sel], np.where(ok, y - 2 * u, np.nan)[sel], np.where(ok, y + 2 * u, np.nan)[sel],
                                color="tab:blue", alpha=0.15, lw=0)
            else:
                ax.plot(ht[sel], ys[which][sel], color="tab:blue", lw=1.3)

    def thin(ax, which):
        if which == "band":
            ax.fill_between(h, lo, hi, color="tab:blue", alpha=0.15, lw=0)
        else:
            ax.plot(h, {"shown": shown, "grey": grey}[which], color="tab:blue", lw=1.3)

    for which in ("shown", "grey", "band"):
        for dpi, apart in ((110, 1.0), (330, 2.5)):
            inked = [_inked(draw, which, ((0, 180), (-60, 5)), (0.06, 0.55, 0.2, 0.3), dpi) for draw in (every, thin)]
            assert _apart_px(*inked) <= apart, (which, dpi)
