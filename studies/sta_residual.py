"""The bone STA model's held-out residual: is the simulated artefact (``exubio simulate --sta bone``:
the regression's mean course plus a draw of what it leaves on held-out tasks) as large as the pins'?

For each S2M pin trial (../shared/data/truth/sta_opendata; Cereatti et al. 2017, J Biomech 62:5-13,
doi 10.1016/j.jbiomech.2017.02.004) held out: the model is built on the other three tasks exactly as
``exubio sta-fit`` builds it (the ridge regression, and its residual process measured by leave one
out among those three), driven by the held-out task's own bone angles, and drawn ``--seeds`` times.
Per segment: the RMS of the cluster's rotation (deg) and of its centroid's translation (mm) in the
data, in the regression's mean course alone (the simulator before), and in the simulated artefact
(mean course + residual draws); the residual's 1/e correlation time (s) in the data and in the draws.

    python studies/sta_residual.py                     # the table (about 30 s)
    python studies/sta_residual.py --write exubio/data/sta_bone_s2m.json   # (re)write the shipped residual

``--write`` adds to a model JSON (its other fields untouched) each segment's ``residual`` measured on
all four S2M tasks (leave one task out).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "truth" / "sta_opendata"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--write", default=None, help="a model JSON to add the residual (all four tasks) to")
    args = ap.parse_args(argv)
    from exubio.synth.sta_validate import held_out_amplitude

    s2m = sorted(DATA.glob("dataSample_S2M_*.mat"))
    if len(s2m) < 4:
        print(f"(the four S2M trials are not in {DATA})")
        return 0
    if args.write:
        from exubio.synth.sta_bone import fit_sta_model

        path = Path(args.write)
        data = json.loads(path.read_text(encoding="utf-8"))
        model = fit_sta_model(s2m, rate_hz=300.0)
        for s, seg in model.segments.items():
            data["segments"][s]["residual"] = seg.residual.to_json()
        path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        print(f"wrote the residual of {', '.join(model.segments)} into {path}")
    print("| held out | segment | rotation deg: pins / mean course / simulated | translation mm: pins / mean course / "
          "simulated | residual correlation s: pins / simulated |\n|---|---|---|---|---|")
    for h in sorted(held_out_amplitude(s2m, rate_hz=300.0, seeds=args.seeds), key=lambda h: (h.segment != "scapula", h.task)):
        r, t, c = h.rotation_deg, h.translation_mm, h.correlation_s
        print(f"| S2M {h.task} | {h.segment} | {r[0]:.1f} / {r[1]:.1f} / {r[2]:.1f} | {t[0]:.1f} / {t[1]:.1f} / {t[2]:.1f} "
              f"| {c[0]:.2f} / {c[1]:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
