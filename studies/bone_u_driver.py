"""The STA amplitude model's driver, tried against the pins (benchmarks/README.md, "The uncertainty a
lab's run gives, on the pins"): each segment's artefact spread grows with d = theta_s tanh(theta /
theta_s), theta the humerus's rotation from rest (0: d = theta, as shipped), in the fit
(exubio.truth.sta_amplitude.fit_sta_amplitude's ``saturation_rad``) and so in the uncertainty. The
girdle's part of u (exubio.truth.girdle) is the shipped one, per rad of theta, in every run. The S2M
standing tasks of ../shared/data/truth are judged with the amplitude fitted on the other S2M tasks
(leave one task out), the tasks of ``--data`` with the amplitude fitted on all four; LS, the u and
status a lab's run gives (no still-thorax term). Printed: per task the measured angles whose coverage
of +-2u is below 90 %, the worst three (coverage, frames measured), and over all of them how many cells
are below 90 % and above 99 %.

    python studies/bone_u_driver.py                        # d = theta, as shipped
    python studies/bone_u_driver.py --saturation 0.5       # theta_s = 0.5 rad
    python studies/bone_u_driver.py --data DIR             # and the held-out S2M tasks of DIR
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import warnings
from pathlib import Path

import numpy as np

from exubio.io.yaml import read_yaml
from exubio.model.load import DEFAULT_MODEL
from exubio.trust.sta_amplitude import load_sta_amplitude
from exubio.truth import compare
from exubio.truth import sta_amplitude as fit
from exubio.truth.lab_run import setup_lab_run
from exubio.truth.sta_format import read_sta_trial

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "truth" / "sta_opendata"
RATE_HZ = 300.0  # S2M


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--saturation", type=float, default=0.0, help="theta_s in rad (0: d = theta, as shipped)")
    ap.add_argument("--data", type=Path, help="a folder of held-out S2M tasks (ball throwing, where the subject steps, left out)")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    ts = args.saturation
    status = compare.angle_status  # every angle judged with the u and status a lab's run gives
    compare.angle_status = lambda inputs, rec, *, still_thorax: status(inputs, rec, still_thorax=False)
    generic, shipped = read_yaml(DEFAULT_MODEL), load_sta_amplitude()
    shared = sorted(SHARED.glob("dataSample_S2M_*.mat"))

    def amplitude(paths):
        a = fit.fit_sta_amplitude([(read_sta_trial(p), RATE_HZ) for p in paths], saturation_rad=ts if ts > 0 else None)
        return dataclasses.replace(a, trunk=shipped.trunk, trunk_nodes=shipped.trunk_nodes,
                                   trunk_table=shipped.trunk_table, trunk_source=shipped.trunk_source,
                                   girdle=shipped.girdle, girdle_source=shipped.girdle_source,
                                      girdle_offset_rad=shipped.girdle_offset_rad)

    def judged(path, amp) -> dict:
        comp, _ = compare.compare_bone_trial(setup_lab_run(read_sta_trial(path), generic, rate_hz=RATE_HZ),
                                             methods=("ls",), amplitude=amp)
        return {a: (e.coverage, e.measured_fraction) for a, per in comp.angles.items() for m, e in per.items()
                if e.coverage is not None and np.isfinite(e.rmse_deg)}

    rows = [(f"{p.stem[11:]} (other tasks' fit)", judged(p, amplitude([q for q in shared if q != p])))
            for p in shared if "punching" not in p.name]  # punching: the subject steps (benchmarks/README.md)
    if args.data is not None:
        every = amplitude(shared)
        rows += [(f"{p.stem[11:]} (held out)", judged(p, every)) for p in sorted(args.data.glob("dataSample_S2M_*.mat"))
                 if "ballThrowing" not in p.name]
    cells = []
    for name, cov in rows:
        worst = sorted(cov.items(), key=lambda kv: kv[1][0])
        cells += [c for c, _ in cov.values()]
        print(f"{name:40s} below 90 %: {sum(c < 0.9 for c, _ in cov.values())} of {len(cov)}; worst "
              + ", ".join(f"{a} {c:.0%} ({f:.0%})" for a, (c, f) in worst[:3]))
    print(f"theta_s {ts:g} rad: {len(cells)} cells, {sum(c < 0.9 for c in cells)} below 90 %, "
          f"{sum(c > 0.99 for c in cells)} above 99 %, median {np.median(cells):.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
