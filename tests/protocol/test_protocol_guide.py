"""The docs' "Write a protocol for your marker set" (docs/protocols.md) followed step by step for a marker set exubio
does not ship: its protocol (the page's YAML block) is checked by `exubio protocols`, its
technical markers' places are read off `exubio model-points` (step 4), a trial of that marker set
is simulated and reconstructed, and what the guide says of it holds: the measured angles exact
noise-free, the held girdle angles marked as modelled, technical markers written 30 mm off caught
by the verdict and reduced by a static calibration, and the stand-in rule's 1.6 deg (step 2)."""
from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.io.results import read_angles_csv
from exubio.model.angles import anatomical_table
from exubio.model.load import load_model
from exubio.synth.simulate import Motion, simulate_trial

PAGE = Path(__file__).resolve().parents[2] / "docs" / "protocols.md"
HEADING = "## Write a protocol for your marker set"


def guide_protocol() -> str:
    text = PAGE.read_text(encoding="utf-8")
    section = text[text.index(HEADING):]
    section = section[: section.index("\n## ", len(HEADING))]
    return re.search(r"```yaml\n(.*?)```", section, re.S).group(1)


def model_points(capsys, segment: str) -> dict[str, tuple[float, ...]]:
    """Step 1: `exubio model-points --segment SEGMENT`, parsed (mm, segment frame)."""
    assert main(["model-points", "--segment", segment]) == 0
    rows = re.findall(r"^\s+(\S+)\s+\[\s*([-\d.]+),\s*([-\d.]+),\s*([-\d.]+)\]", capsys.readouterr().out, re.M)
    return {name: tuple(float(v) for v in xyz) for name, *xyz in rows}


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """The guide's protocol written to a file, and a noise-free abduction of its marker set: each
    marker simulated at the model point the protocol ties it to (for a technical marker, the point
    printed by model-points at its local_position_mm), then given the lab's label."""
    folder = tmp_path_factory.mktemp("guide")
    text = guide_protocol()
    (folder / "lab_15.yaml").write_text(text, encoding="utf-8")
    return folder, yaml.safe_load(text)


def _simulated(folder: Path, protocol: dict, capsys) -> tuple[Path, np.ndarray]:
    frame = protocol["thorax_frame"]
    stand_for = {frame["ij"]: "IJ", frame["px"]: "PX", frame["c7"]: "C7", frame["t8"]: "T10"}  # T10 for T8
    points = {}
    for label, m in protocol["markers"].items():
        if m["segment"] == "thorax":
            points[label] = stand_for[label]
        elif "point" in m:
            points[label] = m["point"]
        else:  # step 4: a technical marker at a place read off model-points
            printed = model_points(capsys, m["segment"])
            points[label] = next(n for n, xyz in printed.items() if np.allclose(xyz, m["local_position_mm"]))
    model = load_model()
    sim = simulate_trial(model, Motion.ABDUCTION, duration_s=4.0, rate_hz=50.0, seed=3,
                         marker_names=list(points.values()))
    label_of = {p: label for label, p in points.items()}
    traj = dataclasses.replace(sim.trajectories, labels=tuple(label_of[p] for p in sim.trajectories.labels))
    path = write_c3d(folder / "lab.c3d", traj)
    return path, anatomical_table(model, sim.q_true)[1]


def _errors_deg(out: Path, truth: np.ndarray) -> tuple[dict[str, float], dict]:
    _, names, q = read_angles_csv(out / "lab.ls.csv")
    summ = json.loads((out / "lab.ls.summary.json").read_text(encoding="utf-8"))
    rmse = np.degrees(np.sqrt(np.mean((q - truth) ** 2, axis=0)))
    return {n.removesuffix("_deg"): float(e) for n, e in zip(names, rmse)}, summ


def test_the_guide_protocol_for_a_set_exubio_does_not_ship_measures_what_it_says(lab, capsys):
    folder, protocol = lab
    assert main(["protocols", str(folder / "lab_15.yaml")]) == 0  # the file is checked, its markers listed
    listed = capsys.readouterr().out
    assert all(label in listed for label in protocol["markers"] if protocol["markers"][label]["segment"] != "thorax")
    trial, truth = _simulated(folder, protocol, capsys)
    out = folder / "exact"
    assert main(["-q", "reconstruct", str(trial), "--protocol", str(folder / "lab_15.yaml"), "--method", "ls",
                 "--no-report", "--out", str(out)]) == 0
    err, summ = _errors_deg(out, truth)
    status = summ["anatomical_angles"]["status"]
    measured = [n for n, s in status.items() if s == "measured"]
    assert {"GH_X_elevation", "forearm_pronation", "HT_X_elevation"} <= set(measured)
    # measured up to the elevations where the bone-pin artefact's uncertainty passes the bound (HT ~100 deg)
    assert status["ST_X_upward_rotation"] in ("measured", "partly not measured")
    assert max(err[n] for n in measured) < 0.1, {n: err[n] for n in measured}  # step 4: "within 0.05 deg"
    # step 5: the held clavicle rotation and the AC angles are modelled, not measured (and not exact)
    assert status["SC_Z_posterior_rotation"] == "modelled" and status["AC_X_upward_rotation"] == "modelled"
    assert err["SC_Z_posterior_rotation"] > 1.0
    assert summ["quality"]["verdict"] == "ok"


@pytest.mark.slow  # calibrations and reconstructions end to end (about 3-4 s)
def test_technical_markers_written_30_mm_off_are_caught_and_a_static_calibration_reduces_the_error(lab, capsys):
    folder, protocol = lab
    trial, truth = _simulated(folder, protocol, capsys)
    off = json.loads(json.dumps(protocol))
    for m in off["markers"].values():
        if "local_position_mm" in m:
            m["local_position_mm"] = [v + d for v, d in zip(m["local_position_mm"], (18.0, -27.0, 17.0))]  # 36 mm
    (folder / "off.yaml").write_text(yaml.safe_dump(off), encoding="utf-8")
    worst = {}
    for name, extra in (("generic", []), ("calibrated", ["--static-frames", "0:5"])):
        out = folder / name
        main(["-q", "reconstruct", str(trial), "--protocol", str(folder / "off.yaml"), "--method", "ls",
              "--no-report", "--out", str(out), *extra])
        err, summ = _errors_deg(out, truth)
        worst[name] = max(err[n] for n in ("forearm_pronation", "elbow_flexion", "GH_Y_axial_rotation"))
        if name == "generic":
            assert summ["quality"]["verdict"] != "ok"
            assert any("R_UA" in r["message"] or "R_FA" in r["message"] for r in summ["quality"]["reasons"])
    assert worst["generic"] > 2.0  # they matter (step 4)
    assert worst["calibrated"] < 0.7 * worst["generic"], worst  # and the calibration reduces, not removes, it


def test_a_stand_in_10_mm_off_along_the_spine_turns_the_thorax_frame_by_the_guides_1_6_deg():
    from exubio.prep.thorax import thorax_frame

    pts = {p: np.asarray(xyz, float) for p, xyz in _thorax_points().items()}  # step 1's thorax points
    rot, _ = thorax_frame(pts["IJ"], pts["PX"], pts["C7"], pts["T8"])
    moved = pts["T8"] + np.array([10.0, 0.0, 0.0])  # a stand-in 10 mm more anterior
    rot2, _ = thorax_frame(pts["IJ"], pts["PX"], pts["C7"], moved)
    angle = np.degrees(np.arccos(np.clip(rot[:, 1] @ rot2[:, 1], -1, 1)))
    assert angle == pytest.approx(1.6, abs=0.1)


def _thorax_points() -> dict[str, tuple[float, ...]]:
    import io
    from contextlib import redirect_stdout

    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["model-points", "--segment", "thorax"]) == 0
    rows = re.findall(r"^\s+(\S+)\s+\[\s*([-\d.]+),\s*([-\d.]+),\s*([-\d.]+)\]", buf.getvalue(), re.M)
    return {name: tuple(float(v) for v in xyz) for name, *xyz in rows}
