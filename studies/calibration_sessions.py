"""Same-session calibration on real trials: each task trial calibrated from its session's static
trial against the same trial calibrated from its own first frames (issue "Subject calibration").

Pairs (../shared/data/SOURCES.md): martin_statique -> martin_dynamique (shipped protocol), and
kinova_martin_statique -> each kinova_martin trial (``protocols/examples/kinova_martin_session.yaml``,
the session's RADIUS/ULNA relabelling). Both methods run; per trial it prints the mean residual
(PF / LS, mm) of each calibration, the difference static - first frames (the aim: at most 1 mm),
the worst PF-LS RMSE over the determined coordinates and the verdicts.

Usage:
    python studies/calibration_sessions.py [--only dent] [--first-frames 0:20] [--functional] [--json]
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from trust_real_trials import SESSION, SHARED, run_one  # noqa: E402


def pairs() -> list[dict]:
    c3d = SHARED / "c3d"
    out = [{"trial": c3d / "bioptim_exo_martin_dynamique.c3d", "static": c3d / "bioptim_exo_martin_statique.c3d",
            "protocol": None}]
    for name in ("aisselle", "dent", "manger", "tete"):
        out.append({"trial": c3d / f"bioptim_exo_kinova_martin_{name}_f3_1.c3d",
                    "static": c3d / "bioptim_exo_kinova_martin_statique.c3d", "protocol": SESSION})
    return out


def _run(spec: dict, work: Path) -> dict:
    """run_one, with a failure recorded (NaN residuals, the error as the verdict) instead of raised."""
    try:
        return run_one(spec, work)
    except Exception as exc:  # a benchmark reports every pair
        nan = float("nan")
        return {"methods": {m: {"mean_residual_mm": nan, "verdict": f"error: {exc}", "reasons": []} for m in ("pf", "ls")},
                "pf_ls_max_rmse_deg_determined": None, "pf_ls_worst": None}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default="", help="run the trials whose file name contains this")
    ap.add_argument("--first-frames", default="0:20", help="the trial's own calibration frames (default 0:20)")
    ap.add_argument("--json", action="store_true", help="one JSON line per trial on stdout")
    ap.add_argument("--functional", action="store_true",
                    help="also calibrate with the trial itself as the functional trial (SCoRE glenohumeral centre)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to run", file=sys.stderr)
        return 2
    print(f"{'trial':<44} {'static PF/LS mm':>16} {'own PF/LS mm':>14} {'LS diff':>8} {'PF-LS deg':>10}  verdicts (static)",
          file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        for spec in pairs():
            if args.only and args.only not in spec["trial"].name:
                continue
            if args.functional:
                spec = {**spec, "functional": spec["trial"]}
            a = _run(spec, Path(tmp) / "static")
            b = _run({**spec, "static": None, "functional": None, "static_frames": args.first_frames}, Path(tmp) / "own")
            res = {k: (r["methods"]["pf"]["mean_residual_mm"], r["methods"]["ls"]["mean_residual_mm"]) for k, r in
                   (("static", a), ("own", b))}
            rec = {"trial": spec["trial"].name, "static": spec["static"].name, "first_frames": args.first_frames,
                   "residual_mm": res, "ls_diff_mm": round(res["static"][1] - res["own"][1], 2),
                   "pf_ls_max_rmse_deg_determined": a["pf_ls_max_rmse_deg_determined"], "pf_ls_worst": a["pf_ls_worst"],
                   "verdicts": {m: v["verdict"] for m, v in a["methods"].items()},
                   "reasons": {m: v["reasons"] for m, v in a["methods"].items()},
                   "own_verdicts": {m: v["verdict"] for m, v in b["methods"].items()}}
            if args.json:
                print(json.dumps(rec), flush=True)
            print(f"{rec['trial']:<44} {res['static'][0]:>7.2f}/{res['static'][1]:<7.2f} {res['own'][0]:>6.2f}/{res['own'][1]:<6.2f}"
                  f" {rec['ls_diff_mm']:>8.2f} {rec['pf_ls_max_rmse_deg_determined'] or float('nan'):>10.2f}  "
                  f"{rec['verdicts']} (own: {rec['own_verdicts']})", file=sys.stderr, flush=True)
            for m, rs in rec["reasons"].items():
                for r in rs:
                    print(f"    [{m}] {r}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
