"""Figures of merit of a reconstruction: marker residual statistics (paper Eq. 8, Table 1),
constraint residuals, joint RMSE against a truth or another method. Pure numpy; no solver."""
from __future__ import annotations

import warnings
from typing import Any, Sequence

import numpy as np

from exubio.types import Model, Reconstruction


def residual_statistics(recon: Reconstruction, /) -> dict[str, Any]:
    """Marker residuals in mm: overall mean/SD/max with the worst marker, the per-frame mean over
    markers (E_j of Eq. 8) and its maximum with the SD at that frame, and per-marker RMSE."""
    res = recon.residuals_m * 1000.0
    names = list(recon.marker_names)
    if np.isnan(res).all():
        return {"mean": None, "sd": None, "max": None, "max_marker": None}
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an optional marker may be absent throughout
        per_frame_mean = np.nanmean(res, axis=1)  # res is NaN wherever it is not valid: no masked copy
        per_frame_sd = np.nanstd(res, axis=1)
        per_marker_max = np.nanmax(res, axis=0)
        mean, sd = float(np.nanmean(res)), float(np.nanstd(res))
        # res squared in place (its last use; res**2 was a second whole-trial copy beside nanmean's)
        per_marker_rmse = np.sqrt(np.nanmean(np.square(res, out=res), axis=0))
    j = int(np.nanargmax(per_frame_mean))
    worst = int(np.nanargmax(per_marker_max))
    worst_rmse = int(np.nanargmax(per_marker_rmse))
    return {
        "mean": mean,
        "sd": sd,
        "max": float(per_marker_max[worst]),
        "max_marker": names[worst],
        "max_frame_mean": float(per_frame_mean[j]),
        "max_frame_mean_sd": float(per_frame_sd[j]),
        "max_frame_mean_time_s": float(recon.time_s[j]),
        "max_marker_rmse": float(per_marker_rmse[worst_rmse]),
        "max_marker_rmse_marker": names[worst_rmse],
        "per_marker_rmse": {n: (None if np.isnan(v) else float(v)) for n, v in zip(names, per_marker_rmse)},
        "per_marker_max": {n: (None if np.isnan(v) else float(v)) for n, v in zip(names, per_marker_max)},
    }


def per_frame_residuals_mm(recon: Reconstruction, /) -> tuple[np.ndarray, np.ndarray]:
    """(mean, SD) over markers of the residual per frame, mm (Fig. 3)."""
    res = recon.residuals_m * 1000.0
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(res, axis=1), np.nanstd(res, axis=1)


def rmse_deg(q_a: np.ndarray, q_b: np.ndarray, names: Sequence[str], /) -> dict[str, float]:
    """RMSE in degrees per coordinate between two (n, m) joint-angle series in radians."""
    d = np.rad2deg(np.asarray(q_a) - np.asarray(q_b))
    return {n: float(v) for n, v in zip(names, np.sqrt(np.nanmean(d**2, axis=0)))}


def measured_angle_rmse_deg(model: Model, q_rad: np.ndarray, q_true_rad: np.ndarray, status: np.ndarray, /
                            ) -> dict[str, float]:
    """RMSE (deg) against a truth of each anatomical angle (exubio.model.angles.anatomical_table)
    that is measured in every frame (``status``: (n, a) AngleStatus codes); differences wrapped
    to +-180 deg. The angles modelled or not measured are left out: they are no measurement."""
    from exubio.model.angles import anatomical_table
    from exubio.trust.observability import AngleStatus

    names, rec = anatomical_table(model, q_rad)
    _, true = anatomical_table(model, q_true_rad)
    err = np.degrees(np.abs(np.angle(np.exp(1j * (rec - true)))))
    measured = np.asarray(status) == AngleStatus.MEASURED
    return {n: float(np.sqrt(np.mean(err[measured[:, j], j] ** 2))) for j, n in enumerate(names) if measured[:, j].all()}


def marker_rmse_mm(a: np.ndarray, b: np.ndarray, names: Sequence[str], /) -> dict[str, float]:
    """RMSE (mm) of the 3-D distance between two marker/model-point trajectory sets (n, k, 3)."""
    d = np.linalg.norm(np.asarray(a) - np.asarray(b), axis=2) * 1000.0
    return {n: float(v) for n, v in zip(names, np.sqrt(np.nanmean(d**2, axis=0)))}
