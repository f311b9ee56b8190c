"""Fig. 2: PF's sensitivity to the spring constant c and the damper-spring ratio k = d/c, the same
for every marker: one PF reconstruction of the abduction trial per (c, k) of the settings' grid,
its mean spring deflection over all markers and frames. PF falls back on its own
(exubio.methods.pf.PFOptions.fallback: a run that stops is run again with inertia x 0.01 and full
Newton): a run that finished on the fallback is recorded with its first run's reason
(``fallback_runs``); a run that raises ReconstructionError even so is recorded as failed."""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from exubio.errors import ReconstructionError
from exubio.run.pipeline import reconstruct
from exubio.types import Protocol
from exubio.validation.results import FailedRun, Sensitivity
from exubio.validation.settings import ValidationSettings
from exubio.validation.trials import Progress, Trial

__all__ = ["sensitivity_study", "with_springs"]


def with_springs(protocol: Protocol, stiffness: float, damping: float) -> Protocol:
    """``protocol`` with every marker's spring constant (N/m) and damping (Ns/m) set."""
    markers = tuple(dataclasses.replace(m, stiffness_n_per_m=stiffness, damping_ns_per_m=damping)
                    for m in protocol.markers)
    return dataclasses.replace(protocol, markers=markers, default_stiffness_n_per_m=stiffness,
                               default_damping_ns_per_m=damping)


def sensitivity_study(trial: Trial, s: ValidationSettings, progress: Progress) -> Sensitivity:
    """PF on ``trial`` for every ratio x stiffness of the settings."""
    cs, ks = np.array(s.sensitivity_stiffness_n_per_m), np.array(s.sensitivity_ratio_s)
    defl = np.full((ks.size, cs.size), np.nan)
    wall = np.full((ks.size, cs.size), np.nan)
    failures, fell_back = [], []
    t_all = time.perf_counter()
    for a, k in enumerate(ks):
        for b, c in enumerate(cs):
            progress(f"sensitivity: c = {c:.0f} N/m, k = {k:g} s ({a * cs.size + b + 1}/{cs.size * ks.size})")
            prot = with_springs(trial.protocol, c, k * c)
            t0 = time.perf_counter()
            try:
                rec = reconstruct(trial.model, prot, trial.targets, method="pf")
                defl[a, b] = float(np.nanmean(rec.residuals_m)) * 1000.0
                fb = rec.info.get("fallback")
                if fb:
                    fell_back.append(FailedRun(stiffness_n_per_m=float(c), ratio_s=float(k), error=fb["first_run"],
                                               robust_options=", ".join(f"{o} {v}" for o, v in fb["options"].items()),
                                               robust_deflection_mm=defl[a, b]))
            except ReconstructionError as exc:
                failures.append(FailedRun(stiffness_n_per_m=float(c), ratio_s=float(k), error=str(exc)))
            wall[a, b] = time.perf_counter() - t0
    total = time.perf_counter() - t_all
    return Sensitivity(trial=trial.name, frames=trial.targets.n_frames, runs=int(cs.size * ks.size),
                       failed_runs=tuple(failures), fallback_runs=tuple(fell_back), total_wall_s=total,
                       wall_s_per_run_max=float(np.nanmax(wall)),
                       stiffness_n_per_m=cs, ratio_s=ks, mean_deflection_mm=defl, wall_s=wall)
