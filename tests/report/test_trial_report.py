"""The trial report's drawing shortcuts give the report matplotlib draws without them: page 1 and
the plot pages drawn into the figures of the previous report (exubio.report.trial_report keeps them
per process) are byte for byte those of new figures, whatever the order of the trials; text wrapped
by bisection breaks where matplotlib's own wrapping does, also with the lines and widths kept from
earlier drawings; titles fixed in place sit where matplotlib puts them."""
from __future__ import annotations

import dataclasses
import io
import random
import re

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text
from page_layout import laid_out_apart

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.report import trial_report as tr
from exubio.report import page_figures
from exubio.synth.simulate import simulate_trial

pytestmark = pytest.mark.exudyn


def _without_date(pdf: bytes) -> bytes:
    return re.sub(rb"/CreationDate \(D:[0-9Z'+-]+\)", b"", pdf)


@pytest.fixture(scope="module")
def result_sets(tmp_path_factory):
    """Result folders of short simulated trials: PF and LS, a marker gap, a calibration page."""
    tmp = tmp_path_factory.mktemp("trial_reports")
    model = load_model()
    sets = {}
    for name, motion, methods, extra, gap in (("both", "abduction", "both", [], False),
                                              ("gap", "flexion", "pf", [], True),
                                              ("calibrated", "abduction", "ls", ["--static-frames", "0:20"], False)):
        trial = simulate_trial(model, motion, duration_s=1.0, rate_hz=100.0, noise_mm=0.5, seed=len(sets) + 3)
        traj = trial.trajectories
        if gap:
            pos = traj.positions_m.copy()
            pos[30:45, traj.labels.index("MET5")] = np.nan
            traj = dataclasses.replace(traj, positions_m=pos)
        path = write_c3d(tmp / f"{name}.c3d", traj)
        out = tmp / name
        main(["-q", "reconstruct", str(path), "--method", methods, "--out", str(out), "--no-report", *extra])
        sets[name] = sorted(out.glob("*.npz"))
        assert sets[name], name
    return sets


def test_reports_drawn_into_reused_figures_are_those_of_new_figures(result_sets, tmp_path):
    items = list(result_sets.items()) + [(f"both {p.name}", [p]) for p in result_sets["both"]]  # PF, LS alone
    fresh = {}
    for name, npz in items:
        page_figures._FREE_PAGES.clear()
        pdf, png = tr.build_trial_report(npz, tmp_path / "fresh.report.pdf")
        fresh[name] = (_without_date(pdf.read_bytes()), png.read_bytes())
    page_figures._FREE_PAGES.clear()
    for name, npz in items + items[::-1]:
        pdf, png = tr.build_trial_report(npz, tmp_path / "reused.report.pdf")
        assert (_without_date(pdf.read_bytes()), png.read_bytes()) == fresh[name], name
    # the plot pages went back for the next report: per layout, as many figures as one report draws at
    # once (a rhythm page per method: 2 for PF and LS), not one per report
    kept = {key[0]: len(figs) for key, figs in page_figures._FREE_PAGES.items()}
    assert kept == {"verdict": 1, "angles": 1, "residuals": 1, "rhythm": 2}, kept


def test_a_page_function_hands_out_a_figure_no_report_will_draw_into(result_sets):
    from exubio.io.results import read_npz, read_npz_metadata

    npz = result_sets["both"]
    recons = [read_npz(p) for p in npz]
    angles = {r.method: tr.read_angles(p) for p, r in zip(npz, recons)}
    first = tr.angles_page(recons, read_npz_metadata(npz[0]), {}, angles=angles)
    second = tr.angles_page(recons, read_npz_metadata(npz[0]), {}, angles=angles)
    assert first is not second and all(first is not f for figs in page_figures._FREE_PAGES.values() for f in figs)


def test_bisection_wraps_where_matplotlib_wraps():
    rng = random.Random(0)
    words = ("the quick brown fox jumps over a lazy dog; marker EPI_lat, SCAP_IA: 12.5 mm (RMSE) -> swapped "
             "calibrated_on_a_long_static_trial_name.c3d").split()
    for k in range(30):
        lines = [" ".join(rng.choice(words) for _ in range(rng.randint(1, 70))) for _ in range(rng.randint(1, 5))]
        if k % 5 == 0:
            lines.append("x" * 260)  # a word wider than the page
        fig = tr._figure()
        text = tr._bisect_wrap(fig.text(rng.uniform(0.0, 0.6), 0.9, "\n".join(lines), wrap=True, va="top",
                                        fontsize=rng.choice([7, 8, 11]), family=rng.choice(["monospace", "sans-serif"]),
                                        ha=rng.choice(["left", "center", "right"])))
        for dpi in (72, 110):
            fig.set_dpi(dpi)
            fig.canvas.draw()
            assert text._get_wrapped_text() == Text._get_wrapped_text(text)
        assert text._get_wrapped_text().count("\n") > len(lines) - 1 or k % 5  # something was wrapped


def test_wrapped_lines_kept_are_those_of_the_renderer_that_draws():
    """The lines and widths page_figures keeps are reused only where matplotlib would measure the
    same: each drawing (Agg at two dpi, the PDF, another font size, another place on the page) breaks
    the text where matplotlib's own wrapping does for that renderer, and a page drawn with the kept
    lines is byte for byte the page drawn with none kept."""
    words = ("calibration (static_trial.c3d): marker ULNA is 58 mm from the model's point; the verdict is "
             "check: read the reasons before using the angles, thresholds in exubio/trust/quality.py").split()
    body = " ".join(words * 3)

    def page(x: float, size: float) -> tuple[Figure, Text]:
        fig = tr._figure()
        return fig, tr._bisect_wrap(fig.text(x, 0.9, body, wrap=True, va="top", fontsize=size))

    def drawn(fig: Figure, fmt: str, dpi: float) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format=fmt, dpi=dpi, metadata={"CreationDate": None} if fmt == "pdf" else None)
        return buf.getvalue()

    page_figures._WRAPS.clear()
    page_figures._WIDTHS.clear()
    states = [(0.04, 7, "png", 110), (0.04, 7, "pdf", 72), (0.04, 7, "png", 72), (0.04, 9, "png", 110),
              (0.04, 9, "pdf", 72), (0.3, 7, "png", 110), (0.3, 7, "pdf", 72)]
    kept, lines = {}, set()
    for x, size, fmt, dpi in states + states[::-1]:  # the second time round, every wrap is a kept one
        fig, text = page(x, size)
        kept[(x, size, fmt, dpi)] = drawn(fig, fmt, dpi)
        assert text._get_wrapped_text() == Text._get_wrapped_text(text), (x, size, fmt, dpi)
        lines.add(text._get_wrapped_text())
    assert len(lines) >= 4  # the renderers, sizes and places do break the lines differently
    for state in states:
        page_figures._WRAPS.clear()
        page_figures._WIDTHS.clear()
        assert drawn(*page(*state[:2])[:1], *state[2:]) == kept[state], state


def _titled_page(pin: bool):
    fig = tr._figure()
    axes = fig.subplots(2, 3, sharex=True)
    t = np.linspace(0.0, 10.0, 200)
    for k, ax in enumerate(axes.flat):
        y = np.sin(t + k) * 10.0 ** k
        if k == 4:
            y = 1e5 + 1e-3 * np.sin(t)  # an offset text ("+1e5") at the top of the y axis
        ax.plot(t, y)
        ax.set_title(f"panel {k}: a title long enough to reach the axis corner", fontsize=7)
    axes[1, 2].xaxis.set_label_position("top")
    axes[1, 2].set_xlabel("time (s), on top")
    fig.subplots_adjust(hspace=0.5)
    return tr._pin_titles(fig) if pin else fig


def test_titles_are_fixed_only_where_matplotlib_would_leave_them():
    pinned = _titled_page(True)
    auto = [ax._autotitlepos for ax in pinned.axes]
    assert auto == [False, False, False, False, True, True]  # offset text; x label on top
    images = []
    for fig in (pinned, _titled_page(False)):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=80)
        images.append(buf.getvalue())
    assert images[0] == images[1]


def _page_one(npz_paths, summaries):
    from exubio.io.results import read_npz, read_npz_metadata

    recons = [read_npz(p, points=False) for p in npz_paths]
    angles = {r.method: tr.read_angles(p) for p, r in zip(npz_paths, recons)}
    return tr.verdict_page(recons, read_npz_metadata(npz_paths[0]), summaries, angles=angles), recons


@pytest.mark.parametrize("n_reasons", [1, 4, 30])
def test_page_one_never_overlaps_whatever_the_number_of_reasons(result_sets, n_reasons):
    """Page 1 a supervisor reads: however many and however long the reasons, no text block overlaps
    another or the picture, every one stays on the page, a reason both methods give is written
    once, absolute paths are written as file names, and what does not fit is counted."""
    import json

    paths = result_sets["both"]
    long = ("calibration (/very/long/folder/of/the/lab/session/static_trial.c3d): marker ULNA is 58 mm from the "
            "landmark it is declared over (above 40 mm): misplaced, mislabelled, or a wrong static pose; " * 2)
    summaries = {}
    for p in paths:
        s = json.loads((p.parent / (p.name[:-len(".npz")] + ".summary.json")).read_text())
        method = s["method"]
        s["quality"] = {"verdict": "check", "reasons": [{"code": "x", "level": "check", "message": f"{k}: {long}"}
                                                        for k in range(n_reasons)]
                        + [{"code": "y", "level": "note", "message": f"{method} only"}]}
        summaries[method] = s
    fig, recons = _page_one(paths, summaries)
    fig.set_dpi(tr.PAGE1_DPI)
    boxes = laid_out_apart(fig)
    texts = [t for t, _ in boxes]
    assert sum(t.startswith("check: 0: ") for t in texts) == 1  # both methods' reason, once
    assert all("/very/long" not in t for t in texts) and any("static_trial.c3d" in t for t in texts)
    assert {f"note: {r.method} only" for r in recons} <= set(texts)  # each method's own reason, under it
    if n_reasons == 30:
        assert any(t.startswith("... ") and "more" in t for t in texts)


def test_a_marker_absent_from_the_whole_trial_is_not_shaded_as_a_gap(tmp_path):
    """An optional marker the trial lacks (ELB, as in the shared C3D sessions) shaded the whole
    residual plot as an 837-frame gap; a real gap is still shaded, and the absent marker is named."""
    from exubio.io.results import read_npz, read_npz_metadata
    from exubio.synth.simulate import DEFAULT_MARKERS

    sim = simulate_trial(load_model(), "abduction", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=2,
                         marker_names=[m for m in DEFAULT_MARKERS if m != "ELB"])
    pos = sim.trajectories.positions_m.copy()
    pos[40:55, sim.trajectories.labels.index("ARM")] = np.nan  # one real gap, 15 frames
    path = write_c3d(tmp_path / "t.c3d", dataclasses.replace(sim.trajectories, positions_m=pos))
    assert main(["-q", "reconstruct", str(path), "--method", "ls", "--no-report", "--out", str(tmp_path / "o")]) == 0
    npz = tmp_path / "o" / "t.ls.npz"
    recon = read_npz(npz, points=False)
    assert {g.marker for g in recon.gaps} == {"ELB", "ARM"}  # ELB is in the protocol and missing throughout
    fig = tr.residuals_page([recon], read_npz_metadata(npz), {})
    ax = next(a for a in fig.axes if "marker gaps" in a.get_title())
    shaded = [p for p in ax.patches if p.get_facecolor()[:3] == pytest.approx((1.0, 0.647, 0.0), abs=0.01)]
    assert len(shaded) == 1
    x0, width = shaded[0].get_x(), shaded[0].get_width()  # a Rectangle spanning the gap's times
    assert (x0, x0 + width) == pytest.approx((recon.time_s[40], recon.time_s[54]))
    text = " ".join(t.get_text() for a in fig.axes for t in a.texts)
    assert "absent from the whole trial" in text and "ELB" in text


def test_the_calibration_page_is_readable_whatever_the_checks_say():
    """It was small text on an empty page, a check cut at 170 characters ('...an implausible postur'):
    now every text block stays on the page and apart from the others and the marker chart, each
    check is written in full (paths as file names) up to a count of the rest, the worst landmark
    distance is marked."""
    from exubio.report.calibration_page import calibration_page

    markers = {f"M{k:02d}": {"segment": "humerus", "registered": k != 3, "residual_mm": 0.1 * k,
                             "generic_offset_mm": 5.0 * k} for k in range(20)}
    rep = {"frames": {"start": 0, "stop": 50, "n_frames": 50, "chosen_automatically": True},
           "scale_factors": {s: 1.0 for s in ("thorax", "clavicle", "scapula", "humerus", "ulna", "radius", "hand")},
           "ellipsoid": {"centre_mm": [-90.4, -46.0, 0.0], "radii_mm": [80.0, 130.0, 123.0]},
           "joint_centres_mm": {"definition": "x", "gh": [1.0, 2.0, 3.0], "elbow": [4.0, 5.0, 6.0]},
           "static_pose_deg": {f"q{k}": float(k) for k in range(13)}, "static_pose_at_limit_deg": {"q2": 2.0},
           "markers": markers, "landmark_offsets_mm": {"M05": 12.0, "M07": 58.0, "M09": 20.0}}
    end = "and this is the last word of a long check: posture"
    long = "calibration (/a/very/long/folder/of/the/session/static_trial.c3d): marker M07 is 58 mm from its landmark; " * 3
    for n_checks in (1, 12):
        reasons = [{"code": "calibration_landmark", "level": "check", "message": f"{k}: {long}{end}"}
                   for k in range(n_checks)]
        fig = calibration_page({}, {"pf": {"calibration": {"static": "/x/static.c3d", "report": rep},
                                           "quality": {"reasons": reasons}}})
        boxes = laid_out_apart(fig)
        text = " ".join(t for t, _ in boxes).replace("\n    ", " ")
        assert end in text and "/a/very/long" not in text and "static_trial.c3d" in text
        assert (" more in the summary.json" in text) == (n_checks == 12)
        labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
        assert "M07 (worst)" in labels
