"""Fig. 3 and Table 1: each trial's marker residuals |model point - marker| under PF and LS (per
frame mean and SD over markers, maxima, per-marker RMSE) and the wall times."""
from __future__ import annotations

import math

import numpy as np

from exubio.trust.evaluate import per_frame_residuals_mm, residual_statistics
from exubio.validation.results import METHODS, Failed, ResidualRow, ResidualStats
from exubio.validation.trials import Trial, plot_stride

__all__ = ["residual_table"]


def residual_table(trials: dict[str, Trial]) -> dict[str, ResidualRow]:
    """Table 1 rows by trial name, with the decimated per-frame residual curves of Fig. 3."""
    table = {}
    for name, tr in trials.items():
        stride = plot_stride(tr.targets.n_frames)
        per: dict[str, ResidualStats | Failed] = {}
        for method in METHODS:
            rec = tr.recon.get(method)
            if rec is None:
                per[method] = tr.failure(method)
                continue
            mean, sd = per_frame_residuals_mm(rec)
            st = residual_statistics(rec)
            per[method] = ResidualStats(
                ms_per_frame=tr.wall_s[method] / tr.targets.n_frames * 1000.0,
                max_mean_residual_mm=st["max_frame_mean"], sd_at_max_mean_mm=st["max_frame_mean_sd"],
                time_of_max_mean_s=st["max_frame_mean_time_s"],
                max_residual_mm=st["max"], max_residual_marker=st["max_marker"],
                max_rmse_mm=st["max_marker_rmse"], max_rmse_marker=st["max_marker_rmse_marker"],
                mean_residual_mm=st["mean"],
                per_marker_rmse_mm={k: math.nan if v is None else v for k, v in st["per_marker_rmse"].items()},
                max_abs_g=float(np.nanmax(np.abs(rec.constraint))),
                mean_mm=mean[::stride], sd_mm=sd[::stride])
        table[name] = ResidualRow(
            frames=tr.targets.n_frames, duration_s=float(tr.targets.time_s[-1] - tr.targets.time_s[0]),
            data=tr.data.kind, markers=len(tr.protocol.markers),
            pf_wall_s=tr.wall_s.get("pf", float("nan")), pf=per["pf"],
            ls_wall_s=tr.wall_s.get("ls", float("nan")), ls=per["ls"],
            time_s=tr.targets.time_s[::stride])
    return table
