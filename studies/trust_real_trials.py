"""Every real trial of ../shared/data through both methods, as a lab would run them, with the
verdicts: what the trust checks say and the figures behind them.

Each C3D task trial is calibrated on its own session's static trial (../shared/data/SOURCES.md);
F0_boire_05 has none and is calibrated on its own first 20 frames; the TRC trials on their first
50 frames with the thoracoscapular protocol. The kinova_martin session is run twice: with the
shipped protocol, and with ``protocols/examples/kinova_martin_session.yaml`` (the shipped protocol
plus the relabelling of that session's swapped RADIUS/ULNA labels). Then every task trial of the two
martin sessions with the static of the OTHER session (markers re-placed between them): what a lab
gets when a study file points a trial to the wrong session.

Prints, per trial and protocol: the verdict of each method with its reasons, the mean residual,
the worst PF-LS RMSE over the determined coordinates and every coordinate's range (deg) against
its limits. One JSON line per run on stdout (``--json``), a table on stderr.

Usage:
    python studies/trust_real_trials.py            # every trial (about a minute on 2 cores)
    python studies/trust_real_trials.py --only kinova_martin_tete
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

from exubio.io.results import read_npz
from exubio.model.load import load_model
from exubio.run.job import TrialJob, run_job

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
SESSION = ROOT / "protocols" / "examples" / "kinova_martin_session.yaml"
TRC_PROTOCOL = ROOT / "protocols" / "thoracoscapular_9.yaml"


def runs() -> list[dict]:
    c3d = SHARED / "c3d"
    out = []
    for name in ("aisselle", "dent", "manger", "tete"):
        trial = c3d / f"bioptim_exo_kinova_martin_{name}_f3_1.c3d"
        static = c3d / "bioptim_exo_kinova_martin_statique.c3d"
        out.append({"trial": trial, "static": static, "protocol": None})
        out.append({"trial": trial, "static": static, "protocol": SESSION})
    out.append({"trial": c3d / "bioptim_exo_martin_dynamique.c3d", "static": c3d / "bioptim_exo_martin_statique.c3d",
                "protocol": None})
    out.append({"trial": c3d / "bioptim_exo_F0_boire_05.c3d", "static_frames": "0:20", "protocol": None})
    # a static of the other session of the same subject (markers re-placed between them)
    # (each trial's and each static's own label fix applied to it alone: --relabel / --static-relabel)
    swap = {"RADIUS": "ULNA", "ULNA": "RADIUS"}  # the kinova_martin session's labelling slip
    for name in ("aisselle", "dent", "manger", "tete"):
        out.append({"trial": c3d / f"bioptim_exo_kinova_martin_{name}_f3_1.c3d", "static": c3d / "bioptim_exo_martin_statique.c3d",
                    "protocol": None, "cross": True, "relabel": swap})
    out.append({"trial": c3d / "bioptim_exo_martin_dynamique.c3d", "static": c3d / "bioptim_exo_kinova_martin_statique.c3d",
                "protocol": None, "cross": True, "static_relabel": swap})
    for name in ("ABD01", "FLX01"):
        out.append({"trial": SHARED / "trc" / f"tsm_rmr_{name}.trc", "static_frames": "0:50", "protocol": TRC_PROTOCOL})
    return out


def run_one(spec: dict, work: Path) -> dict:
    from exubio.run.inputs import load_session
    from exubio.run.session import StaticSpec, calibrate_session

    out_dir = work / f"{spec['trial'].stem}_{'session' if spec['protocol'] == SESSION else 'shipped'}{'_cross' if spec.get('cross') else ''}"
    extra, model_path = {}, None
    session = load_session(protocol_path=spec["protocol"])
    if spec.get("static"):  # the session's static trial: calibration, its label checks, the reference
        static = spec["static"]
        if spec.get("static_relabel"):
            from exubio.io.trial import read_trial
            from exubio.protocol.labels import relabel_trajectories

            static = relabel_trajectories(read_trial(static), spec["static_relabel"])
        cal = calibrate_session(static, session, out_dir, "static",
                                spec=StaticSpec(functional=Path(spec["functional"]) if spec.get("functional") else None))
        model_path, extra["calibration"] = cal.model_file, cal
    result = run_job(TrialJob(spec["trial"], out_dir, methods=("pf", "ls"), session=session,
                              static_frames=spec.get("static_frames"), calibration=extra.get("calibration"),
                              report=False, **({"relabel": spec["relabel"]} if spec.get("relabel") else {})))
    model = load_model(model_path) if model_path else None
    rec = {"trial": spec["trial"].name, "static": Path(spec["static"]).name if spec.get("static") else spec.get("static_frames"),
           "protocol": ("session relabel" if spec["protocol"] == SESSION else Path(spec["protocol"] or "upper_limb_21").stem)
           + (" / OTHER SESSION'S STATIC" if spec.get("cross") else ""),
           "methods": {}}
    for m in result.methods:
        s = m.summary
        recon = read_npz(m.paths["npz"])
        rng = np.degrees((model or load_model(result.calibration.model_file)).coordinate_ranges_rad)
        q = np.degrees(recon.q_rad)
        outside = {n: [round(float(q[:, j].min()), 1), round(float(q[:, j].max()), 1)]
                   for j, n in enumerate(recon.coordinate_names)
                   if n not in s.get("not_measured", []) and (q[:, j].min() < rng[j, 0] - 0.5 or q[:, j].max() > rng[j, 1] + 0.5)}
        rec["methods"][m.method] = {
            "verdict": s["quality"]["verdict"],
            "reasons": [f"{r['level']}: {r['message']}" for r in s["quality"]["reasons"]],
            "mean_residual_mm": round(s["residual_mm"]["mean"], 2),
            "angles_outside_range_deg": outside,
            "not_measured": s.get("not_measured", []),
            "undetermined": s["determinacy"]["undetermined_for_trial"],
            "model_mismatch": s.get("model_mismatch"),
        }
    agree = {k: v for k, v in (result.agreement_deg or {}).items() if v == v}
    rec["pf_ls_max_rmse_deg_determined"] = round(max(agree.values()), 2) if agree else None
    rec["pf_ls_worst"] = max(agree, key=agree.get) if agree else None
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default="", help="run the trials whose file name contains this")
    ap.add_argument("--json", action="store_true", help="one JSON line per run on stdout")
    ap.add_argument("--cross-only", action="store_true", help="only the trials with the other session's static")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to run", file=sys.stderr)
        return 2
    err = sys.stderr
    with tempfile.TemporaryDirectory() as tmp:
        for spec in runs():
            if args.only and args.only not in spec["trial"].name or args.cross_only and not spec.get("cross"):
                continue
            rec = run_one(spec, Path(tmp))
            if args.json:
                print(json.dumps(rec), flush=True)
            ran = rec["methods"]  # a method that failed has no entry: the other's reasons say why
            verdicts = ", ".join(f"{m} {ran[m]['verdict']}" if m in ran else f"{m} FAILED" for m in ("pf", "ls"))
            residual = " / ".join(str(ran[m]["mean_residual_mm"]) if m in ran else "-" for m in ("pf", "ls"))
            either = ran.get("ls") or ran.get("pf") or {}
            print(f"\n{rec['trial']}  [static {rec['static']}, protocol {rec['protocol']}]: {verdicts}; "
                  f"residual {residual} mm; "
                  f"PF-LS max {rec['pf_ls_max_rmse_deg_determined']} deg ({rec['pf_ls_worst']}); "
                  f"outside range: {either.get('angles_outside_range_deg') or 'none'}", file=err)
            for m, v in rec["methods"].items():
                for r in v["reasons"]:
                    print(f"    [{m}] {r}", file=err)
                ev = (v.get("model_mismatch") or {}).get("evidence") or []
                print(f"    [{m}] model-mismatch evidence: " + "; ".join(
                    f"{e['segment']} bias {e['bias_mm']:.1f} mm ({e['worst_bias_marker']} {e['worst_bias_mm']:.1f})"
                    + (f" gap {e['pose_gap_deg']:.1f} deg (p90 {e['pose_gap_p90_deg']:.1f})" if e["pose_gap_deg"] is not None else "")
                    + (f" normal {e['normal_mm']:+.1f} mm" if e["normal_mm"] is not None else "")
                    + (f" contact offset {e['contact_offset_mm']:.1f} mm (mean {e['contact_offset_mean_mm']:+.1f})"
                       if e.get("contact_offset_mm") is not None else "") for e in ev), file=err)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
