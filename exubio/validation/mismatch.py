"""Model mismatch: trials simulated with a perturbed model (exubio.synth.perturb) and reconstructed with
the generic one; the measured angles' errors against the perturbation, and whether the verdict
(exubio.trust.assess, its model-mismatch detector exubio.trust.mismatch) says ``check`` where they cost more
than ``COST_LIMIT_DEG``, and stays ``ok`` without a mismatch.

A run's *mismatch cost* is the worst RMSE over the measured angles (each over the frames where it
is measured) of the same perturbation and motion without noise or soft-tissue artefact: what the
mismatch alone costs. With artefact, the error also holds what noise and STA cost (up to about 5 deg
on a measured angle with 20 mm STA and no mismatch), which no residual check can tell from the
marker motion itself.
"""
from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from exubio.model.angles import anatomical_table
from exubio.protocol.bind import bind
from exubio.trust.assess import assess_trial
from exubio.trust.observability import AngleStatus
from exubio.synth.perturb import ModelPerturbation
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.synth.simulate import simulate_trial
from exubio.types import Model
from exubio.validation.results import MismatchRun, ModelMismatch
from exubio.validation.settings import ValidationSettings

log = logging.getLogger(__name__)

__all__ = ["CASES", "COST_LIMIT_DEG", "MOTIONS", "measured_angle_errors", "mismatch_study", "run_case"]

COST_LIMIT_DEG = 5.0
"""A mismatch that costs more than this (RMSE, deg) on a measured angle must make the verdict check."""

P = ModelPerturbation
CASES: dict[str, ModelPerturbation] = {
    "none": P(),
    "ellipsoid 10 mm posterior, 8 % larger": P(ellipsoid_centre_mm=(-10, 0, 0), ellipsoid_radii_scale=(1.08,) * 3),
    "ellipsoid 5 mm posterior, 4 % larger": P(ellipsoid_centre_mm=(-5, 0, 0), ellipsoid_radii_scale=(1.04,) * 3),
    "ellipsoid 10 mm anterior, 8 % smaller": P(ellipsoid_centre_mm=(10, 0, 0), ellipsoid_radii_scale=(0.92,) * 3),
    "clavicle 10 % longer": P(segment_length_scale={"clavicle": 1.10}),
    "humerus 10 % shorter": P(segment_length_scale={"humerus": 0.90}),
    "GH centre 15 mm up, 10 mm back": P(joint_centre_mm={"humerus": (-10, 15, 0)}),
    "SCAP_IA 20 mm down": P(marker_offset_mm={"SCAP_IA": (0, -20, 0)}),
}
"""The perturbations of the section (studies/model_mismatch.py runs a larger grid)."""
QUICK_CASES = ("none", "ellipsoid 10 mm posterior, 8 % larger")
MOTIONS = ("abduction", "flexion", "scaption")
DURATION_S, RATE_HZ = 5.0, 50.0  # one elevation cycle 10 -> 120 -> 10 deg


def measured_angle_errors(model: Model, truth_model: Model, q_rec: np.ndarray, q_true: np.ndarray,
                          status: np.ndarray, /) -> dict[str, tuple[float, float]]:
    """(RMSE, max |error|) in deg of every anatomical angle measured in more than half of the
    frames, over the frames where it is measured; the truth's angles from the model that generated
    the trial (its anatomical frames are the generic model's for these perturbations)."""
    names, rec = anatomical_table(model, q_rec)
    _, tru = anatomical_table(truth_model, q_true)
    d = np.degrees(np.angle(np.exp(1j * (rec - tru))))
    out = {}
    for j, n in enumerate(names):
        sel = status[:, j] == AngleStatus.MEASURED
        if sel.mean() > 0.5:
            out[n] = (float(np.sqrt(np.mean(d[sel, j] ** 2))), float(np.max(np.abs(d[sel, j]))))
    return out


def run_case(case: str, perturbation: ModelPerturbation, motion: str, *, noise_mm: float, sta_mm: float,
             methods: tuple[str, ...], seed: int = 0, duration_s: float = DURATION_S,
             rate_hz: float = RATE_HZ) -> list[dict]:
    """One simulated trial with ``perturbation``, each method on the generic model, assessed alone:
    per method a dict with the fields of MismatchRun but ``mismatch_cost_deg``."""
    model, protocol = load_model_and_protocol()
    sim = simulate_trial(model, motion, duration_s=duration_s, rate_hz=rate_hz, noise_mm=noise_mm, sta_mm=sta_mm,
                         seed=seed, perturbation=perturbation)
    targets = prepare_targets(sim.trajectories, protocol)
    binding = bind(model, protocol)
    out = []
    for method in methods:
        rec = reconstruct(model, protocol, targets, method=method)
        a = assess_trial(binding, targets, [rec])
        errs = measured_angle_errors(model, sim.model, rec.q_rad, sim.q_true, a.angles[method].status)
        worst = max(errs, key=lambda k: errs[k][0])
        mm = a.mismatch[method]
        scap = mm.evidence.get("scapula")
        out.append(dict(
            case=case, perturbation=perturbation.words(), motion=motion,
            artefact="clean" if noise_mm == 0 and sta_mm == 0 else f"noise {noise_mm:g} mm, STA {sta_mm:g} mm",
            method=method, worst_angle=worst, worst_rmse_deg=errs[worst][0],
            worst_max_deg=max(e[1] for e in errs.values()),
            angle_rmse_deg={k: v[0] for k, v in errs.items()},
            mean_residual_mm=float(np.nanmean(rec.residuals_m)) * 1e3, verdict=a.quality[method].verdict,
            reasons=tuple(f"{x.level}: {x.message}" for x in a.quality[method].reasons if x.level != "note"),
            mismatch_segments=tuple(f.segment for f in mm.findings if f.level == "check"),
            scapula_contact_offset_mean_mm=(float("nan") if scap is None or scap.contact_offset_mean_mm is None
                                            else scap.contact_offset_mean_mm),
            bias_mm={s: e.bias_mm for s, e in mm.evidence.items()}))
    return out


def mismatch_study(s: ValidationSettings, progress: Callable[[str], None]) -> ModelMismatch:
    """Every case x motion, clean and with the settings' noise and STA; both methods (LS only and
    two cases on abduction in a quick run)."""
    cases = {k: CASES[k] for k in QUICK_CASES} if s.quick else CASES
    motions = ("abduction",) if s.quick else MOTIONS
    methods = ("ls",) if s.quick else ("ls", "pf")
    artefacts = ((0.0, 0.0), (s.noise_mm, s.sta_mm))
    rows: list[dict] = []
    for case, pert in cases.items():
        progress(f"model mismatch: {case}")
        for motion in motions:
            cost: dict[str, float] = {}
            for noise, sta in artefacts:
                for row in run_case(case, pert, motion, noise_mm=noise, sta_mm=sta, methods=methods, seed=s.seed):
                    if row["artefact"] == "clean":
                        cost[row["method"]] = row["worst_rmse_deg"]
                    rows.append({**row, "mismatch_cost_deg": cost[row["method"]]})
    runs = tuple(MismatchRun(**r) for r in rows)
    costly = [r for r in runs if r.mismatch_cost_deg > COST_LIMIT_DEG]
    caught = [r for r in costly if r.verdict != "ok" and r.mismatch_segments]
    caught_ids = {id(r) for r in caught}
    clean = [r for r in runs if r.case == "none"]
    return ModelMismatch(
        cost_limit_deg=COST_LIMIT_DEG, duration_s=DURATION_S, rate_hz=RATE_HZ, noise_mm=s.noise_mm, sta_mm=s.sta_mm,
        runs=runs, costly=len(costly), caught=len(caught),
        missed=tuple(f"{r.case} / {r.motion} / {r.artefact} / {r.method}" for r in costly if id(r) not in caught_ids),
        no_mismatch=len(clean), false_alarms=tuple(f"{r.motion} / {r.artefact} / {r.method}" for r in clean
                                                   if r.mismatch_segments),
        no_mismatch_not_ok=tuple(f"{r.motion} / {r.artefact} / {r.method}: {'; '.join(r.reasons)}" for r in clean
                                 if r.verdict != "ok"),
        flagged_cheap=tuple(f"{r.case} / {r.motion} / {r.artefact} / {r.method} (cost {r.mismatch_cost_deg:.1f} deg)"
                            for r in runs if r.case != "none" and r.mismatch_cost_deg <= COST_LIMIT_DEG
                            and r.mismatch_segments))
