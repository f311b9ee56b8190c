"""exubio.report.viewer: the self-contained 3D HTML view of a reconstruction.

Data tests read the page without a browser: the JSON block ``exubio-data`` and the plotly figure
itself (its animation frames, traces and marker names) against the result files of a real
reconstruction of the shipped example (PF and LS). The browser test loads the page in a real
headless Chromium (skipped when none is installed: ``apt-get install -y chromium``), checks that
plotly rendered both WebGL scenes with every frame and that no JavaScript error happened, and that
the screenshot shows the bones in both scenes.
"""
from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError
from exubio.io.results import read_npz, read_npz_metadata, write_npz
from exubio.model.load import DEFAULT_MODEL, load_model
from exubio.run.inputs import load_session
from exubio.run.pipeline import reconstruct_file
from exubio.io.resources import shipped_file
from exubio.report.viewer import MAX_ANIMATION_FRAMES, find_results, write_view

pytestmark = [pytest.mark.exudyn, pytest.mark.slow]

EXAMPLE = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
BONE_RGB = (0x7A, 0x4B, 0x1E)  # exubio.report.viewer._BONE_COLOUR


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
def page_data(html_text: str) -> dict:
    m = re.search(r'<script id="exubio-data" type="application/json">(.*?)</script>', html_text, re.S)
    assert m, "no exubio-data block"
    return json.loads(m.group(1))


def plotly_call(html_text: str) -> tuple[list, dict, list]:
    """(data, layout, frames) of the plotly figure embedded in the page."""
    dec = json.JSONDecoder()
    start = html_text.index("Plotly.newPlot(")
    pos = html_text.index("[", start)
    data, end = dec.raw_decode(html_text, pos)
    pos = html_text.index("{", end)
    layout, _ = dec.raw_decode(html_text, pos)
    start = html_text.index("Plotly.addFrames(")
    pos = html_text.index("[", start)
    frames, _ = dec.raw_decode(html_text, pos)
    return data, layout, frames


def copy_result(src: Path, dst_dir: Path, *, metadata: dict | None = None, name: str | None = None) -> Path:
    """A copy of an .npz (optionally with other metadata) in another folder, without its summary."""
    dst_dir.mkdir(parents=True, exist_ok=True)
    dst = dst_dir / (name or src.name)
    meta = read_npz_metadata(src) if metadata is None else metadata
    extra = {"undetermined": np.load(src)["undetermined"]}
    write_npz(dst, read_npz(src), metadata=meta, extra_arrays=extra)
    return dst


# --------------------------------------------------------------------------------------------
# fixtures: a real reconstruction of the shipped example, PF and LS
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("view_results")
    reconstruct_file(EXAMPLE, out, methods=["pf", "ls"])
    return out


@pytest.fixture(scope="module")
def page(results, tmp_path_factory):
    html_path = tmp_path_factory.mktemp("view") / "example.html"
    t0 = time.perf_counter()
    write_view([results / "example_abduction.pf.npz"], html_path)
    return html_path, time.perf_counter() - t0


# --------------------------------------------------------------------------------------------
# the page's data, without a browser
# --------------------------------------------------------------------------------------------
def test_page_data_frames_markers_methods_verdicts(results, page):
    html_path, seconds = page
    text = html_path.read_text(encoding="utf-8")
    data = page_data(text)
    pf, ls = read_npz(results / "example_abduction.pf.npz"), read_npz(results / "example_abduction.ls.npz")
    summaries = {m: json.loads((results / f"example_abduction.{m}.summary.json").read_text(encoding="utf-8")) for m in ("pf", "ls")}

    assert data["methods"] == ["pf", "ls"]  # the LS result beside the PF one was found
    assert data["verdicts"] == {m: s["quality"]["verdict"] for m, s in summaries.items()}
    assert data["verdict_reasons"] == {m: s["quality"]["reasons"] for m, s in summaries.items()}
    assert data["marker_names"] == list(pf.marker_names)
    assert data["n_frames_total"] == pf.n_frames == 1000
    step = math.ceil(1000 / MAX_ANIMATION_FRAMES)
    assert data["frame_step"] == step == 4 and data["n_frames_shown"] == 250
    assert data["time_s"] == pytest.approx(pf.time_s[::step].tolist())
    assert any("one frame in 4 is shown" in n for n in data["notes"])  # the decimation is said on the page
    assert "one frame in 4 is shown (250 of 1000 frames" in text
    assert data["model"] == str(DEFAULT_MODEL)
    assert data["model_constraint_mismatch"]["pf"] < 1e-9 and data["model_constraint_mismatch"]["ls"] < 1e-9
    assert data["mean_residual_mm"]["pf"] == pytest.approx(np.nanmean(pf.residuals_m) * 1000, abs=1e-3)
    assert data["marker_segments"]["CLAV_AC"] == "clavicle" and data["marker_segments"]["EPI_lat"] == "humerus"
    assert data["marker_segments"]["SCAP_IA"] == "scapula" and data["marker_segments"]["MET2"] == "hand"
    verdicts = " · ".join(f"{m.upper()}: {data['verdicts'][m].upper()}" for m in ("pf", "ls"))
    assert re.search(r"<title>[^<]*" + re.escape(verdicts) + r"</title>", text)  # the verdict in the title

    # the plotly figure: one animation frame per shown frame, PF and LS scenes side by side
    traces, layout, frames = plotly_call(text)
    assert len(frames) == data["n_frames_shown"]
    assert "scene" in layout and "scene2" in layout
    assert layout["scene"]["domain"]["x"][1] <= layout["scene2"]["domain"]["x"][0]
    assert len(layout["sliders"][0]["steps"]) == len(frames)
    assert [b["label"] for b in layout["updatemenus"][0]["buttons"]] == ["▶ Play", "❚❚ Pause"]
    assert "OK" in layout["title"]["text"] or "CHECK" in layout["title"]["text"] or "FAIL" in layout["title"]["text"]
    names = [t["name"] for t in traces]
    ellipsoid = "thorax ellipsoid (scapula glides on it)"
    assert names.count(ellipsoid) == 2 and names.count("bones") == 2
    # the body: the ellipsoid at the model's place and size, the torso's ISB landmarks, a legend of
    # the segments whose points are drawn (their colours), nothing shown that only a test reads
    model = load_model(DEFAULT_MODEL)
    mesh = traces[names.index(ellipsoid)]
    xyz = np.column_stack([mesh[c] for c in "xyz"]).astype(float)
    centre, radii = np.asarray(model.ellipsoid.centre_m) * 1000, np.asarray(model.ellipsoid.radii_m) * 1000
    np.testing.assert_allclose((xyz.max(axis=0) + xyz.min(axis=0)) / 2, centre, atol=1.0)
    np.testing.assert_allclose((xyz.max(axis=0) - xyz.min(axis=0)) / 2, radii, rtol=0.02)
    torso = traces[names.index("thorax landmarks")]
    for name in ("IJ", "C7", "T8", "PX"):
        i = torso["text"].index(name)
        np.testing.assert_allclose([torso[c][i] for c in "xyz"], np.asarray(model.segments[0].points[name]) * 1000,
                                   atol=0.051)
    legend = [n for n, t in zip(names, traces) if t.get("legendgroup") == "segments"]
    assert legend == [f"{g} points" for g in model.segment_names if g in data["marker_segments"].values()]
    assert "Long trial" not in text
    assert names.count("measured markers") == 2 and names.count("model points") == 2
    assert names.count("residuals (marker to model point)") == 2
    measured = [i for i, t in enumerate(traces) if t["name"] == "measured markers"]
    for t in (traces[i] for i in measured):
        assert [s.split(" ")[0] for s in t["text"]] == list(pf.marker_names)
    # frame k of the PF scene holds the measured markers of frame k*step in mm
    animated = frames[0]["traces"]
    assert len(animated) == 8 and all(len(f["data"]) == 8 for f in frames)
    k = 100
    slot = animated.index(measured[0])
    xyz = np.column_stack([frames[k]["data"][slot][c] for c in "xyz"]).astype(float)
    np.testing.assert_allclose(xyz, pf.measured_m[k * step] * 1000.0, atol=0.051)
    slot_ls = animated.index(measured[1])
    xyz_ls = np.column_stack([frames[k]["data"][slot_ls][c] for c in "xyz"]).astype(float)
    np.testing.assert_allclose(xyz_ls, ls.measured_m[k * step] * 1000.0, atol=0.051)
    # residual lines: measured -> model point, a break after each
    res_slot = animated.index(names.index("residuals (marker to model point)"))
    x = frames[k]["data"][res_slot]["x"]
    assert len(x) == 3 * len(pf.marker_names) and x[2::3] == [None] * len(pf.marker_names)
    assert x[1] == pytest.approx(pf.model_points_m[k * step, 0, 0] * 1000.0, abs=0.051)

    # self-contained: plotly.js embedded, nothing fetched from the network
    assert not re.search(r"<script[^>]+src=", text)
    assert not re.search(r"<link[^>]+href=", text) and "Plotly.newPlot" in text
    assert re.search(r"plotly\.js v\d+\.\d+\.\d+", text)  # the library itself is inlined
    size_mb = html_path.stat().st_size / 1e6
    assert 3.0 < size_mb < 20.0, size_mb
    print(f"\nview of the example (PF+LS, {len(frames)} frames): {size_mb:.1f} MB, written in {seconds:.2f} s")


def test_given_the_ls_result_shows_pf_first_and_same_page(results, tmp_path):
    out = write_view([results / "example_abduction.ls.npz"], tmp_path / "v.html")
    assert page_data(out.read_text(encoding="utf-8"))["methods"] == ["pf", "ls"]
    assert find_results([results / "example_abduction.ls.npz"]) == [
        results / "example_abduction.pf.npz", results / "example_abduction.ls.npz"]


def test_one_method_alone_and_verdict_from_metadata(results, tmp_path):
    src = results / "example_abduction.pf.npz"
    # no summary.json beside it: verdict unknown, said on the page
    lone = copy_result(src, tmp_path / "lone")
    data = page_data(write_view([lone], tmp_path / "lone.html").read_text(encoding="utf-8"))
    assert data["methods"] == ["pf"] and data["verdicts"] == {"pf": "unknown"}
    _, layout, frames = plotly_call((tmp_path / "lone.html").read_text(encoding="utf-8"))
    assert "scene2" not in layout and len(frames[0]["data"]) == 4
    # a verdict in the npz metadata is used when there is no summary.json
    meta = {**read_npz_metadata(src), "quality": {"verdict": "check", "reasons": ["because"]}}
    tagged = copy_result(src, tmp_path / "tagged", metadata=meta)
    data = page_data(write_view([tagged], tmp_path / "tagged.html").read_text(encoding="utf-8"))
    assert data["verdicts"] == {"pf": "check"} and data["verdict_reasons"] == {"pf": ["because"]}


def test_long_trials_are_decimated(results, tmp_path):
    out = write_view([results / "example_abduction.pf.npz"], tmp_path / "d.html", max_frames=7)
    data = page_data(out.read_text(encoding="utf-8"))
    _, layout, frames = plotly_call(out.read_text(encoding="utf-8"))
    assert data["frame_step"] == 143 and data["n_frames_shown"] == len(frames) == 7
    assert len(layout["sliders"][0]["steps"]) == 7
    assert "one frame in 143 is shown (7 of 1000 frames" in out.read_text(encoding="utf-8")


def test_overwrite_is_refused_unless_asked(results, tmp_path):
    target = tmp_path / "sub" / "v.html"
    write_view([results / "example_abduction.pf.npz"], target, max_frames=3)
    before = target.read_bytes()
    with pytest.raises(InputError, match="already exists"):
        write_view([results / "example_abduction.pf.npz"], target, max_frames=4)
    assert target.read_bytes() == before
    write_view([results / "example_abduction.pf.npz"], target, max_frames=4, overwrite=True)
    assert page_data(target.read_text(encoding="utf-8"))["n_frames_shown"] == 4
    assert not list(target.parent.glob(".*tmp*"))  # atomic write left nothing behind


def test_bad_input_names_the_file(tmp_path):
    missing = tmp_path / "nope.pf.npz"
    with pytest.raises(InputError, match=re.escape(str(missing))):
        write_view([missing], tmp_path / "v.html")
    text = tmp_path / "text.pf.npz"
    text.write_text("not a zip", encoding="utf-8")
    with pytest.raises(InputError, match=re.escape(str(text))):
        write_view([text], tmp_path / "v.html")
    foreign = tmp_path / "foreign.pf.npz"
    with open(foreign, "wb") as fh:
        np.savez(fh, a=np.zeros(3))
    with pytest.raises(InputError, match=re.escape(str(foreign))):
        write_view([foreign], tmp_path / "v.html")
    npy = tmp_path / "array.pf.npz"
    with open(npy, "wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(InputError, match=re.escape(str(npy))):
        write_view([npy], tmp_path / "v.html")
    assert not (tmp_path / "v.html").exists()


def test_model_is_recovered_or_asked_for(results, tmp_path):
    src = results / "example_abduction.pf.npz"
    meta = read_npz_metadata(src)
    # the shipped generic model, named by a path of another installation
    moved = copy_result(src, tmp_path / "a", metadata={**meta, "model": "/elsewhere/models/upper_extremity.yaml"})
    assert page_data(write_view([moved], tmp_path / "a.html").read_text(encoding="utf-8"))["model"] == str(DEFAULT_MODEL)
    # an unknown model file that cannot be found: an InputError that says how to give it
    lost = copy_result(src, tmp_path / "b", metadata={**meta, "model": "/elsewhere/subject.yaml"})
    with pytest.raises(InputError, match=r"subject\.yaml.*model_path"):
        write_view([lost], tmp_path / "b.html")
    out = write_view([lost], tmp_path / "b.html", model_path=DEFAULT_MODEL)
    assert page_data(out.read_text(encoding="utf-8"))["model"] == str(DEFAULT_MODEL)


def test_subject_model_beside_moved_results_and_a_wrong_model_is_flagged(tmp_path):
    """A run with its own model file (as a calibrated <trial>.model.yaml): the results folder is
    moved, the model is found beside the results; the generic model instead is flagged."""
    run = tmp_path / "run"
    run.mkdir()
    text = Path(DEFAULT_MODEL).read_text(encoding="utf-8")
    radii = re.search(r"radii_mm: \[([^\]]+)\]", text)
    bigger = ", ".join(f"{float(v) * 1.03:.6f}" for v in radii.group(1).split(","))
    subject = run / "subject.model.yaml"
    subject.write_text(text.replace(radii.group(0), f"radii_mm: [{bigger}]"), encoding="utf-8")
    reconstruct_file(EXAMPLE, run, methods=["ls"], session=load_session(model_path=subject))
    moved = tmp_path / "moved"
    shutil.move(str(run), str(moved))
    out = write_view([moved / "example_abduction.ls.npz"], tmp_path / "v.html")
    data = page_data(out.read_text(encoding="utf-8"))
    assert data["model"] == str(moved / "subject.model.yaml") and data["methods"] == ["ls"]
    assert data["model_constraint_mismatch"]["ls"] < 1e-9 and not any("WARNING" in n for n in data["notes"])
    out = write_view([moved / "example_abduction.ls.npz"], tmp_path / "w.html", model_path=DEFAULT_MODEL)
    data = page_data(out.read_text(encoding="utf-8"))
    assert data["model_constraint_mismatch"]["ls"] > 1e-3
    assert any("WARNING" in n and "not the model of the run" in n for n in data["notes"])


# --------------------------------------------------------------------------------------------
# a real headless browser
# --------------------------------------------------------------------------------------------
def chromium_binary() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


def run_chromium(html_path: Path, png: Path) -> tuple[str, float]:
    """Load the page headless; returns (the DOM after the scripts ran, seconds). WebGL runs on
    SwiftShader (software), which recent Chromium enables only when asked."""
    exe = chromium_binary()
    if exe is None:
        pytest.skip("no chromium binary (apt-get install -y chromium)")
    cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
           f"--screenshot={png}", "--window-size=1200,800", "--virtual-time-budget=10000", "--dump-dom",
           html_path.resolve().as_uri()]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, encoding="utf-8", errors="replace", timeout=180)
    seconds = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout, seconds


def test_page_renders_in_headless_chromium(page, tmp_path):
    html_path, _ = page
    png = tmp_path / "view.png"
    dom, seconds = run_chromium(html_path, png)
    print(f"\nchromium: {seconds:.1f} s")
    errors = re.search(r'<pre id="exubio-errors"([^>]*)>(.*?)</pre>', dom, re.S)
    assert errors and errors.group(2).strip() == "" and "hidden" in errors.group(1), errors.group(2)
    assert "WebGL is not supported" not in dom.split("</script>")[-1]
    status = re.search(r'<p id="exubio-status"([^>]*)>([^<]*)</p>', dom)
    assert status, "status paragraph missing"
    attrs = dict(re.findall(r'data-([a-z]+)="([^"]*)"', status.group(1)))
    data = page_data(html_path.read_text(encoding="utf-8"))
    assert int(attrs["frames"]) == data["n_frames_shown"] == 250  # the live plot holds every frame
    traces, _, _ = plotly_call(html_path.read_text(encoding="utf-8"))
    assert int(attrs["traces"]) == len(traces) and int(attrs["canvases"]) >= 2  # every trace, 2 WebGL scenes
    assert "hidden" in status.group(1)  # the render check is for the test, not shown to the reader
    assert attrs["external"] == ""  # nothing was loaded from the network: it works offline
    assert re.search(r'class="[^"]*js-plotly-plot', dom)
    assert dom.count('class="gl-container"') == 2 or dom.count("<canvas") >= 2
    assert "slider-container" in dom and "updatemenu-container" in dom

    Image = pytest.importorskip("PIL.Image")  # Pillow comes with matplotlib
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert img.shape == (800, 1200, 3)
    assert img.std() > 10 and len(np.unique(img.reshape(-1, 3), axis=0)) > 200  # not blank
    # the bones (their colour) are drawn in both scenes: left and right half of the plot area
    near_bone = np.abs(img - np.array(BONE_RGB)).sum(axis=2) < 60
    left, right = near_bone[120:600, :600].sum(), near_bone[120:600, 600:].sum()
    assert left > 300 and right > 300, (left, right)


def test_a_javascript_error_is_caught_by_the_page_check(page, tmp_path):
    """The error check is not vacuous: a page that throws shows the error in the dumped DOM."""
    html_path, _ = page
    broken = tmp_path / "broken.html"
    text = html_path.read_text(encoding="utf-8")
    broken.write_text(text.replace("</body>", "<script>throw new Error('exubio-test-error');</script></body>"),
                      encoding="utf-8")
    dom, _ = run_chromium(broken, tmp_path / "broken.png")
    errors = re.search(r'<pre id="exubio-errors"([^>]*)>(.*?)</pre>', dom, re.S)
    assert errors and "exubio-test-error" in errors.group(2)


def test_cli_view_writes_the_page_and_refuses_bad_input(results, tmp_path, capsys):
    """`exubio view RESULT.npz --out FILE.html`: exit 0 and the page; again without --overwrite, or
    with a file that is not a result: exit 2 naming the file."""
    from exubio.cli import main

    npz = results / "example_abduction.pf.npz"
    out = tmp_path / "v.html"
    assert main(["-q", "view", str(npz), "--out", str(out)]) == 0
    assert page_data(out.read_text(encoding="utf-8"))["methods"]
    assert main(["-q", "view", str(npz), "--out", str(out)]) == 2
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    assert main(["-q", "view", str(bad), "--out", str(tmp_path / "b.html")]) == 2
    assert "bad.npz" in capsys.readouterr().err
