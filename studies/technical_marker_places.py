"""What a technical marker's written place costs: the protocol guide's 15-marker protocol (docs/protocols.md) ("Write a
protocol for your marker set"), a noise-free simulated abduction of its marker set, reconstructed
by LS with both technical markers (R_UA, R_FA) written exactly, 10 mm and 37 mm off, with the generic
model and calibrated on the trial's first 5 frames. Prints the RMSE (deg) of the worst measured
angle among forearm pronation, elbow flexion and GH axial rotation, and of every measured angle.

    python studies/technical_marker_places.py
"""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.io.results import read_angles_csv
from exubio.model.angles import anatomical_table
from exubio.model.load import load_model
from exubio.synth.simulate import Motion, simulate_trial

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "protocols.md"
POINTS = {"STRN": "IJ", "XIPH": "PX", "C7": "C7", "T10": "T10", "R_UA": "ARM", "R_FA": "RADIUS"}
OFFSETS = {"exact": (0.0, 0.0, 0.0), "10 mm": (6.0, 6.0, 6.0), "37 mm": (18.0, -27.0, 17.0)}
KEY = ("forearm_pronation", "elbow_flexion", "GH_Y_axial_rotation")


def guide_protocol() -> dict:
    text = GUIDE.read_text(encoding="utf-8")
    section = text[text.index("## Write a protocol for your marker set"):]
    return yaml.safe_load(re.search(r"```yaml\n(.*?)```", section, re.S).group(1))


def run(folder: Path, trial: Path, protocol: dict, truth: np.ndarray, extra: list[str]) -> tuple[float, float]:
    path = folder / "p.yaml"
    path.write_text(yaml.safe_dump(protocol), encoding="utf-8")
    out = folder / "out"
    with contextlib.redirect_stdout(io.StringIO()):
        main(["-q", "reconstruct", str(trial), "--protocol", str(path), "--method", "ls", "--no-report",
              "--out", str(out), "--overwrite", *extra])
    _, names, q = read_angles_csv(out / "lab.ls.csv")
    status = json.loads((out / "lab.ls.summary.json").read_text())["anatomical_angles"]["status"]
    err = dict(zip([n.removesuffix("_deg") for n in names], np.degrees(np.sqrt(np.mean((q - truth) ** 2, axis=0)))))
    return max(err[n] for n in KEY), max(e for n, e in err.items() if status[n] == "measured")


def main_() -> int:
    protocol = guide_protocol()
    points = {label: POINTS.get(label) or m["point"] for label, m in protocol["markers"].items()}
    model = load_model()
    sim = simulate_trial(model, Motion.ABDUCTION, duration_s=4.0, rate_hz=50.0, seed=3, marker_names=list(points.values()))
    label_of = {p: label for label, p in points.items()}
    truth = anatomical_table(model, sim.q_true)[1]
    print(f"{'technical markers':18s} {'model':11s} {'worst of ' + '/'.join(KEY):>60s} {'worst measured':>15s}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        trial = write_c3d(folder / "lab.c3d", dataclasses.replace(
            sim.trajectories, labels=tuple(label_of[p] for p in sim.trajectories.labels)))
        for name, delta in OFFSETS.items():
            moved = json.loads(json.dumps(protocol))
            for m in moved["markers"].values():
                if "local_position_mm" in m:
                    m["local_position_mm"] = [v + d for v, d in zip(m["local_position_mm"], delta)]
            for label, extra in (("generic", []), ("calibrated", ["--static-frames", "0:5"])):
                key, worst = run(folder, trial, moved, truth, extra)
                print(f"{name:18s} {label:11s} {key:60.2f} {worst:15.2f}  deg RMSE")
    return 0


if __name__ == "__main__":
    sys.exit(main_())
