"""exubio against bone: every trial of ../shared/data/truth/sta_opendata reconstructed by PF and LS as
a lab would (``exubio truth``), per angle the RMSE, max error and the coverage of +-2u, and the same
with each skin marker carried rigidly by its bone (no soft-tissue artefact: what is left is the
model's girdle and the thorax assumption's). Also: the STA amplitude model fitted on three of the
four S2M tasks and used on the fourth (coverage with a model that did not see the task).

    python studies/bone_truth.py                 # the table (markdown) to stdout
    python studies/bone_truth.py --loto          # + leave-one-task-out coverage
    python studies/bone_truth.py --data DIR      # the trials of another folder (e.g. the tasks below)
    python studies/bone_truth.py --no-direct-misfit   # u as before the direct misfit term
    python studies/bone_truth.py --no-trunk-term      # u as a lab's run gives it (no still-thorax term)

Tasks of the same source not in ../shared (S2M armAdd, armExt, ballThrowing, behindBackReach;
ARTANIM armFlex): STAOpenData/Data @ 33dd5a4, documents_and_data/dataSample/Matlab/, read from a
folder given with --data; not copied into the project.

Data: Cereatti et al. 2017, J Biomech 62:5-13 (ISB STA data-sharing sample; see
../shared/data/truth/SOURCES.md). Rates: S2M 300 Hz, ARTANIM 30 Hz (its SOURCES.md).
"""
from __future__ import annotations

import argparse
import logging
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "truth" / "sta_opendata"
RATES = {"S2M": 300.0, "ARTANIM": 30.0}
SHOWN = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_Y_plane_of_elevation",
         "GH_X_elevation", "GH_Y_axial_rotation", "GH_phadke_X_elevation", "GH_phadke_Z_flexion",
         "GH_phadke_Y_internal_rotation", "HT_Y_plane_of_elevation", "HT_X_elevation", "HT_Y_axial_rotation")


def _cell(e) -> str:
    if e is None or not np.isfinite(e.rmse_deg):
        return "not measured"
    cov = "-" if e.coverage is None else f"{e.coverage:.0%}"
    return f"{e.rmse_deg:.1f} / {e.max_deg:.1f} / {cov} ({e.measured_fraction:.0%})"


def run(path: Path, *, without_sta: bool = False, amplitude=None):
    from exubio.errors import ModelError
    from exubio.io.yaml import read_yaml
    from exubio.model.load import DEFAULT_MODEL
    from exubio.truth.compare import compare_bone_trial
    from exubio.truth.lab_run import setup_lab_run
    from exubio.truth.sta_format import read_sta_trial

    trial = read_sta_trial(path)
    lab = setup_lab_run(trial, read_yaml(DEFAULT_MODEL, error=ModelError), rate_hz=RATES[trial.lab],
                        without_sta=without_sta)
    comp, _ = compare_bone_trial(lab, amplitude=amplitude)
    return comp


def table(comps: list, title: str) -> str:
    head = "| angle | " + " | ".join(f"{c.task} {m.upper()}" for c in comps for m in ("pf", "ls")) + " |"
    sep = "|---|" + "---|" * (2 * len(comps))
    rows = [f"**{title}** (RMSE / max deg / coverage of +-2u (measured frames))", "", head, sep]
    verdict = "| verdict | " + " | ".join(
        (c.verdicts.get(m, "-")[:40] + ("..." if len(c.verdicts.get(m, "")) > 40 else "")) for c in comps
        for m in ("pf", "ls")) + " |"
    rows.append(verdict)
    rows.append("| bone AC off the model clavicle's sphere, median / p95 (mm) | " + " | ".join(
        ("-" if c.clavicle_gap_mm is None else f"{c.clavicle_gap_mm['median']:.0f} / {c.clavicle_gap_mm['p95']:.0f}")
        for c in comps for m in ("pf", "ls")) + " |")
    for a in SHOWN:
        rows.append(f"| {a} | " + " | ".join(
            _cell(c.angles[a].get(m)) if not c.verdicts.get(m, "").startswith("failed") else "PF failed"
            for c in comps for m in ("pf", "ls")) + " |")
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loto", action="store_true", help="also leave-one-task-out STA amplitude coverage (S2M)")
    ap.add_argument("--data", type=Path, default=DATA, help=f"folder of .mat trials (default {DATA})")
    ap.add_argument("--no-direct-misfit", action="store_true",
                    help="as before the direct misfit term: a misfit segment's frame not turned "
                         "(exubio.trust.angle_uncertainty.misfit_angle_variance)")
    ap.add_argument("--no-trunk-term", action="store_true",
                    help="u as a lab's run gives it, without the still thorax's term (the files have no thorax "
                         "marker; exubio truth adds what an unseen trunk costs): the coverage of a lab's u")
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    if args.no_direct_misfit:
        from exubio.trust import angle_uncertainty

        angle_uncertainty.DIRECT_MISFIT = False
    if args.no_trunk_term:  # the table's coverage is then exubio truth's 'lab' figures
        from exubio.truth import compare

        status = compare.angle_status
        compare.angle_status = lambda inputs, rec, *, still_thorax: status(inputs, rec, still_thorax=False)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    files = sorted(args.data.glob("*.mat"))
    comps = [run(f) for f in files]
    print(table(comps, "skin markers as recorded (raw, gaps left as gaps)"))
    print()
    print(table([run(f, without_sta=True) for f in files], "markers carried rigidly by the bones (no STA)"))
    if args.loto:
        import dataclasses

        from exubio.trust.sta_amplitude import load_sta_amplitude
        from exubio.truth.sta_amplitude import fit_sta_amplitude

        shipped = load_sta_amplitude()
        from exubio.truth.sta_format import read_sta_trial

        s2m = [f for f in files if "S2M" in f.name]
        loto = []
        for held in s2m:
            amp = fit_sta_amplitude([(read_sta_trial(f), RATES["S2M"]) for f in s2m if f != held])
            amp = dataclasses.replace(amp, trunk=shipped.trunk, trunk_nodes=shipped.trunk_nodes, trunk_table=shipped.trunk_table,
                                      trunk_source=shipped.trunk_source,  # not from these files
                                      girdle=shipped.girdle, girdle_source=shipped.girdle_source,
                                      girdle_offset_rad=shipped.girdle_offset_rad)
            loto.append(run(held, amplitude=amp))
        print()
        print(table(loto, "STA amplitude fitted on the other three S2M tasks (leave one task out)"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
