"""The marker sets labs use (the shipped plug_in_gait_upper and isb_landmarks protocols, both arms):
simulated trials of each marker set, noise-free, both arms in one trial, reconstructed the way a lab
would (`exubio simulate --protocol R --protocol L`, then `exubio reconstruct TRIAL --protocol R
--both-arms`), and every anatomical angle compared with the truth: the RMSE (deg) of each angle the
protocol claims as measured before any trial (`exubio protocols NAME`), and the worst, over its
measured frames, of each angle it claims as partly measured.

Usage: python studies/marker_sets.py [--motions abduction flexion] [--duration 5] [--method ls]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from exubio.protocol.bind import bind
from exubio.cli import main as exubio
from exubio.io.results import read_npz_arrays
from exubio.model.angles import anatomical_table
from exubio.model.load import load_model
from exubio.run.inputs import protocol_for_model
from exubio.trust.assess import angle_status_of_protocol
from exubio.trust.observability import AngleStatus

SETS = {"plug_in_gait_upper": "plug_in_gait_upper_left", "isb_landmarks": "isb_landmarks_left"}


def errors(out: Path, stem: str, method: str, model, q_true: np.ndarray, claimed: dict[str, str]) -> dict[str, float]:
    """Per angle the protocol claims measured (or partly): RMSE (deg) over the frames it is measured in."""
    arrays = read_npz_arrays(out / f"{stem}.{method}.npz", ("q_rad", "angle_status"))
    names, rec = anatomical_table(model, arrays["q_rad"])
    _, true = anatomical_table(model, q_true)
    err = np.degrees(np.abs(np.angle(np.exp(1j * (rec - true)))))
    measured = arrays["angle_status"] == AngleStatus.MEASURED
    res = {}
    for j, n in enumerate(names):
        if claimed[n] == "measured" or claimed[n].startswith("partly"):
            sel = measured[:, j] if claimed[n] != "measured" else np.ones(len(err), bool)
            res[n] = float(np.sqrt(np.mean(err[sel, j] ** 2))) if sel.any() else float("nan")
    return res


def run(right: str, motion: str, duration: float, method: str, folder: Path) -> dict:
    from exubio.io.results import read_angles_csv

    model = load_model()
    left = SETS[right]
    c3d = folder / f"{right}_{motion}.c3d"
    assert exubio(["-q", "simulate", "--motion", motion, "--duration", str(duration), "--rate", "50",
                   "--protocol", right, "--protocol", left, "--out", str(c3d)]) == 0
    out = folder / f"{right}_{motion}"
    code = exubio(["-q", "reconstruct", str(c3d), "--protocol", right, "--both-arms", "--method", method,
                   "--no-report", "--out", str(out)])
    _, _, q_true = read_angles_csv(c3d.with_name(c3d.stem + ".truth.csv"))  # radians
    result = {"exit": code}
    for side, name in (("right", right), ("left", left)):
        claimed = angle_status_of_protocol(bind(model, protocol_for_model(model, name)))
        result[side] = (claimed, errors(out / side, c3d.stem, method, model, q_true, claimed))
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--motions", nargs="+", default=["abduction", "flexion"])
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--method", default="ls", choices=["ls", "pf"])
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as tmp:
        for right in SETS:
            for motion in args.motions:
                r = run(right, motion, args.duration, args.method, Path(tmp))
                print(f"== {right} + {SETS[right]}, {motion}, {args.duration:g} s at 50 Hz, noise-free, "
                      f"{args.method}, exit {r['exit']}")
                claimed, err_r = r["right"]
                _, err_l = r["left"]
                print(f"  {'angle':30s} {'claimed':20s} {'right':>7s} {'left':>7s}  (RMSE deg)")
                for n, st in claimed.items():
                    if n in err_r:
                        print(f"  {n:30s} {st:20s} {err_r[n]:7.3f} {err_l[n]:7.3f}")
                worst = max(max(v for k, v in e.items() if claimed[k] == "measured") for e in (err_r, err_l))
                print(f"  worst angle claimed measured: {worst:.3f} deg")
                sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
