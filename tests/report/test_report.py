"""The validation study and its report: a quick run writes the data files, the PDF with the
expected pages and the PNGs; the typed results go through the files and back unchanged, and files
that do not fit them are refused; the report is rebuilt from the files alone without importing the
solver; the bundled Ludewig et al. 2009 data; the real-trial plumbing (skipped without
../shared/data)."""
from __future__ import annotations

import ast
import copy
import dataclasses
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from exubio.literature.invivo import ANGLE_KEYS as LUDEWIG_COLUMNS
from exubio.literature.reference import load_ludewig2009
from exubio.report import FIGURES, REPORT_PAGES
from exubio.validation import SchemaError, ValidationResults, run_validation
from exubio.validation.determinacy import undetermined_coordinates, unobserved_segments
from exubio.validation.paths import portable_paths, shared_data_dir
from exubio.validation.results import DATA_NPZ, RUNS_JSON, TABLE1_JSON
from exubio.validation.trials import real_trial, why_no_real_trial

pytestmark = pytest.mark.exudyn

PACKAGE = Path(__file__).resolve().parents[2] / "exubio"
SOLVER_MODULES = ("exubio.methods", "exubio.backend", "exubio.run.pipeline", "exudyn", "exubio.calibration",
                  "exubio.validation.run", "exubio.validation.trials")


def _pdf_pages(path: Path) -> int:
    return len(re.findall(rb"/Type\s*/Page[^s]", path.read_bytes()))


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("validation")
    messages: list[str] = []
    results = run_validation(out, quick=True, progress=messages.append)
    return out, results, messages


def test_quick_run_writes_every_file(quick):
    out, runs, messages = quick
    for name in ("validation.pdf", "validation_data.npz", "table1.json", "validation_runs.json", *FIGURES):
        assert (out / name).is_file(), name
    for png in FIGURES:
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert _pdf_pages(out / "validation.pdf") >= len(REPORT_PAGES)
    assert not list(out.glob("*.tmp*"))
    assert any("sensitivity" in m for m in messages)


def test_quick_run_content(quick):
    out, r, _ = quick
    assert isinstance(r, ValidationResults) and r.quick is True
    # provenance: a quick run uses simulated trials only, and says so
    assert {k: v.kind for k, v in r.data.items()} == {"abduction": "simulated", "flexion": "simulated",
                                                      "sier": "simulated"}
    assert r.data["abduction"].reason_not_real
    # the 32-run sensitivity grid
    sens = r.sensitivity
    assert sens.runs == 32 and len(sens.stiffness_n_per_m) == 8 and len(sens.ratio_s) == 4
    assert sens.stiffness_n_per_m[0] == pytest.approx(10.0) and sens.stiffness_n_per_m[-1] == pytest.approx(1e4)
    assert sens.mean_deflection_mm.shape == (4, 8) and sens.total_wall_s > 0
    with np.load(out / "validation_data.npz") as z:
        assert z["sens__mean_deflection_mm"].shape == (4, 8)
        assert z["res__sier__pf__mean_mm"].ndim == 1
        assert z["iv__abduction__pf__ST_deg"].shape[1] == 3
    # Table 1 rows with both methods and the paper's numbers beside them
    table = json.loads((out / "table1.json").read_text(encoding="utf-8"))
    assert set(table["rows"]) == {"abduction", "flexion", "sier"}
    for row in table["rows"].values():
        for method in ("pf", "ls"):
            assert row[method]["max_mean_residual_mm"] > 0
            assert isinstance(row[method]["max_residual_marker"], str)
    assert table["paper"]["sier"]["frames"] == 96001
    # SIER figures against the truth exist and are finite; the checks are recorded
    assert np.isfinite(r.sier.pf.gh_axial_rotation_rmse_deg)
    assert len(r.sier.pf.gh_marker_rmse_xyz_mm) == 3
    assert {c.what for c in r.checks} >= {"SIER: PF GH axial rotation RMSE vs truth"}
    assert all(isinstance(c.passed, bool) for c in r.checks)
    # simulated data with the full marker set: every coordinate determined but the clavicle's axial
    # rotation, which its two markers barely see, and the AC rotation that trades against it
    assert set(r.agreement.trials["sier"].undetermined_coordinates) == {"sc_posterior_rotation", "ac_upward_rotation"}
    # Ludewig deviations at the four elevations
    dev = r.invivo["abduction"].pf.angles["ST_medRotation_X"]
    assert len(dev.deviation_deg) == 4
    # like for like: Ludewig's definitions stated, the ISB-frame deviation beside, the corridor
    iv = r.invivo["abduction"]
    assert "TS>AC" in iv.definitions["ST"] and "xz'y''" in iv.definitions["GH"]
    assert len(dev.isb_frame_deviation_deg) == 4
    members = {m.study for m in iv.corridor["ST"].members}
    assert members == {"Ludewig et al. 2009", "Chu et al. 2012"}  # frontal plane, in vivo, buildable frames
    assert 0.0 <= dev.share_inside_corridor <= 1.0 and dev.corridor_studies == 2
    assert np.isnan(iv.pf.angles["GH_abduction_X"].share_inside_corridor)  # Ludewig alone in the frontal plane
    aims = r.invivo_aims
    assert any("ST upward rotation within 8 deg" in a.what for a in aims)
    assert any(a.passed is None and "not evaluable" in a.note for a in aims)
    assert r.invivo["flexion"].corridor["GH"].lo.shape == (181, 3)
    with np.load(out / "validation_data.npz") as z:
        assert z["iv__flexion__corridor__GH__lo"].shape == (181, 3)
    # validation_runs.json keeps the key names its readers use
    runs = json.loads((out / "validation_runs.json").read_text(encoding="utf-8"))
    assert runs["sensitivity"]["runs"] == 32 and runs["quick"] is True
    assert len(runs["invivo"]["abduction"]["pf"]["ST_medRotation_X"]["deviation_deg"]) == 4
    assert set(runs["agreement"]["sier"]["undetermined_coordinates"]) == {"sc_posterior_rotation", "ac_upward_rotation"}
    assert runs["invivo"]["abduction"]["pf"]["GH_abduction_X"]["share_inside_corridor"] is None  # NaN as null
    assert all(isinstance(c["passed"], bool) for c in runs["checks"])


# --------------------------------------------------------------------------------------------
# The typed results and their files
# --------------------------------------------------------------------------------------------
def test_results_go_through_the_files_unchanged(quick, tmp_path):
    """What the study returns equals what the report reads back from the files, and saving what
    was read writes the same files again."""
    out, results, _ = quick
    loaded = ValidationResults.load(out)
    assert loaded == results
    assert loaded.report_wall_s is not None and loaded.report_wall_s == results.report_wall_s
    loaded.save(tmp_path)
    for name in (RUNS_JSON, TABLE1_JSON):
        assert (tmp_path / name).read_bytes() == (out / name).read_bytes(), name
    with np.load(out / DATA_NPZ) as a, np.load(tmp_path / DATA_NPZ) as b:
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k
    # equality sees a changed number and a changed array
    assert dataclasses.replace(results, total_wall_s=results.total_wall_s + 1.0) != results
    sens = dataclasses.replace(results.sensitivity, wall_s=results.sensitivity.wall_s + 1.0)
    assert dataclasses.replace(results, sensitivity=sens) != results


def test_files_that_do_not_fit_the_results_are_refused(quick, tmp_path):
    """A key the records do not know or miss, an array no field reads or a missing one, a table1.json
    that disagrees with validation_runs.json: SchemaError, never a silently wrong report."""
    out, _, _ = quick
    runs = json.loads((out / RUNS_JSON).read_text(encoding="utf-8"))
    with np.load(out / DATA_NPZ) as z:
        arrays = {k: z[k] for k in z.files}
    assert ValidationResults.from_json(runs, arrays) == ValidationResults.load(out)
    extra = copy.deepcopy(runs)
    extra["sier"]["pf"]["gh_marker_rmse_mm"] = 1.0
    with pytest.raises(SchemaError, match="gh_marker_rmse_mm"):
        ValidationResults.from_json(extra, arrays)
    missing = copy.deepcopy(runs)
    del missing["table1"]["sier"]["ls"]["max_rmse_mm"]
    with pytest.raises(SchemaError, match="max_rmse_mm"):
        ValidationResults.from_json(missing, arrays)
    with pytest.raises(SchemaError, match="sier__spare"):
        ValidationResults.from_json(runs, {**arrays, "sier__spare": np.zeros(3)})
    with pytest.raises(SchemaError, match="sier__time_s"):
        ValidationResults.from_json(runs, {k: v for k, v in arrays.items() if k != "sier__time_s"})
    for name in (RUNS_JSON, DATA_NPZ):
        shutil.copy(out / name, tmp_path / name)
    table1 = json.loads((out / TABLE1_JSON).read_text(encoding="utf-8"))
    table1["rows"]["sier"]["frames"] += 1
    (tmp_path / TABLE1_JSON).write_text(json.dumps(table1), encoding="utf-8")
    with pytest.raises(SchemaError, match="disagrees"):
        ValidationResults.load(tmp_path)


def test_report_rebuilds_from_files_without_the_solver(quick, tmp_path):
    """The report reads the typed results from the files alone: neither the solver nor the study's
    own modules are imported."""
    out, _, _ = quick
    for name in ("validation_data.npz", "table1.json", "validation_runs.json"):
        (tmp_path / name).write_bytes((out / name).read_bytes())
    code = (
        "import sys\n"
        "from exubio.report import build_report\n"
        f"build_report({str(tmp_path)!r})\n"
        f"bad = [m for m in sys.modules if m.startswith({SOLVER_MODULES!r})]\n"
        "assert not bad, bad\n"
        "assert 'matplotlib.pyplot' not in sys.modules  # Agg canvases only, no global backend state\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=300)
    assert (tmp_path / "validation.pdf").is_file()
    for png in FIGURES:
        assert (tmp_path / png).is_file()


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_report_package_imports_no_solver():
    files = sorted((PACKAGE / "report").glob("*.py"))
    assert files
    for f in files:
        bad = [m for m in _imports(f) if m.startswith(SOLVER_MODULES) or m == "matplotlib.pyplot"]
        assert not bad, f"{f.name} imports {bad}"


def test_only_the_report_package_imports_matplotlib():
    for f in PACKAGE.rglob("*.py"):
        if "report" in f.relative_to(PACKAGE).parts:
            continue
        assert not [m for m in _imports(f) if m.split(".")[0] == "matplotlib"], f


# --------------------------------------------------------------------------------------------
# Reference data
# --------------------------------------------------------------------------------------------
def test_ludewig_data_file_is_cited_and_complete():
    path = PACKAGE / "data" / "ludewig2009.csv"
    header = "".join(line for line in path.read_text(encoding="utf-8").splitlines(keepends=True) if line.startswith("#"))
    for needle in ("Ludewig PM", "J Bone Joint Surg Am 91(2):378-389", "10.2106/JBJS.G.01483", "Spartacus",
                   "10.5281/zenodo.11455521"):
        assert needle in header
    data = load_ludewig2009()
    assert set(data) == {"frontal", "scapular", "sagittal"}
    for plane in data.values():
        np.testing.assert_array_equal(plane["ht_elevation_deg"], np.arange(30.0, 121.0, 5.0))
        for cols in LUDEWIG_COLUMNS.values():
            for c in cols:
                assert plane[c].shape == (19,)


def test_ludewig_values_match_the_published_tables():
    data = load_ludewig2009()
    f = data["frontal"]
    i = {h: int(np.flatnonzero(f["ht_elevation_deg"] == h)[0]) for h in (30, 60, 90, 120)}
    assert [f["ST_medRotation_X"][i[h]] for h in (30, 60, 90, 120)] == [-15.6, -26.5, -36.5, -46.4]
    assert [f["SC_elevation_X"][i[h]] for h in (30, 60, 90, 120)] == [-14.3, -16.8, -18.1, -19.5]
    s = data["sagittal"]
    assert s["GH_abduction_X"][i[90]] == -58.2 and s["ST_protraction_Y"][i[120]] == 43.5


# --------------------------------------------------------------------------------------------
# Observability and the real trials
# --------------------------------------------------------------------------------------------
def test_undetermined_coordinates():
    from exubio.run.inputs import load_model_and_protocol

    model, protocol = load_model_and_protocol()
    q = np.zeros((1, model.n_coordinates))
    q[0, model.coordinate_names.index("gh_abduction")] = 0.8
    assert max(undetermined_coordinates(model, protocol, q).values()) < 0.1
    assert unobserved_segments(model, protocol) == []
    no_forearm = protocol.__class__(**{**protocol.__dict__, "markers": tuple(
        m for m in protocol.markers if m.segment not in ("ulna", "radius", "hand"))})
    share = undetermined_coordinates(model, no_forearm, q)
    for c in ("elbow_flexion", "pronation", "wrist_flexion", "wrist_radial_deviation"):
        assert share[c] == pytest.approx(1.0)
    assert share["gh_abduction"] < 0.1
    assert unobserved_segments(model, no_forearm) == ["ulna", "radius", "hand"]


@pytest.mark.skipif(why_no_real_trial("abduction") is not None,
                    reason=f"real trial not available: {why_no_real_trial('abduction')}")
def test_real_trial_is_calibrated_and_prepared():
    model, protocol, targets, cal = real_trial("abduction")
    assert (shared_data_dir() / "trc").is_dir()
    assert "calibrated" in model.name
    assert set(protocol.marker_names) == {"aa", "ts", "ai", "gu", "EpL", "centelbow"}
    assert targets.n_frames == 1091
    assert cal.residual_mm.mean < 5.0


def test_a_calibrated_trial_report_has_a_calibration_page(tmp_path):
    """A trial reconstructed with a calibration: the PDF gets a page more with the scale factors,
    the joint centres, the static pose and every marker; without one it has four (verdict, anatomical
    angles, residuals, and the rhythm page of the arm's raise: exubio.report.rhythm_page)."""
    from exubio.cli import main
    from exubio.io.c3d import write_c3d
    from exubio.model.load import load_model
    from exubio.synth.simulate import simulate_trial

    trial = simulate_trial(load_model(), "abduction", duration_s=1.0, rate_hz=100.0, noise_mm=0.5, seed=2)
    path = write_c3d(tmp_path / "t.c3d", trial.trajectories)
    for extra, pages in (([], 4), (["--static-frames", "0:20"], 5)):
        out = tmp_path / f"out{pages}"
        main(["-q", "reconstruct", str(path), "--method", "ls", "--out", str(out), *extra])
        assert _pdf_pages(out / "t.report.pdf") == pages
    summary = json.loads((tmp_path / "out5" / "t.ls.summary.json").read_text(encoding="utf-8"))
    from exubio.report.trial_report import calibration_page

    fig = calibration_page({}, {"ls": summary})
    text = "\n".join([t.get_text() for t in fig.texts] + [t.get_text() for t in fig.axes[0].get_yticklabels()])
    for needle in ("segment scale factors\n  thorax", "joint centres, static pose", "  gh      [", "static pose (deg)",
                   "EPI_lat", "SCAP_FRONT"):
        assert needle in text, needle



def test_portable_paths_rewrites_this_machines_paths():
    """Absolute paths of the shared data and of the checkout, inside any string of a JSON-like
    object, become ../shared/data/... and ./...; other strings and numbers are left alone."""
    from exubio.io.resources import _CHECKOUT

    shared = shared_data_dir()
    obj = {"data": {"abduction": {"source": str(shared / "trc" / "a.trc"), "frames": 10}},
           "errors": [f"{shared.resolve() / 'trc' / 'b.trc'}: the PF solver stopped", "plain text"],
           "model": str(_CHECKOUT / "models" / "upper_extremity.yaml")}
    out = portable_paths(obj)
    assert out["data"]["abduction"] == {"source": "../shared/data/trc/a.trc", "frames": 10}
    assert out["errors"] == ["../shared/data/trc/b.trc: the PF solver stopped", "plain text"]
    assert out["model"] == "./models/upper_extremity.yaml"


def test_the_committed_validation_outputs_hold_no_absolute_path():
    """reports/validation/*.json as committed: no path of the machine that wrote them (they are
    compared across machines)."""
    folder = Path(__file__).resolve().parents[2] / "reports" / "validation"
    files = sorted(folder.glob("*.json"))
    if not files:
        pytest.skip(f"{folder} has no validation outputs")
    for path in files:
        for value in re.findall(r'"([^"]*)"', path.read_text(encoding="utf-8")):
            assert not re.search(r"(^|[\s'(])(/[A-Za-z]|[A-Za-z]:\\)", value), (path.name, value)
