"""What does assuming the thorax fixed in the lab cost? (``exubio truth`` must assume it: the bone
files carry no thorax marker.) A simulated abduction (10 s, 100 Hz, 1 mm noise) whose whole body
moves: the trunk leans sideways, leans forward or turns by up to ANGLE deg (a smooth ramp up and back,
about a point 0.45 m below IJ), reconstructed by LS (a) as a lab with thorax markers would (the
thorax frame built from them in every frame) and (b) with the thorax markers frozen at the first
frame (the thorax assumed fixed). Per motion and angle: the RMSE (deg) of each ST, GH and HT angle
against the truth over its measured frames.

    python studies/thorax_assumption.py --angles 5 10
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import warnings

import numpy as np

SHOWN = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
         "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation", "HT_X_elevation", "HT_Y_plane_of_elevation")
AXES = {"lateral lean": np.array([1.0, 0.0, 0.0]), "forward lean": np.array([0.0, 0.0, 1.0]),
        "trunk rotation": np.array([0.0, 1.0, 0.0])}


def _rot(axis: np.ndarray, a: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(a[:, None] * axis[None, :]).as_matrix()


def run(kind: str, angle_deg: float, frozen: bool):
    import exubio
    from exubio.model.angles import anatomical_table
    from exubio.synth.simulate import simulate_trial

    model = exubio.load_model()
    protocol = exubio.load_protocol(model=model)
    sim = simulate_trial(model, "abduction", duration_s=10.0, rate_hz=100.0, noise_mm=1.0, seed=1, lab_transform=False)
    traj = sim.trajectories
    n = traj.n_frames
    ramp = np.radians(angle_deg) * (1 - np.cos(2 * np.pi * np.arange(n) / n)) / 2
    R = _rot(AXES[kind], ramp)  # in the thorax frame of the first frame (= the simulation's frame)
    pivot = np.array([0.0, -0.45, 0.0])
    pos = np.einsum("nij,nkj->nki", R, traj.positions_m - pivot) + pivot
    if frozen:
        thorax = [j for j, lab in enumerate(traj.labels) if lab in {m for m, s in zip(sim.trajectories.labels,
                                                                                    sim.marker_segments) if s == "thorax"}]
        pos[:, thorax] = pos[0, thorax]
    moved = dataclasses.replace(traj, positions_m=pos)
    rec = exubio.reconstruct(moved, model, protocol, method="ls")
    det = exubio.angle_status(rec, model, protocol)
    names, est = anatomical_table(model, rec.q_rad)
    _, truth = anatomical_table(model, sim.q_true)
    err = np.degrees(np.abs(np.angle(np.exp(1j * (est - truth)))))
    out = {}
    for a in SHOWN:
        j = names.index(a)
        ok = det.status[:, j] == 0
        out[a] = float(np.sqrt(np.mean(err[ok, j] ** 2))) if ok.any() else float("nan")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--angles", nargs="+", type=float, default=[5.0, 10.0])
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    print("| trunk motion | thorax | " + " | ".join(SHOWN) + " |")
    print("|---|---|" + "---|" * len(SHOWN))
    for kind in AXES:
        for ang in args.angles:
            for frozen in (False, True):
                r = run(kind, ang, frozen)
                label = "assumed fixed" if frozen else "tracked"
                print(f"| {kind} {ang:g} deg | {label} | " + " | ".join(f"{r[a]:.1f}" for a in SHOWN) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
