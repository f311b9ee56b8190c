"""The rhythm pages as PNGs (reports/screenshots/): a trial's (the first method's result of an
``exubio reconstruct`` folder) and a study's group page (an ``exubio study`` folder), drawn by the
same functions as the PDF reports (exubio.report.rhythm_page).

    python studies/rhythm_figures.py --trial OUT/TRIAL.pf.npz --study STUDY_OUT --out reports/screenshots

Printed: per angle and phase, the group's mean and SD at HT elevation 30/60/90/120 deg and how
much of HT 30-120 deg the group mean spends inside the in vivo corridor.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from exubio.report.rhythm_page import study_rhythm_pages, trial_rhythm_figure
from exubio.scapulohumeral.files import study_rhythm
from exubio.scapulohumeral.table import HT_GRID_DEG, RHYTHM_ANGLES


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", type=Path, required=True)
    ap.add_argument("--study", type=Path, required=True)
    ap.add_argument("--out", type=Path, default=Path("reports/screenshots"))
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    method = a.trial.name.split(".")[-2]
    fig = trial_rhythm_figure(a.trial, a.trial.name.split(".")[0], method)
    if fig is None:
        raise SystemExit(f"{a.trial}: no rhythm (no raising or lowering of the arm)")
    fig.savefig(a.out / "rhythm_trial_page.png", dpi=100)
    groups = study_rhythm(a.study)
    name = json.loads((a.study / "study.json").read_text(encoding="utf-8")).get("study", a.study.name)
    pages = study_rhythm_pages(groups, name)
    pages[0].savefig(a.out / "rhythm_study_group_page.png", dpi=100)
    g = groups[0]
    print(f"{g.method} {g.plane}: {len(g.subjects)} subjects, {len(g.trials)} trials")
    at = [int(np.flatnonzero(HT_GRID_DEG == h)[0]) for h in (30, 60, 90, 120)]
    sel = (HT_GRID_DEG >= 30) & (HT_GRID_DEG <= 120)
    for k, (name, _) in enumerate(RHYTHM_ANGLES):
        for p, phase in enumerate(("raising", "lowering")):
            m, sd = g.group.mean_deg[p, :, k], g.group.sd_deg[p, :, k]
            cells = " ".join(f"{m[i]:7.1f}±{sd[i]:4.1f}" for i in at)
            lo, hi = g.reference.at(name, HT_GRID_DEG)
            ok = sel & np.isfinite(lo) & np.isfinite(m)
            share = f"{np.mean((m[ok] >= lo[ok]) & (m[ok] <= hi[ok])):.0%} of {ok.sum() * 2 - 2} deg" if ok.any() else "no corridor"
            print(f"{name:32s} {phase:8s} {cells}   inside corridor: {share}")


if __name__ == "__main__":
    main()
