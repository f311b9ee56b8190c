"""Run the whole validation study, save its typed results and build the report.

Sections (paper figure in brackets), one module each:

1. sensitivity [Fig. 2] (``exubio.validation.sensitivity``): PF on the abduction trial for 8
   spring constants c (10-10000 N/m, log-spaced) x 4 damper-spring ratios k = d/c (0.01-10 s).
2. residuals [Fig. 3, Table 1] (``.residuals``): PF and LS on abduction, flexion and SIER.
3. SIER [Fig. 4] (``.sier``): simulated internal-external rotation with noise and soft-tissue
   artefact against the truth, and over several noise/STA realisations.
4. in vivo [Fig. 5] (``.invivo``, ``.c3d_tasks``): SC, ST, GH angles in Ludewig et al. 2009's own
   definitions against his means and the corridor of comparable studies; the same for the
   21-marker C3D task trials in every plane of elevation their raising phases match.
5. PF vs LS agreement [Fig. 6] (``.agreement``).
6. model mismatch [Fig. 7] (``.mismatch``): trials generated with a perturbed model, reconstructed
   with the generic one: the measured angles' errors and the verdict's model-mismatch check.
7. rates against the truth [Fig. 8] (``.rates``): q̇, q̈ of PF and LS and of finite differences
   of their q against a simulated trial's exact rates, noise-free and with noise and STA.
8. the scapula calibrated over motion, cross-validated (``.scapula``).

then the checks against the paper and the in vivo aims (``.checks``). The trials are real where
the data allow (``.trials``).
"""
from __future__ import annotations

import dataclasses
import logging
import platform
import time
from pathlib import Path

import numpy as np

import exubio
from exubio.validation.agreement import pf_ls_agreement
from exubio.validation.c3d_tasks import c3d_task_comparison
from exubio.validation.checks import invivo_aims, paper_checks
from exubio.io.records import decode
from exubio.validation.invivo import invivo_comparison, ludewig_means
from exubio.validation.mismatch import mismatch_study
from exubio.validation.rates import rates_against_truth, rates_checks
from exubio.validation.scapula import scapula_checks, scapula_cross_validation
from exubio.validation.bone import bone_checks, bone_truth_study
from exubio.validation.paths import portable_paths
from exubio.validation.residuals import residual_table
from exubio.validation.results import METHODS, AgreementTrial, PaperNumbers, ValidationResults
from exubio.validation.sensitivity import sensitivity_study
from exubio.validation.settings import QUICK_SETTINGS, ValidationSettings
from exubio.validation.sier import sier_against_truth, sier_realisations
from exubio.validation.trials import Progress, Trial, prepare_trials, run_method

log = logging.getLogger(__name__)

__all__ = ["run_validation"]


def _truth_rmse_deg(trials: dict[str, Trial]) -> dict[str, dict[str, dict[str, float]]]:
    """RMSE (deg) of every coordinate against the truth, per simulated trial and method."""
    return {name: {m: dict(zip(tr.model.coordinate_names,
                               np.sqrt(np.mean(np.degrees(tr.recon[m].q_rad - tr.sim.q_true) ** 2, axis=0)).tolist()))
                   for m in METHODS if tr.recon.get(m) is not None}
            for name, tr in trials.items() if tr.sim is not None}


def _portable(results: ValidationResults) -> ValidationResults:
    """``results`` with this machine's paths written relative (``portable_paths``)."""
    return decode(ValidationResults, portable_paths(results.to_json()), results.arrays())


def run_validation(out_dir: str | Path = "reports/validation", /, *, quick: bool = False,
                   progress: Progress | None = None,
                   settings: ValidationSettings | None = None) -> ValidationResults:
    """Run the whole study, write the data files (``ValidationResults.save``) and the report into
    ``out_dir``; returns the results. ``quick`` uses short trials (a smoke test, < 30 s)."""
    from exubio.report.paper import PAPER  # numbers only; the report is built from the saved files

    s = settings or (QUICK_SETTINGS if quick else ValidationSettings())
    say: Progress = progress or (lambda msg: log.info("%s", msg))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    say("preparing trials")
    trials = prepare_trials(s, say)
    for tr in trials.values():
        for method in METHODS:
            run_method(tr, method, say)

    say("sensitivity study (32 PF runs)")
    sensitivity = sensitivity_study(trials["abduction"], s, say)
    table1 = residual_table(trials)
    say("SIER against the truth")
    sier = sier_against_truth(trials["sier"], s)
    realisations = sier_realisations(trials["sier"], s, say)
    say("ISB angles against Ludewig et al. 2009")
    ludewig = ludewig_means()
    invivo = invivo_comparison(trials)
    agreement = pf_ls_agreement(trials)
    c3d_tasks = c3d_task_comparison(s, say)
    for name in ("abduction", "flexion"):
        a = agreement.trials.get(name)
        invivo[name] = dataclasses.replace(
            invivo[name], undetermined_isb_angles=a.undetermined_isb_angles if isinstance(a, AgreementTrial) else ())
    say("model mismatch (perturbed generating model)")
    mismatch = mismatch_study(s, say)
    say("rates against the truth")
    rates = rates_against_truth(s, say)
    scapula = scapula_cross_validation(s, say)
    say("bone truth (the ISB soft-tissue-artefact data-sharing trials)")
    bone = bone_truth_study(say, quick=s.quick)
    paper = decode(PaperNumbers, PAPER)
    results = ValidationResults(
        exubio_version=exubio.__version__, python=platform.python_version(),
        machine=platform.machine(), processor=platform.processor() or platform.machine(),
        quick=s.quick, settings=s,
        data={name: tr.data for name, tr in trials.items()},
        reconstruction_errors={name: dict(tr.errors) for name, tr in trials.items() if tr.errors},
        sensitivity=sensitivity, table1=table1, sier=sier, sier_realisations=realisations, invivo=invivo,
        agreement=agreement, c3d_tasks=c3d_tasks, truth_rmse_deg=_truth_rmse_deg(trials), paper=paper,
        checks=paper_checks(sier, realisations, agreement, sensitivity, invivo, paper) + rates_checks(rates)
        + scapula_checks(scapula) + bone_checks(bone),
        rates=rates, scapula=scapula,
        invivo_aims=invivo_aims(invivo), total_wall_s=time.perf_counter() - t_start, ludewig=ludewig,
        mismatch=mismatch, bone=bone)
    results = _portable(results)
    results.save(out)

    say("building the report")
    from exubio.report import build_report

    t_rep = time.perf_counter()
    build_report(out)
    results = dataclasses.replace(results, report_wall_s=time.perf_counter() - t_rep)
    results.save(out)
    say(f"done in {time.perf_counter() - t_start:.0f} s: {out / 'validation.pdf'}")
    return results
