"""The validation's bone-truth chapter: every bone-referenced trial of the shared data (the ISB
soft-tissue-artefact data-sharing sample, ``<shared data>/truth/sta_opendata``) reconstructed by PF
and LS as ``exubio truth`` does (exubio.truth), per task and angle the RMSE, the maximum error and
the coverage of +-2u over the measured frames, beside the published skin-marker-against-bone ranges
(Begon M, Andersen MS, Dumas R (2018) Multibody kinematics optimization for the estimation of upper
and lower limb human joint kinematics: a systematized methodological review. J Biomech Eng
140:030801: GH 3-10 deg; the scapula's best methods 3-6 deg below 120 deg of elevation).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from exubio.validation.paths import shared_data_dir
from exubio.validation.records_comparisons import BONE_PUBLISHED as PUBLISHED
from exubio.validation.records_comparisons import BONE_SHOWN as SHOWN
from exubio.validation.records_comparisons import BoneAngle, BoneTask, BoneTruth
from exubio.validation.records_runs import Skipped
from exubio.validation.results import Check

__all__ = ["BONE_RATES_HZ", "BoneAngle", "BoneTask", "BoneTruth", "PUBLISHED", "bone_truth_study", "bone_checks"]

BONE_RATES_HZ = {"S2M": 300.0, "ARTANIM": 30.0}
"""The sampling rates the files do not store, from the dataset's documentation (SOURCES.md)."""

def bone_truth_study(say: Callable[[str], None] = lambda _: None, /, *, quick: bool = False) -> BoneTruth | Skipped:
    """Every .mat trial under ``<shared data>/truth/sta_opendata`` through exubio.truth (``quick``:
    the shortest one only, a smoke test of the chapter)."""
    from exubio.errors import ExubioError, ModelError
    from exubio.io.yaml import read_yaml
    from exubio.model.load import DEFAULT_MODEL
    from exubio.truth.compare import compare_bone_trial
    from exubio.truth.lab_run import setup_lab_run
    from exubio.truth.sta_format import read_sta_trial

    folder = shared_data_dir() / "truth" / "sta_opendata"
    files = sorted(folder.glob("*.mat")) if folder.is_dir() else []
    if not files:
        return Skipped(skipped=f"no bone-referenced trial in {folder}")
    if quick:
        files = [min(files, key=lambda f: f.stat().st_size)]
    generic = read_yaml(DEFAULT_MODEL, error=ModelError)
    tasks: dict[str, BoneTask] = {}
    assumption = ""
    for path in files:
        say(f"bone truth: {path.name}")
        try:
            trial = read_sta_trial(path)
            run = setup_lab_run(trial, generic, rate_hz=BONE_RATES_HZ.get(trial.lab, 100.0))
            comp, _ = compare_bone_trial(run)
        except ExubioError as exc:
            tasks[path.stem] = BoneTask(file=path.name, task=path.stem, n_frames=0,
                                        verdicts={"pf": f"failed: {exc}", "ls": f"failed: {exc}"}, angles={})
            continue
        assumption = comp.assumption.split("; left arm")[0]
        angles = {}
        for a in SHOWN:
            angles[a] = {m: BoneAngle(rmse_deg=e.rmse_deg, max_deg=e.max_deg,
                                      coverage=float("nan") if e.coverage is None else e.coverage,
                                      measured_fraction=e.measured_fraction)
                         for m, e in comp.angles[a].items()}
        tasks[path.stem] = BoneTask(file=path.name, task=comp.task, n_frames=comp.n_frames,
                                    verdicts={m: v[:200] for m, v in comp.verdicts.items()}, angles=angles)
    return BoneTruth(assumption=assumption, tasks=tasks)


def bone_checks(bone: BoneTruth | Skipped | None, /) -> tuple[Check, ...]:
    """Aims against bone (LS, the S2M tasks PF and LS both finish): GH in Phadke's sequence within
    the published skin-marker range (RMSE <= 10 deg), and the uncertainty's coverage of the ST and
    GH angles at least 90 % (the median over tasks and angles)."""
    if not isinstance(bone, BoneTruth):
        return ()
    gh, cov = [], []
    for t in bone.tasks.values():
        if not t.angles or str(t.verdicts.get("pf", "")).startswith("failed"):
            continue
        for a, per in t.angles.items():
            e = per.get("ls")
            if e is None or not np.isfinite(e.rmse_deg):
                continue
            if a.startswith("GH_phadke"):
                gh.append(e.rmse_deg)
            if a.startswith(("ST_", "GH_")) and np.isfinite(e.coverage):
                cov.append(e.coverage)
    out = []
    if gh:
        worst = float(max(gh))
        out.append(Check(what="bone truth: GH (Phadke) RMSE against the pins, worst task and angle (LS)", value=worst,
                         limit=PUBLISHED["GH"][1], unit="deg", kind="aim", passed=worst <= PUBLISHED["GH"][1],
                         note="published skin-marker range 3-10 deg (Begon et al. 2018)"))
    if cov:
        med = float(np.median(cov))
        out.append(Check(what="bone truth: median coverage of +-2u over the ST and GH angles (LS)", value=med,
                         limit=0.90, unit="fraction", kind="aim_min", passed=med >= 0.90,
                         note="the aim is about 0.95; studies/README.md, exubio against bone"))
    return tuple(out)
