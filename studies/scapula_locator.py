"""Scapula calibrations judged against a scapula locator (issue 33 item 3; bone truth).

Data: ../shared/data/truth/scapula_locator/scapula_locator_P9-P12.csv, from aceglia/scapula_cluster
(Ceglia, Begon et al., Montréal; AGPL-3.0 data, numbers only): per participant and static
posture, the trial-mean lab positions of AA, TS and AI by the locator (truth), the skin markers
over them and a scapula-cluster reconstruction. Left arm.

It prints, for the calibrations of exubio.truth.locator_eval.METHODS calibrated on the flexion
statics (and then the other way round, on the abduction statics):
1. per participant and calibration, over the postures every calibration left out (median and max
   distance of AA, TS, AI from the locator, mm; ISB scapula frame error, deg);
2. the same per posture group (each calibration's own held-out postures);
3. variants of the recommended double calibration: what it is interpolated in (the skin frame's
   upward rotation, clamped or extrapolated; the nominal elevation parsed from the file name);
4. the calibration postures' other repeat (the same posture taken again: the floor).
Writes nothing unless --out DIR (then DIR/scapula_locator.md and the JSON of each plane).

Usage:  python studies/scapula_locator.py [--file CSV] [--out DIR]      (a second)
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from exubio.truth.locator import (LANDMARKS, System, apply_calibration, calibrate, calibration_trials,
                                  locator_displaced, orientation_error, read_locator_csv, scapula_frame,
                                  upward_rotation)
from exubio.truth.locator_cli import format_table, to_json
from exubio.truth.locator_eval import RECOMMENDED, evaluate, summarize

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "data" / "truth" / "scapula_locator" / \
    "scapula_locator_P9-P12.csv"


def _double_variants(data) -> list[str]:
    """The recommended double calibration (flexion 45 + 120, skin) interpolated three ways, on the
    postures outside the flexion plane and the flexion 90 forward/back (held out by all)."""
    rows = ["| participant | interpolated in | n | AA med | TS med | AI med | orient. med (deg) |", "|---|---|---|---|---|---|---|"]
    pooled: dict[str, list[np.ndarray]] = {}
    for p in data.participants:
        trials = [t for t in data.of(p) if not locator_displaced(t)]
        chosen, absent = calibration_trials(trials, plane="flex", elevations=("45", "120"))
        if absent:
            continue
        cal = calibrate(chosen)
        held = [t for t in trials if t.posture.plane != "flex" or t.posture.variant]
        skin = np.stack([t.positions_m[System.SKIN] for t in held])
        truth = np.stack([t.positions_m[System.LOCATOR] for t in held])
        R, o = scapula_frame(skin)
        theta = upward_rotation(skin, cal.reference_m)
        w = (theta - cal.nodes_rad[0]) / (cal.nodes_rad[1] - cal.nodes_rad[0])
        extrapolated = o[:, None, :] + np.einsum("nij,nlj->nli", R, cal.offsets_m[0] * (1 - w)[:, None, None]
                                                 + cal.offsets_m[1] * w[:, None, None])
        # nominal elevation: the offsets at 45 and 120 deg by the file's angle (max: not a number, left out)
        by_name = {t.posture.file: t for t in chosen}
        nominal_nodes = np.array([float(by_name[f].posture.elevation) for f in cal.postures])
        numeric = np.array([t.posture.elevation != "max" for t in held])
        elev = np.array([float(t.posture.elevation) if t.posture.elevation != "max" else np.nan for t in held])
        wn = np.clip((elev - nominal_nodes[0]) / (nominal_nodes[1] - nominal_nodes[0]), 0, 1)
        nominal = o[:, None, :] + np.einsum("nij,nlj->nli", R, cal.offsets_m[0] * (1 - wn)[:, None, None]
                                            + cal.offsets_m[1] * wn[:, None, None])
        for name, est, mask in (("upward rotation, clamped (shipped)", apply_calibration(cal, skin), None),
                                ("upward rotation, extrapolated", extrapolated, None),
                                ("upward rotation, clamped, no 'max' posture", apply_calibration(cal, skin), numeric),
                                ("nominal elevation, clamped, no 'max' posture", nominal, numeric)):
            m = np.ones(len(held), bool) if mask is None else mask
            d = np.linalg.norm(est[m] - truth[m], axis=-1)
            ori = orientation_error(est[m], truth[m])
            rows.append(_row(p, name, d, ori))
            pooled.setdefault(name, []).append(np.column_stack([d, ori]))
    for name, parts in pooled.items():
        x = np.concatenate(parts)
        rows.append(_row("all", name, x[:, :3], x[:, 3]))
    return rows


def _repeats(data) -> list[str]:
    """Single and double calibration judged on their own postures' other repeat."""
    rows = ["| participant | calibration | trial | AA | TS | AI | orient. (deg) |", "|---|---|---|---|---|---|---|"]
    for p in data.participants:
        trials = [t for t in data.of(p) if not locator_displaced(t)]
        for label, elevations in (("skin single 45", ("45",)), ("skin double 45+120", ("45", "120"))):
            chosen, absent = calibration_trials(trials, plane="flex", elevations=elevations)
            if absent:
                continue
            cal = calibrate(chosen)
            names = {t.posture.name: t.posture.file for t in chosen}
            for t in trials:
                if t.posture.name in names and t.posture.file not in names.values():
                    est = apply_calibration(cal, t.positions_m[System.SKIN])
                    d = np.linalg.norm(est - t.positions_m[System.LOCATOR], axis=-1) * 1000
                    o = math.degrees(float(orientation_error(est, t.positions_m[System.LOCATOR])))
                    rows.append(f"| {p} | {label} | {t.posture.file} | " + " | ".join(_f(v) for v in d) + f" | {_f(o)} |")
    return rows


def _row(who: str, name: str, d: np.ndarray, ori: np.ndarray) -> str:
    med = [np.nanmedian(d[:, j]) * 1000 if np.isfinite(d[:, j]).any() else math.nan for j in range(3)]
    o = np.degrees(np.nanmedian(ori)) if np.isfinite(ori).any() else math.nan
    return f"| {who} | {name} | {len(d)} | " + " | ".join(_f(v) for v in med) + f" | {_f(o)} |"


def _f(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.1f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--file", default=str(DEFAULT), help="locator CSV (default: the shared P9-P12 file)")
    ap.add_argument("--out", help="folder for scapula_locator.md and scapula_locator.<plane>.json")
    args = ap.parse_args(argv)
    if not Path(args.file).is_file():
        print(f"scapula_locator: {args.file} not found (the shared data are absent)", file=sys.stderr)
        return 2
    data = read_locator_csv(args.file)
    parts: list[str] = []
    payload = {}
    for plane in ("flex", "abd"):
        ev = evaluate(data, plane=plane)
        common = summarize(ev, by_group=False)
        parts += [f"## 1. Calibrated on the {plane} statics: the postures every calibration left out", "",
                  format_table(common, ev), ""]
        if plane == "flex":
            grouped = [s for s in summarize(ev) if s.group != "common held-out"]
            parts += ["## 2. Calibrated on the flex statics, per posture group (each calibration's own held-out "
                      "postures)", "", format_table(grouped, ev).split("\n\n")[1], ""]
        payload[plane] = to_json(ev, summarize(ev))
    parts += ["## 3. The double calibration (skin, flex 45 + 120) interpolated three ways "
              "(held out: abduction, flex 90 forward/back; mm)", "", *_double_variants(data), "",
              "## 4. The calibration postures' other repeat (mm)", "", *_repeats(data), "",
              f"Recommended: {RECOMMENDED.name}; landmarks {', '.join(LANDMARKS)}."]
    text = "\n".join(parts)
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "scapula_locator.md").write_text(text + "\n", encoding="utf-8")
        for plane, p in payload.items():
            (out / f"scapula_locator.{plane}.json").write_text(json.dumps(p, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
