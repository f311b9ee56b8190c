"""The gap table: what a marker gap does to the angles, what the angles say about it, and how well the gap is filled.

On every movement trial of ../shared/data (six C3D trials, two TRC trials; the static trials serve
their sessions' calibrations), up to three protocol markers per segment (all where a segment has
three or fewer; else the two farthest apart on it and the one farthest from the line through them,
whose loss costs the segment most) are cut in turn, for gaps of 0.1,
0.25, 0.5, 1 and 2 s placed every (gap + 1 s) from 0.5 s on (all gaps of one marker and length cut
together, separated by at least 1 s of measured samples), and the trial is reconstructed with LS
(per frame, so separated gaps do not interact through the dynamics; about 10x faster than PF, which
a table of ~350 reconstructions needs). Against the same trial reconstructed without the cut, per
gap length and angle, over the gap frames: the angle's change |error| (median, 95th percentile),
the fraction of gap frames measured (and in the uncut run), the median standard uncertainty u (and
in the uncut run), the fraction of frames where |error| <= 2u; per gap length, the fill error
(exubio.prep.fill, no length limit here; its offset window of 0.1 s a side and of 0.5 s) against
the cut-out samples, and for reference a cubic
spline through the marker's measured samples (what a capture program's spline fill does).

Calibration: martin_* trials on bioptim_exo_martin_statique, kinova_martin_* on
bioptim_exo_kinova_martin_statique; F0_boire_05 (no static of its subject) and the TRC trials
(thoracoscapular_9 protocol) on their first 0.5 s (as ``--static-frames 0:50``).

    python studies/gap_table.py            # prints the Markdown tables (--out FILE.csv: the table as CSV too)
    python studies/gap_table.py --quick    # one C3D trial, three markers: a smoke run
    python studies/gap_table.py --cache /tmp/gap_rows   # each trial's rows kept: a run cut short resumes
"""
from __future__ import annotations

import argparse
import dataclasses
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
LENGTHS_S = (0.1, 0.25, 0.5, 1.0, 2.0)
SPACING_S = 1.0
WIDE_WINDOW_S = 0.5  # the fill's offset averaged over 0.5 s a side too, beside the default (exubio.prep.fill.FILL_WINDOW_S)
START_S = 0.5

C3D = DATA / "c3d"
TRIALS = (  # (trial, protocol, static or None: calibrated on its first 0.5 s)
    (C3D / "bioptim_exo_martin_dynamique.c3d", None, C3D / "bioptim_exo_martin_statique.c3d"),
    (C3D / "bioptim_exo_F0_boire_05.c3d", None, None),
    *((C3D / f"bioptim_exo_kinova_martin_{t}_f3_1.c3d", None, C3D / "bioptim_exo_kinova_martin_statique.c3d")
      for t in ("aisselle", "dent", "manger", "tete")),
    (DATA / "trc" / "tsm_rmr_ABD01.trc", "thoracoscapular_9", None),
    (DATA / "trc" / "tsm_rmr_FLX01.trc", "thoracoscapular_9", None),
)


def gap_mask(n: int, rate: float, length_s: float) -> np.ndarray:
    """(n,) bool: gaps of length_s every (length_s + SPACING_S) from START_S, each ending before the trial does."""
    mask = np.zeros(n, dtype=bool)
    L, step = int(round(length_s * rate)), int(round((length_s + SPACING_S) * rate))
    for a in range(int(round(START_S * rate)), n - L - int(round(START_S * rate)), step):
        mask[a:a + L] = True
    return mask


def session_for(trial: Path, protocol: str | None, static: Path | None):
    import exubio
    from exubio.calibration import parse_frames  # noqa: F401 - the same frames syntax as the CLI
    from exubio.protocol.bind import bind
    from exubio.trust.missing_markers import drop_missing_markers

    model = exubio.load_model()
    prot = exubio.load_protocol(protocol, model=model) if protocol else exubio.load_protocol(model=model)
    traj = exubio.read_trial(trial)
    if static is not None:
        cal_traj = exubio.read_trial(static)
    else:
        cal_traj = dataclasses.replace(traj, positions_m=traj.positions_m[:50], time_s=traj.time_s[:50])
    cal_prot = drop_missing_markers(cal_traj, bind(model, prot))[0].protocol
    model, prot_c, _ = exubio.calibrate(cal_traj, model, cal_prot)
    prot_t = drop_missing_markers(traj, bind(model, exubio.load_protocol(protocol, model=model) if protocol
                                              else exubio.load_protocol(model=model)))[0].protocol
    return traj, model, prot_t


def sample_markers(prot, cols: list[tuple[str, int]]) -> list[tuple[str, int]]:
    """Up to three markers per segment: all where it has three or fewer, else the two farthest apart on it
    and the one farthest from the line through them (the three that set its orientation best; losing one
    of them is the worst case of the segment, e.g. the TRC set's only humerus marker off its long axis)."""
    by = {m.name: m for m in prot.markers}
    out = []
    for seg in dict.fromkeys(by[nm].segment for nm, _ in cols):
        mine = [(nm, c) for nm, c in cols if by[nm].segment == seg]
        if len(mine) > 3:
            pos = {nm: np.asarray(by[nm].local_position_m, dtype=float) for nm, _ in mine}
            pairs = [(np.linalg.norm(pos[a[0]] - pos[b[0]]), i, k) for i, a in enumerate(mine)
                     for k, b in enumerate(mine) if i < k]
            _, i, k = max(pairs)
            a, b = pos[mine[i][0]], pos[mine[k][0]]
            axis = (b - a) / np.linalg.norm(b - a)
            off = [(np.linalg.norm(np.cross(pos[nm] - a, axis)), t) for t, (nm, _) in enumerate(mine) if t not in (i, k)]
            mine = [mine[i], mine[k], mine[max(off)[1]]]
        out += mine
    return out


def wrap(d: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * d))


def run_trial(trial: Path, protocol: str | None, static: Path | None, markers_limit: int | None = None,
              skip: frozenset[str] = frozenset()) -> list[dict]:
    """The rows of every sampled marker of the trial but those in ``skip`` (done already)."""
    import exubio
    from scipy.interpolate import CubicSpline

    from exubio.prep.fill import fill_gaps
    from exubio.protocol.labels import resolve_labels

    traj, model, prot = session_for(trial, protocol, static)
    base = exubio.reconstruct(traj, model, prot, method="ls")
    det0 = exubio.angle_status(base, model, prot)
    names = det0.names
    ang0 = np.stack([exubio.angles(base, model)[n] for n in names], axis=1)
    match = resolve_labels(prot, traj.labels, source=traj.source)
    cols = [(nm, match.columns[nm]) for nm in prot.marker_names if match.columns[nm] is not None]
    cols = [(nm, c) for nm, c in cols if np.isfinite(traj.positions_m[:, c]).all(axis=1).mean() > 0.9]
    cols = [(nm, c) for nm, c in sample_markers(prot, cols) if nm not in skip]
    rows = []
    t_idx = np.arange(traj.n_frames)
    for nm, c in cols[:markers_limit]:
        for L in LENGTHS_S:
            gap = gap_mask(traj.n_frames, traj.rate_hz, L) & np.isfinite(traj.positions_m[:, c]).all(axis=1)
            if not gap.any():
                continue
            pos = traj.positions_m.copy()
            pos[gap, c] = np.nan
            cut = dataclasses.replace(traj, positions_m=pos)
            rec = exubio.reconstruct(cut, model, prot, method="ls")
            det = exubio.angle_status(rec, model, prot)
            ang = np.stack([exubio.angles(rec, model)[n] for n in names], axis=1)
            err = np.degrees(np.abs(wrap(ang[gap] - ang0[gap])))
            u = np.degrees(det.uncertainty_rad[gap])
            u0 = np.degrees(det0.uncertainty_rad[gap])
            fill = fill_gaps(cut, model, prot, rec.q_rad, max_gap_s=np.inf)  # the default window (FILL_WINDOW_S)
            fe = np.linalg.norm(fill.positions_m[gap, c] - traj.positions_m[gap, c], axis=1) * 1e3
            wide = fill_gaps(cut, model, prot, rec.q_rad, max_gap_s=np.inf, window_s=WIDE_WINDOW_S)
            fe_wide = np.linalg.norm(wide.positions_m[gap, c] - traj.positions_m[gap, c], axis=1) * 1e3
            ok = np.isfinite(pos[:, c]).all(axis=1)
            spline = CubicSpline(t_idx[ok], pos[ok, c])(t_idx[gap])
            se = np.linalg.norm(spline - traj.positions_m[gap, c], axis=1) * 1e3
            for j, a in enumerate(names):
                rows.append({"trial": trial.name, "marker": nm, "gap_s": L, "angle": a, "frames": int(gap.sum()),
                             "err": err[:, j], "meas": det.status[gap, j] == 0, "meas0": det0.status[gap, j] == 0,
                             "u": u[:, j], "u0": u0[:, j], "fill_mm": fe, "fill_wide_mm": fe_wide,
                             "spline_mm": se})
    return rows


def summarise(rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """Per (gap, angle) and per gap the figures of the module docstring."""
    out, fills = [], []
    for L in LENGTHS_S:
        sub = [r for r in rows if r["gap_s"] == L]
        if not sub:
            continue
        for a in dict.fromkeys(r["angle"] for r in sub):
            rr = [r for r in sub if r["angle"] == a]
            e = np.concatenate([r["err"] for r in rr])
            u = np.concatenate([r["u"] for r in rr])
            u0 = np.concatenate([r["u0"] for r in rr])
            fin = np.isfinite(u) & np.isfinite(e)
            out.append({"gap_s": L, "angle": a, "frames": int(e.size),
                        "err_median_deg": float(np.nanmedian(e)), "err_p95_deg": float(np.nanpercentile(e, 95)),
                        "measured": float(np.concatenate([r["meas"] for r in rr]).mean()),
                        "measured_nogap": float(np.concatenate([r["meas0"] for r in rr]).mean()),
                        "u_median_deg": float(np.median(u[fin])) if fin.any() else np.inf,
                        "u_median_nogap_deg": float(np.median(u0[np.isfinite(u0)])) if np.isfinite(u0).any() else np.inf,
                        "within_2u": float((e[fin] <= 2 * u[fin]).mean()) if fin.any() else np.nan})
        first = [r for r in sub if r["angle"] == sub[0]["angle"]]
        fe = np.concatenate([r["fill_mm"] for r in first])
        se = np.concatenate([r["spline_mm"] for r in first])
        fw = np.concatenate([r["fill_wide_mm"] for r in first])
        fills.append({"gap_s": L, "frames": int(fe.size), "gaps_cut": len(first),
                      "fill_median_mm": float(np.median(fe)), "fill_p95_mm": float(np.percentile(fe, 95)),
                      "fill_max_mm": float(fe.max()),
                      "fill_wide_median_mm": float(np.median(fw)), "fill_wide_p95_mm": float(np.percentile(fw, 95)),
                      "spline_median_mm": float(np.median(se)), "spline_p95_mm": float(np.percentile(se, 95))})
    return out, fills


JOINT_SEGMENTS = {"SC": ("clavicle",), "AC": ("clavicle", "scapula"), "ST": ("scapula",), "GH": ("scapula", "humerus"),
                  "HT": ("humerus",), "elbow": ("humerus", "ulna"), "forearm": ("ulna", "radius"),
                  "wrist": ("radius", "hand")}
"""The segments whose markers set each joint's angles (the thorax, fixed, aside)."""


def marker_segments() -> dict[str, str]:
    """Marker name -> its segment, over the protocols of the table's trials."""
    import exubio

    model = exubio.load_model()
    out = {}
    for name in ("upper_limb_21", "thoracoscapular_9"):
        out.update({m.name: m.segment for m in exubio.load_protocol(name, model=model).markers})
    return out


def on_joint(rows: list[dict], segments: dict[str, str]) -> list[dict]:
    """The rows of gaps cut from a marker on one of the segments of the row's angle's joint."""
    return [r for r in rows if segments.get(r["marker"]) in JOINT_SEGMENTS[r["angle"].split("_")[0]]]


def fill_by_segment(rows: list[dict], segments: dict[str, str]) -> str:
    """Fill and spline error (median / 95th percentile, mm) per segment of the cut marker and gap length."""
    first = {(r["trial"], r["marker"], r["gap_s"]): r for r in rows}.values()
    segs = list(dict.fromkeys(segments[r["marker"]] for r in first))
    lines = ["| segment (markers cut) | " + " | ".join(f"{L:g} s: fill / spline" for L in LENGTHS_S) + " |",
             "|---|" + "---|" * len(LENGTHS_S)]
    for seg in segs:
        mine = [r for r in first if segments[r["marker"]] == seg]
        cells = []
        for L in LENGTHS_S:
            rr = [r for r in mine if r["gap_s"] == L]
            if not rr:
                cells.append("")
                continue
            fe = np.concatenate([r["fill_mm"] for r in rr])
            se = np.concatenate([r["spline_mm"] for r in rr])
            cells.append(f"{np.median(fe):.1f} / {np.percentile(fe, 95):.0f}; {np.median(se):.1f} / {np.percentile(se, 95):.0f}")
        names = sorted({r["marker"] for r in mine})
        lines.append(f"| {seg} ({', '.join(names)}) | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def markdown(table: list[dict], fills: list[dict]) -> str:
    lines = ["| gap (s) | gaps cut | gap frames | fill median (mm) | fill 95th pct (mm) | fill max (mm) | "
             "0.5 s window: median / 95th (mm) | spline median (mm) | spline 95th pct (mm) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for f in fills:
        lines.append(f"| {f['gap_s']:g} | {f['gaps_cut']} | {f['frames']} | {f['fill_median_mm']:.1f} | "
                     f"{f['fill_p95_mm']:.1f} | {f['fill_max_mm']:.1f} | {f['fill_wide_median_mm']:.1f} / "
                     f"{f['fill_wide_p95_mm']:.1f} | {f['spline_median_mm']:.1f} | {f['spline_p95_mm']:.1f} |")
    lines += ["", "Per angle (all trials and cut markers pooled; each cell: median / 95th percentile |error| in deg "
              "against the uncut run; measured % of gap frames (uncut run); median u in deg (uncut run); % of gap "
              "frames with |error| <= 2u):", ""]
    lengths = [f["gap_s"] for f in fills]
    lines.append("| angle | " + " | ".join(f"{L:g} s" for L in lengths) + " |")
    lines.append("|---|" + "---|" * len(lengths))
    for a in dict.fromkeys(r["angle"] for r in table):
        cells = []
        for L in lengths:
            r = next((r for r in table if r["angle"] == a and r["gap_s"] == L), None)
            if r is None:
                cells.append("")
                continue
            u = "inf" if not np.isfinite(r["u_median_deg"]) else f"{r['u_median_deg']:.1f}"
            u0 = "inf" if not np.isfinite(r["u_median_nogap_deg"]) else f"{r['u_median_nogap_deg']:.1f}"
            cov = "" if not np.isfinite(r["within_2u"]) else f"{100 * r['within_2u']:.0f} %"
            cells.append(f"{r['err_median_deg']:.2f} / {r['err_p95_deg']:.1f}; {100 * r['measured']:.0f} % "
                         f"({100 * r['measured_nogap']:.0f}); u {u} ({u0}); {cov}")
        lines.append(f"| {a} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(path: str, table: list[dict], fills: list[dict]) -> None:
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    with open(Path(path).with_suffix(".fill.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(fills[0]))
        w.writeheader()
        w.writerows(fills)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="one C3D trial, three markers")
    p.add_argument("--out", help="also write the per-angle table to this CSV (and the fill table beside it)")
    p.add_argument("--cache", help="keep each trial's rows in this folder and reuse them (a run cut short resumes)")
    p.add_argument("--trials", help="only the trials whose file name contains one of these (comma-separated)")
    args = p.parse_args(argv)
    if not DATA.is_dir():
        print(f"{DATA}: not there; the gap table needs the real trials of ../shared/data", file=sys.stderr)
        return 2
    started = time.perf_counter()
    rows: list[dict] = []
    trials = TRIALS[:1] if args.quick else TRIALS
    if args.trials:
        trials = [t for t in trials if any(k in t[0].name for k in args.trials.split(","))]
    cache = Path(args.cache) if args.cache else None
    for trial, protocol, static in trials:
        t0 = time.perf_counter()
        part = []
        for saved in sorted(cache.glob(f"{trial.stem}.*pkl")) if cache and cache.is_dir() else ():
            part += pickle.loads(saved.read_bytes())
        new = run_trial(trial, protocol, static, markers_limit=3 if args.quick else None,
                        skip=frozenset(r["marker"] for r in part))  # the markers not in the cache yet
        if new and cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
            (cache / f"{trial.stem}.{'-'.join(sorted({r['marker'] for r in new}))}.pkl").write_bytes(pickle.dumps(new))
        rows += part + new
        print(f"{trial.name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    table, fills = summarise(rows)
    segments = marker_segments()
    joint_table, _ = summarise(on_joint(rows, segments))
    if args.out:
        write_csv(args.out, table, fills)
    n_markers = len({(r["trial"], r["marker"]) for r in rows})
    print(f"{len(trials)} trials, {n_markers} (trial, marker) pairs cut, {len(LENGTHS_S)} gap lengths; "
          f"{time.perf_counter() - started:.0f} s\n")
    print(markdown(table, fills))
    print("\nOnly the gaps of a marker on one of the segments of the angle's joint (JOINT_SEGMENTS):\n")
    print(markdown(joint_table, fills).split("\n\n", 2)[-1])
    print("\nFill and spline error by the cut marker's segment (median / 95th percentile, mm):\n")
    print(fill_by_segment(rows, segments))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
