"""Fig. 6: how closely PF and LS agree on the same trials: RMSE between their joint coordinates
(over the coordinates the markers determine), model-point trajectories, ISB angles and segment
orientations; where segments carry no marker, PF again with them almost massless (a diagnostic
of the inertial coupling LS does not have)."""
from __future__ import annotations

import dataclasses

import numpy as np

from exubio.model.angles import isb_angles
from exubio.errors import ReconstructionError
from exubio.model.kinematics import Kinematics
from exubio.run.pipeline import reconstruct
from exubio.types import Model
from exubio.validation.determinacy import trial_undetermined, undetermined_isb, unobserved_segments
from exubio.validation.results import (
    Agreement,
    AgreementTrial,
    MasslessDiagnostic,
    MasslessFailed,
    NotCompared,
    RmsMax,
)
from exubio.validation.trials import Trial

__all__ = ["pf_ls_agreement"]


def _massless(model: Model, segments: list[str], factor: float = 1e-3) -> Model:
    segs = tuple(dataclasses.replace(s, mass_kg=s.mass_kg * factor, inertia_kgm2=np.asarray(s.inertia_kgm2) * factor)
                 if s.name in segments else s for s in model.segments)
    return dataclasses.replace(model, segments=segs)


def _orientation_difference_deg(model: Model, q_a: np.ndarray, q_b: np.ndarray) -> dict[str, RmsMax]:
    """Angle (deg) of the relative rotation between the two reconstructions' segment orientations:
    sequence-independent, so it is not inflated near a gimbal lock of the joint coordinates."""
    kin = Kinematics(model)
    Ra, _ = kin.poses(q_a)
    Rb, _ = kin.poses(q_b)
    out = {}
    for i, seg in enumerate(model.segments[1:], start=1):
        tr = np.trace(np.swapaxes(Ra[:, i], -1, -2) @ Rb[:, i], axis1=-2, axis2=-1)
        ang = np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))
        out[seg.name] = RmsMax(rms=float(np.sqrt(np.mean(ang**2))), max=float(ang.max()))
    return out


CAUSE_MASS_FACTOR = 1e-2  # the causes diagnostic: every segment's mass and inertia x this
CAUSE_DAMPING_FACTOR = 0.1  # ... and every damper x this


def _marker_rmse_causes(tr: Trial, ls) -> dict[str, float] | None:
    """PF-LS max marker-trajectory RMSE (mm) with PF's two departures from LS taken away one after
    the other (issue 21): every segment almost massless (inertia: the springs no longer accelerate
    anything, m a / c -> 0), then also the dampers weakened (damping: with massless segments PF
    follows LS through the first-order lag d/c, which matters where the markers are not consistent
    with the rigid model, i.e. on real data). None when a run fails."""
    light = _massless(tr.model, list(tr.model.segment_names), CAUSE_MASS_FACTOR)
    weak = dataclasses.replace(tr.protocol, markers=tuple(
        dataclasses.replace(m, damping_ns_per_m=m.damping_ns_per_m * CAUSE_DAMPING_FACTOR) for m in tr.protocol.markers))
    out = {}
    for key, model, protocol in (("masses_x0.01", light, tr.protocol), ("masses_x0.01_dampers_x0.1", light, weak)):
        try:
            rec = reconstruct(model, protocol, tr.targets, method="pf")
        except ReconstructionError:
            return None
        d = np.linalg.norm(rec.model_points_m - ls.model_points_m, axis=2) * 1000.0
        out[key] = float(np.nanmax(np.sqrt(np.nanmean(d**2, axis=0))))
    return out


def pf_ls_agreement(trials: dict[str, Trial]) -> Agreement:
    """PF against LS on every trial where both ran; the maxima over the trials."""
    per: dict[str, AgreementTrial | NotCompared] = {}
    coord_rmse, marker_rmse = [], []
    for name, tr in trials.items():
        pf, ls = tr.recon.get("pf"), tr.recon.get("ls")
        if pf is None or ls is None:
            per[name] = NotCompared()
            continue
        names = pf.coordinate_names
        undetermined = trial_undetermined(tr)
        determined = np.array([n not in undetermined for n in names])
        d = np.degrees(pf.q_rad - ls.q_rad)
        rmse_q = np.sqrt(np.mean(d**2, axis=0))
        dm = np.linalg.norm(pf.model_points_m - ls.model_points_m, axis=2) * 1000.0
        rmse_m = np.sqrt(np.nanmean(dm**2, axis=0))
        kin = Kinematics(tr.model)
        a_pf, a_ls = isb_angles(tr.model, pf.q_rad, kinematics=kin), isb_angles(tr.model, ls.q_rad, kinematics=kin)
        isb = {j: tuple(np.degrees(np.sqrt(np.mean((a_pf[j] - a_ls[j]) ** 2, axis=0))).tolist()) for j in a_pf}
        rmse_det = np.where(determined, rmse_q, -np.inf)
        coord_rmse.append(rmse_det.max())
        marker_rmse.append(np.nanmax(rmse_m))
        diagnostic: MasslessDiagnostic | MasslessFailed | None = None
        massless = None
        free = unobserved_segments(tr.model, tr.protocol)
        if free:
            # diagnostic: in PF the segments without markers still move (inertial coupling) and load
            # their parents; with their mass and inertia scaled by 1e-3 that load disappears
            try:
                pf_d = reconstruct(_massless(tr.model, free), tr.protocol, tr.targets, method="pf")
            except ReconstructionError as exc:
                diagnostic = MasslessFailed(segments=tuple(free), failed=str(exc))
            else:
                massless = np.sqrt(np.mean(np.degrees(pf_d.q_rad - ls.q_rad) ** 2, axis=0))
                diagnostic = MasslessDiagnostic(
                    segments=tuple(free), coordinate_rmse_deg=dict(zip(names, massless.tolist())),
                    max_coordinate_rmse_deg=float(np.where(determined, massless, -np.inf).max()),
                    max_coordinate=names[int(np.argmax(np.where(determined, massless, -np.inf)))],
                    max_marker_rmse_mm=float(np.nanmax(np.sqrt(np.nanmean(
                        (np.linalg.norm(pf_d.model_points_m - ls.model_points_m, axis=2) * 1000.0) ** 2, axis=0)))),
                    segment_orientation_difference_deg=_orientation_difference_deg(tr.model, pf_d.q_rad, ls.q_rad))
        causes = _marker_rmse_causes(tr, ls) if tr.data.is_real else None
        per[name] = AgreementTrial(
            coordinate_rmse_deg=dict(zip(names, rmse_q.tolist())),
            undetermined_coordinates=tuple(undetermined),
            undetermined_isb_angles=tuple(undetermined_isb(undetermined)),
            max_coordinate_rmse_deg=float(rmse_det.max()),
            max_coordinate=names[int(np.argmax(rmse_det))],
            max_coordinate_rmse_deg_all=float(rmse_q.max()),
            marker_rmse_mm=dict(zip(pf.marker_names, rmse_m.tolist())),
            max_marker_rmse_mm=float(np.nanmax(rmse_m)),
            max_marker=pf.marker_names[int(np.nanargmax(rmse_m))],
            isb_angle_rmse_deg=isb,
            segment_orientation_difference_deg=_orientation_difference_deg(tr.model, pf.q_rad, ls.q_rad),
            diagnostic_massless_unobserved=diagnostic, marker_rmse_causes_mm=causes,
            coord_rmse_deg=rmse_q, marker_rmse_series_mm=rmse_m, marker_names=np.array(pf.marker_names),
            coordinate_names=np.array(names), determined=determined, coord_rmse_massless_deg=massless)
    return Agreement(trials=per,
                     max_coordinate_rmse_deg=float(max(coord_rmse)) if coord_rmse else float("nan"),
                     max_marker_rmse_mm=float(max(marker_rmse)) if marker_rmse else float("nan"))
