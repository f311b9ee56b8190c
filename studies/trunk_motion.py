"""How far the trunk moves while the arm does, on real trials whose thorax carries markers: what a run
that assumes the thorax still (``exubio truth``: the bone files carry no thorax marker) cannot see.

Every movement trial of ../shared/data/c3d (Ipuch/bioptim_exo, Vicon, 100 Hz, right arm, two
subjects; statics left out; thorax MAN (IJ), XYP (PX), C7, T10 (for T8); humerus EPI_lat, EPI_med,
DELT, ARM): per trial the thorax's rotation from its start (deg RMS and max per ISB axis), IJ's
displacement (mm RMS per axis) and the humerus's rotation (deg RMS, max); pooled, the second moment
(exubio.truth.trunk_amplitude: one constant, the form that predicts a held-out trial best of the
three printed). ``--write`` puts it into an STA amplitude JSON (its other fields untouched) as
``trunk_table`` (one node).

    python studies/trunk_motion.py
    python studies/trunk_motion.py --write exubio/data/sta_amplitude_s2m.json
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d"
LABELS = dict(ij="MAN", px="XYP", c7="C7", t8="T10", humerus=("EPI_lat", "EPI_med", "DELT", "ARM"))


def _forms(motions, rests, theta):
    """The three forms fitted on ``motions`` (each (xi, theta), their first ``rests`` frames left out),
    evaluated at ``theta``: (n, 6, 6) each; the constant is the shipped fit (fit_trunk_amplitude)."""
    from exubio.synth.driver_table import binned_second_moment, driver_bins, interpolate, nearest_psd
    from exubio.truth.trunk_amplitude import fit_trunk_amplitude

    xs, ts = [], []
    for (xi, th), r in zip(motions, rests):
        ok = np.isfinite(xi).all(axis=1) & np.isfinite(th)
        ok[:r] = False
        xs.append(xi[ok])
        ts.append(th[ok])
    x, t = np.concatenate(xs), np.concatenate(ts)
    b, nodes = driver_bins(t)
    constant = fit_trunk_amplitude(motions, rest_frames=rests)[1][0]
    return {"constant": np.broadcast_to(constant, (theta.size, 6, 6)),
            "table": interpolate(nodes, nearest_psd(binned_second_moment(x, x, b, nodes.size)), theta),
            "slope": (x.T @ x / np.sum(t ** 2))[None] * (theta ** 2)[:, None, None] + 1e-12 * np.eye(6)}


def _score(x, C):
    """(mean Gaussian log-likelihood per frame, fraction of rotation components within 2 SD)."""
    _, logdet = np.linalg.slogdet(C)
    m = np.einsum("ni,nij,nj->n", x, np.linalg.inv(C), x)
    sd = np.sqrt(np.einsum("nii->ni", C)[:, :3])
    return float(np.mean(-0.5 * (logdet + m + 6 * np.log(2 * np.pi)))), float(np.mean(np.abs(x[:, :3]) <= 2 * sd))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write", default=None, help="an STA amplitude JSON to add the trunk's second moment to")
    args = ap.parse_args(argv)
    import exubio
    from exubio.truth.trunk_amplitude import REST_S, fit_trunk_amplitude, trunk_motion

    files = [f for f in sorted(DATA.glob("*.c3d")) if "statique" not in f.name]
    if not files:
        print(f"(no c3d trials in {DATA})")
        return 0
    motions, rests = [], []
    print("| trial | frames | humerus rotation deg RMS / max | thorax rotation deg RMS (X, Y, Z) | thorax rotation deg "
          "max (X, Y, Z) | IJ displacement mm RMS (X, Y, Z) |\n|---|---|---|---|---|---|")
    for f in files:
        tr = exubio.read_trial(f)
        labels = [lab.split(":")[-1] for lab in tr.labels]
        xi, th = trunk_motion(tr.positions_m, labels, tr.rate_hz, where=f.name, **LABELS)
        ok = np.isfinite(xi).all(axis=1) & np.isfinite(th)
        motions.append((xi, th))
        rests.append(int(round(REST_S * tr.rate_hz)))
        r, t = np.degrees(xi[ok, :3]), 1e3 * xi[ok, 3:]
        fmt = lambda v: ", ".join(f"{x:.1f}" for x in v)
        print(f"| {f.name} | {int(ok.sum())} | {np.degrees(np.sqrt(np.mean(th[ok] ** 2))):.0f} / "
              f"{np.degrees(th[ok].max()):.0f} | {fmt(np.sqrt(np.mean(r ** 2, axis=0)))} | "
              f"{fmt(np.abs(r).max(axis=0))} | {fmt(np.sqrt(np.mean(t ** 2, axis=0)))} |")
    nodes, table, frames = fit_trunk_amplitude(motions, rest_frames=rests)
    sd = np.sqrt(np.diag(table[0]))
    print(f"\npooled over {len(files)} trials ({frames} frames, the first {REST_S:g} s of each left out): thorax rotation "
          f"{', '.join(f'{np.degrees(x):.1f}' for x in sd[:3])} deg RMS (X, Y, Z), IJ displacement "
          f"{', '.join(f'{1e3 * x:.1f}' for x in sd[3:])} mm RMS")
    print("\nwhich form: each trial held out, the three forms fitted on the other five; mean Gaussian log-likelihood "
          "per frame of the held-out trial's xi (higher is better) and its rotation components within 2 SD:\n")
    print("| held out | constant | table in bins of theta | per rad^2 of theta |\n|---|---|---|---|")
    scores = {k: [] for k in ("constant", "table", "slope")}
    for i, (xi, th) in enumerate(motions):
        ok = np.isfinite(xi).all(axis=1) & np.isfinite(th)
        ok[: rests[i]] = False
        x, t = xi[ok], th[ok]
        others = [m for j, m in enumerate(motions) if j != i]
        forms = _forms(others, [r for j, r in enumerate(rests) if j != i], t)
        cells = []
        for k, C in forms.items():
            ll, cov = _score(x, C)
            scores[k].append(ll)
            cells.append(f"{ll:.1f} / {cov:.0%}")
        print(f"| {files[i].name} | " + " | ".join(cells) + " |")
    print("| mean | " + " | ".join(f"{np.mean(v):.1f}" for v in scores.values()) + " |")
    if args.write:
        path = Path(args.write)
        data = json.loads(path.read_text(encoding="utf-8"))
        for old in ("trunk_second_moment", "trunk_second_moment_units", "trunk_floor_second_moment"):
            data.pop(old, None)
        data["trunk_table_nodes_rad"] = [float(f"{x:.6g}") for x in nodes]
        data["trunk_table"] = [[[float(f"{x:.6g}") for x in row] for row in C] for C in table]
        data["trunk_table_units"] = (
            "one node (the frames' mean humerus rotation, rad): the second moment of the thorax's rotation vector "
            "from its start (rad, its ISB axes) and IJ's displacement (m, same axes) over every frame after the rest "
            "window: the trunk motion a run that assumes the thorax still cannot see, constant in the arm's motion "
            "(exubio.truth.trunk_amplitude)")
        data["trunk_source"] = (f"studies/trunk_motion.py: {len(files)} movement trials of Ipuch/bioptim_exo @ "
                                f"b4a33b4e (two subjects, right arm, Vicon 100 Hz; {frames} frames): "
                                + ", ".join(f.name for f in files))
        path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        print(f"wrote the trunk's table into {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
