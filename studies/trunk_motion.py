"""How far the trunk moves while the arm does, on real trials whose thorax carries markers: what a run
that assumes the thorax still (``exubio truth``: the bone files carry no thorax marker) cannot see.

Every movement trial of ../shared/data/c3d (Ipuch/bioptim_exo, Vicon, 100 Hz, right arm, two
subjects; statics left out; thorax MAN (IJ), XYP (PX), C7, T10 (for T8); humerus EPI_lat, EPI_med,
DELT, ARM): per trial the thorax's rotation from its start (deg RMS and max per ISB axis), IJ's
displacement (mm RMS per axis) and the humerus's rotation (deg RMS, max); pooled, the second moment
per rad^2 of humerus rotation (exubio.truth.trunk_amplitude). ``--write`` puts it into an STA
amplitude JSON (its other fields untouched) as ``trunk_second_moment``.

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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write", default=None, help="an STA amplitude JSON to add the trunk's second moment to")
    args = ap.parse_args(argv)
    import exubio
    from exubio.truth.trunk_amplitude import fit_trunk_amplitude, trunk_motion

    files = [f for f in sorted(DATA.glob("*.c3d")) if "statique" not in f.name]
    if not files:
        print(f"(no c3d trials in {DATA})")
        return 0
    motions = []
    print("| trial | frames | humerus rotation deg RMS / max | thorax rotation deg RMS (X, Y, Z) | thorax rotation deg "
          "max (X, Y, Z) | IJ displacement mm RMS (X, Y, Z) |\n|---|---|---|---|---|---|")
    for f in files:
        tr = exubio.read_trial(f)
        labels = [lab.split(":")[-1] for lab in tr.labels]
        xi, th = trunk_motion(tr.positions_m, labels, tr.rate_hz, where=f.name, **LABELS)
        ok = np.isfinite(xi).all(axis=1) & np.isfinite(th)
        motions.append((xi, th))
        r, t = np.degrees(xi[ok, :3]), 1e3 * xi[ok, 3:]
        fmt = lambda v: ", ".join(f"{x:.1f}" for x in v)
        print(f"| {f.name} | {int(ok.sum())} | {np.degrees(np.sqrt(np.mean(th[ok] ** 2))):.0f} / "
              f"{np.degrees(th[ok].max()):.0f} | {fmt(np.sqrt(np.mean(r ** 2, axis=0)))} | "
              f"{fmt(np.abs(r).max(axis=0))} | {fmt(np.sqrt(np.mean(t ** 2, axis=0)))} |")
    C, frames = fit_trunk_amplitude(motions)
    sd = np.sqrt(np.diag(C))
    print(f"\npooled over {len(files)} trials ({frames} frames), per rad of humerus rotation: thorax rotation "
          f"{', '.join(f'{x:.3f}' for x in sd[:3])} rad/rad (X, Y, Z), IJ displacement "
          f"{', '.join(f'{1e3 * x:.1f}' for x in sd[3:])} mm/rad")
    if args.write:
        path = Path(args.write)
        data = json.loads(path.read_text(encoding="utf-8"))
        data["trunk_second_moment"] = [[float(f"{x:.6g}") for x in row] for row in C]
        data["trunk_second_moment_units"] = (
            "the thorax's rotation vector from its start (rad, its ISB axes) and IJ's displacement (m, same axes) x same, "
            "per rad^2 of driver: the trunk motion a run that assumes the thorax still cannot see "
            "(exubio.truth.trunk_amplitude)")
        data["trunk_source"] = (f"studies/trunk_motion.py: {len(files)} movement trials of Ipuch/bioptim_exo @ "
                                f"b4a33b4e (two subjects, right arm, Vicon 100 Hz; {frames} frames): "
                                + ", ".join(f.name for f in files))
        path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        print(f"wrote trunk_second_moment into {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
