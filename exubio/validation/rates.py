"""Rates against the truth: q̇ and q̈ of PF and LS, and of finite differences of each method's q,
against a simulated trial's exact rates, per coordinate, noise-free and with noise and
soft-tissue artefact; the constraint residuals at position, velocity and acceleration level.

The paper's point for PF is one consistent trajectory q, q̇, q̈ from one integration. What this
section measures (abduction, ``ValidationSettings`` trial length and rate, the 21-marker set):

* ``pf`` / ``ls``: each method's own rates (PF: Exudyn's integrated velocities and accelerations,
  projected on the constraints; LS: the constrained rates solved from the targets' spline
  velocities and accelerations, exubio.methods.poses.solve_rates);
* ``pf_fd`` / ``ls_fd``: central finite differences of each method's q (what a user of a q-only
  tool gets);
* ``pf_no_lead_in`` (noise-free only): PF started at the first frame (``PFOptions.lead_in_s = 0``),
  the former behaviour, kept as the evidence for why PF's noise-free q̈ was no better than LS's:
  its q̈ started at the force-free value (0) and the stiff spring-damper mode took ~40 ms to
  settle (errors up to ~80 deg/s^2 there, ~0.3 deg/s^2 after); the lead-in (the run starts 0.1 s
  earlier on backward-extrapolated targets) removes that transient.

All RMSEs are over the interior frames (the first and last frame, where a central difference is
undefined, are left out for every source alike). Constraint residuals: max |g| (position), max
|G q̇| (1/s, velocity), max |G q̈ + eta| (1/s^2, acceleration) over the frames.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from exubio.errors import ReconstructionError
from exubio.model.kinematics import Kinematics
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.trust.evaluate import rmse_deg
from exubio.synth.simulate import Motion
from exubio.validation.determinacy import UNDETERMINED_SHARE, undetermined_coordinates
from exubio.validation.results import Check, Rates, RatesCondition
from exubio.validation.settings import ValidationSettings
from exubio.validation.trials import Progress, simulated

__all__ = ["PF_AIM_QD_DEG_S", "PF_AIM_QDD_DEG_S2", "rates_against_truth", "rates_checks", "rates_of"]

PF_AIM_QD_DEG_S = 1.0  # issue 21: noise-free PF q̇ within 1 deg/s of the truth on every measured coordinate
PF_AIM_QDD_DEG_S2 = 5.0  # ... and q̈ within 5 deg/s^2


def finite_differences(q: np.ndarray, dt: float, /) -> tuple[np.ndarray, np.ndarray]:
    """Central first and second differences of q (n, m) at the interior frames 1 .. n-2 (the
    end frames are NaN)."""
    qd = np.full_like(q, np.nan)
    qdd = np.full_like(q, np.nan)
    qd[1:-1] = (q[2:] - q[:-2]) / (2.0 * dt)
    qdd[1:-1] = (q[2:] - 2.0 * q[1:-1] + q[:-2]) / dt**2
    return qd, qdd


def _rmse_deg(est: np.ndarray, true: np.ndarray, names) -> dict[str, float]:
    """Per coordinate RMSE (deg), the first and last frames left out (no central difference there)."""
    return rmse_deg(est[1:-1], true[1:-1], names)


def constraint_levels(kin: Kinematics, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, /) -> tuple[float, float, float]:
    """(max |g|, max |G q̇| 1/s, max |G q̈ + eta| 1/s^2) over the frames."""
    G = kin.G(q)
    g = np.abs(kin.g(q)).max()
    gv = np.abs(np.einsum("nkm,nm->nk", G, qd)).max()
    ga = np.abs(np.einsum("nkm,nm->nk", G, qdd) + kin.eta(q, qd)).max()
    return float(g), float(gv), float(ga)


def rates_of(model, protocol, targets, sim, *, pf_options: dict | None = None, with_no_lead_in: bool = False
             ) -> dict:
    """Rates of PF and LS (and their q's finite differences) against ``sim``'s truth: a dict of
    the RatesCondition fields that depend on the reconstructions."""
    kin = Kinematics(model)
    names = model.coordinate_names
    dt = float(np.median(np.diff(targets.time_s)))
    qd_rmse, qdd_rmse, q_rmse, g, gv, ga, wall, errors = {}, {}, {}, {}, {}, {}, {}, {}
    runs = [("pf", "pf", dict(pf_options or {})), ("ls", "ls", {})]
    if with_no_lead_in:
        runs.append(("pf_no_lead_in", "pf", {**(pf_options or {}), "lead_in_s": 0.0}))
    for label, method, opts in runs:
        t0 = time.perf_counter()
        try:
            rec = reconstruct(model, protocol, targets, method=method, **opts)
        except ReconstructionError as exc:
            errors[label] = str(exc)
            continue
        wall[label] = time.perf_counter() - t0
        q_rmse[label] = _rmse_deg(rec.q_rad, sim.q_true, names)
        qd_rmse[label] = _rmse_deg(rec.qd_rad_s, sim.qd_true, names)
        qdd_rmse[label] = _rmse_deg(rec.qdd_rad_s2, sim.qdd_true, names)
        g[label], gv[label], ga[label] = constraint_levels(kin, rec.q_rad, rec.qd_rad_s, rec.qdd_rad_s2)
        if label in ("pf", "ls"):
            fd_qd, fd_qdd = finite_differences(rec.q_rad, dt)
            qd_rmse[f"{label}_fd"] = _rmse_deg(fd_qd, sim.qd_true, names)
            qdd_rmse[f"{label}_fd"] = _rmse_deg(fd_qdd, sim.qdd_true, names)
            _, gv[f"{label}_fd"], ga[f"{label}_fd"] = constraint_levels(kin, rec.q_rad[1:-1], fd_qd[1:-1], fd_qdd[1:-1])
            g[f"{label}_fd"] = g[label]
    return {"q_rmse_deg": q_rmse, "qd_rmse_deg_s": qd_rmse, "qdd_rmse_deg_s2": qdd_rmse, "max_abs_g": g,
            "max_abs_g_qd_1_s": gv, "max_abs_g_qdd_eta_1_s2": ga, "wall_s": wall, "errors": errors}


def rates_against_truth(s: ValidationSettings, progress: Progress) -> Rates:
    """The rates section: the simulated abduction noise-free and with the settings' noise and STA."""
    model, protocol = load_model_and_protocol()
    names = model.coordinate_names
    conditions = {}
    measured: tuple[str, ...] = ()
    for key, noise, sta in (("noise_free", 0.0, 0.0), ("noise_sta", s.noise_mm, s.sta_mm)):
        settings = dataclasses.replace(s, noise_mm=noise, sta_mm=sta)
        sim, targets = simulated(model, protocol, Motion.ABDUCTION, s.trial_duration_s, s.trial_rate_hz, settings,
                                 s.seed)
        if not measured:
            idx = np.linspace(0, sim.q_true.shape[0] - 1, 5).round().astype(int)
            share = undetermined_coordinates(model, protocol, sim.q_true[idx])
            measured = tuple(n for n in names if share[n] <= UNDETERMINED_SHARE and n not in protocol.held_coordinates)
        progress(f"rates: {key} ({targets.n_frames} frames): PF, LS" + (", PF without lead-in" if key == "noise_free"
                                                                        else ""))
        got = rates_of(model, protocol, targets, sim, with_no_lead_in=(key == "noise_free"))
        conditions[key] = RatesCondition(
            description=sim.description, noise_mm=float(noise), sta_mm=float(sta), frames=int(targets.n_frames),
            rate_hz=float(s.trial_rate_hz),
            truth_rms_qd_deg_s=dict(zip(names, np.degrees(np.sqrt(np.mean(sim.qd_true**2, axis=0))).tolist())),
            truth_rms_qdd_deg_s2=dict(zip(names, np.degrees(np.sqrt(np.mean(sim.qdd_true**2, axis=0))).tolist())),
            **got)
    free = conditions["noise_free"]
    pf_qd = max((free.qd_rmse_deg_s.get("pf", {}).get(n, np.nan) for n in measured), default=np.nan)
    pf_qdd = max((free.qdd_rmse_deg_s2.get("pf", {}).get(n, np.nan) for n in measured), default=np.nan)
    return Rates(trial="abduction", coordinates=names, measured_coordinates=measured, conditions=conditions,
                 pf_noise_free_max_qd_rmse_deg_s=float(pf_qd), pf_noise_free_max_qdd_rmse_deg_s2=float(pf_qdd),
                 aim_qd_deg_s=PF_AIM_QD_DEG_S, aim_qdd_deg_s2=PF_AIM_QDD_DEG_S2)


def rates_checks(rates: Rates) -> tuple[Check, ...]:
    """The aims of issue 21 for PF's rates (noise-free, every measured coordinate)."""
    def check(what, value, limit, unit):
        ok = None if not np.isfinite(value) else bool(value <= limit)
        return Check(what=what, value=float(value), limit=float(limit), unit=unit, kind="aim", passed=ok)

    return (check("PF q̇ RMSE vs truth, noise-free, worst measured coordinate", rates.pf_noise_free_max_qd_rmse_deg_s,
                  rates.aim_qd_deg_s, "deg/s"),
            check("PF q̈ RMSE vs truth, noise-free, worst measured coordinate",
                  rates.pf_noise_free_max_qdd_rmse_deg_s2, rates.aim_qdd_deg_s2, "deg/s^2"))
