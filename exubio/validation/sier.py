"""Fig. 4: the simulated internal-external rotation (SIER) with noise and soft-tissue artefact
against its truth: GH axial rotation and the GH marker (``ValidationSettings.gh_marker``) under PF
and LS; and the same over several noise/STA realisations (how typical is the Fig. 4 seed?)."""
from __future__ import annotations

import time

import numpy as np

from exubio.model.angles import isb_angles
from exubio.errors import ReconstructionError
from exubio.model.kinematics import Kinematics
from exubio.run.pipeline import reconstruct
from exubio.synth.simulate import Motion
from exubio.validation.results import (
    METHODS,
    Failed,
    MedianMax,
    Sier,
    SierMethod,
    SierRealisations,
    SierRun,
    SierRunMethod,
    SierSummary,
)
from exubio.validation.settings import ValidationSettings
from exubio.validation.trials import Progress, Trial, plot_stride, simulated

__all__ = ["sier_against_truth", "sier_realisations"]


def sier_against_truth(trial: Trial, s: ValidationSettings) -> Sier:
    """PF and LS on the SIER trial against the simulated truth (Fig. 4)."""
    sim = trial.sim
    model = trial.model
    names = model.coordinate_names
    ir = names.index("gh_internal_rotation")
    kin = Kinematics(model)
    pts = kin.point_set([("humerus", s.gh_marker)])
    true_pos = kin.points(sim.q_true, pts)[:, 0]  # thorax frame
    raw = sim.trajectories.marker(s.gh_marker)  # lab frame: back to the thorax frame
    raw_thorax = (raw - sim.lab_origin_m) @ sim.lab_rotation
    ref = true_pos[0]
    stride = plot_stride(sim.time_s.size)
    rotation = {"true": np.degrees(sim.q_true[::stride, ir])}
    marker = {"true": (true_pos[::stride] - ref) * 1000.0, "input": (raw_thorax[::stride] - ref) * 1000.0}
    true_isb = isb_angles(model, sim.q_true, kinematics=kin)["GH"][:, 2]
    per: dict[str, SierMethod | Failed] = {}
    for method in METHODS:
        rec = trial.recon.get(method)
        if rec is None:
            per[method] = trial.failure(method)
            continue
        j = rec.marker_names.index(s.gh_marker)
        est = rec.model_points_m[:, j]
        d_rot = np.degrees(rec.q_rad[:, ir] - sim.q_true[:, ir])
        d_pos = (est - true_pos) * 1000.0
        isb = isb_angles(model, rec.q_rad, kinematics=kin)["GH"][:, 2]
        rotation[method] = np.degrees(rec.q_rad[::stride, ir])
        marker[method] = (est[::stride] - ref) * 1000.0
        per[method] = SierMethod(
            gh_axial_rotation_rmse_deg=float(np.sqrt(np.mean(d_rot**2))),
            gh_isb_axial_rotation_rmse_deg=float(np.degrees(np.sqrt(np.mean((isb - true_isb) ** 2)))),
            gh_marker_rmse_xyz_mm=tuple(np.sqrt(np.mean(d_pos**2, axis=0)).tolist()),
            joint_rmse_deg=dict(zip(names, np.sqrt(np.mean(np.degrees(rec.q_rad - sim.q_true) ** 2, axis=0)).tolist())))
    gh = list(sim.trajectories.labels).index(s.gh_marker)
    return Sier(gh_marker=s.gh_marker, frames=int(sim.time_s.size), description=sim.description,
                input_error_rms_mm=tuple(np.sqrt(np.mean(((raw_thorax - true_pos) * 1000.0) ** 2, axis=0)).tolist()),
                sta_peak_mm=float(np.max(np.linalg.norm(sim.sta_m[:, gh], axis=1)) * 1000.0),
                pf=per["pf"], ls=per["ls"], time_s=sim.time_s[::stride], gh_rotation_deg=rotation, marker_mm=marker)


def sier_realisations(trial: Trial, s: ValidationSettings, progress: Progress) -> SierRealisations:
    """PF and LS on SIER trials with noise/STA seeds 0 .. n-1 (at ``sier_realisation_rate_hz``):
    the spread of the Fig. 4 figures over artefact realisations of the same magnitude."""
    model, protocol = trial.model, trial.protocol
    kin = Kinematics(model)
    pts = kin.point_set([("humerus", s.gh_marker)])
    ir = model.coordinate_names.index("gh_internal_rotation")
    rows = []
    t0 = time.perf_counter()
    for seed in range(s.sier_realisations):
        progress(f"SIER realisation seed {seed} ({seed + 1}/{s.sier_realisations})")
        sim, tg = simulated(model, protocol, Motion.SIER, s.sier_duration_s, s.sier_realisation_rate_hz, s, seed)
        true_pos = kin.points(sim.q_true, pts)[:, 0]
        per: dict[str, SierRunMethod | Failed] = {}
        for method in METHODS:
            try:
                rec = reconstruct(model, protocol, tg, method=method)
            except ReconstructionError as exc:
                per[method] = Failed(failed=str(exc))
                continue
            j = rec.marker_names.index(s.gh_marker)
            joint = np.sqrt(np.mean(np.degrees(rec.q_rad - sim.q_true) ** 2, axis=0))
            per[method] = SierRunMethod(
                gh_axial_rotation_rmse_deg=float(np.sqrt(np.mean(np.degrees(rec.q_rad[:, ir] - sim.q_true[:, ir]) ** 2))),
                gh_marker_rmse_xyz_mm=tuple(np.sqrt(np.mean(((rec.model_points_m[:, j] - true_pos) * 1000.0) ** 2,
                                                            axis=0)).tolist()),
                max_joint_rmse_deg=float(joint.max()),
                max_joint=model.coordinate_names[int(np.argmax(joint))])
        rows.append(SierRun(seed=seed, frames=tg.n_frames, pf=per["pf"], ls=per["ls"]))

    def stat(values: list[float]) -> MedianMax | None:
        return MedianMax(median=float(np.median(values)), max=float(np.max(values))) if values else None

    summary = {}
    for method in METHODS:
        done = [m for m in (r.method(method) for r in rows) if isinstance(m, SierRunMethod)]
        summary[method] = SierSummary(
            gh_axial_rotation_rmse_deg=stat([m.gh_axial_rotation_rmse_deg for m in done]),
            gh_marker_x_rmse_mm=stat([m.gh_marker_rmse_xyz_mm[0] for m in done]),
            gh_marker_z_rmse_mm=stat([m.gh_marker_rmse_xyz_mm[2] for m in done]))
    return SierRealisations(rate_hz=s.sier_realisation_rate_hz, duration_s=s.sier_duration_s, noise_mm=s.noise_mm,
                            sta_mm=s.sta_mm, runs=tuple(rows), summary=summary, wall_s=time.perf_counter() - t0)
