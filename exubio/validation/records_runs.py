"""The validation study's records of its runs: failures, the trials and their calibration, the
sensitivity study, residual statistics (Table 1), the simulated internal-external rotation.
Part of exubio.validation.results (the file format); imports no solver."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.io.records import (
    Record,
    array,
    optional,
)


# --------------------------------------------------------------------------------------------
# Shared small records
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class Failed(Record):
    """A reconstruction that raised ReconstructionError: its message."""

    failed: str


@dataclass(frozen=True, eq=False, kw_only=True)
class Skipped(Record):
    """A part of the study that was not run, and why."""

    skipped: str


@dataclass(frozen=True, eq=False, kw_only=True)
class MedianMax(Record):
    """Median and maximum of a figure over runs."""

    median: float
    max: float


@dataclass(frozen=True, eq=False, kw_only=True)
class RmsMax(Record):
    """RMS and maximum over frames (deg)."""

    rms: float
    max: float


# --------------------------------------------------------------------------------------------
# Data provenance
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class CalibrationFrames(Record):
    """The frames whose mean is the static pose of a subject calibration (range start:stop:step)."""

    start: int
    stop: int
    step: int
    n_frames: int
    chosen_automatically: bool
    rate_hz: float


@dataclass(frozen=True, eq=False, kw_only=True)
class MeanMax(Record):
    """Mean and maximum (mm)."""

    mean: float
    max: float


@dataclass(frozen=True, eq=False, kw_only=True)
class CalibrationResidual(Record):
    """Calibration residual |model point - marker| (mm): mean, maximum and the marker of the maximum."""

    mean: float
    max: float
    max_marker: str


@dataclass(frozen=True, eq=False, kw_only=True)
class EllipsoidFit(Record):
    """The calibrated thorax ellipsoid: centre and radii (mm), fitted radii scale, max |g| at the static pose."""

    centre_mm: tuple[float, float, float]
    radii_mm: tuple[float, float, float]
    radii_scale_fitted: float
    max_abs_g_at_static_pose: float


@dataclass(frozen=True, eq=False, kw_only=True)
class CalibrationSummary(Record):
    """The subject calibration of a real trial (exubio.calibration), in brief."""

    frames: CalibrationFrames
    scale_factors: dict[str, float]
    residual_mm: CalibrationResidual
    generic_offset_mm: MeanMax
    ellipsoid: EllipsoidFit


@dataclass(frozen=True, eq=False, kw_only=True)
class TrialData(Record):
    """Where a trial of the study comes from: ``kind`` "real" (a recorded trial: ``source``,
    ``citation``, ``rate_hz``, ``calibration``, ``markers``) or "simulated" (``description``, and
    ``reason_not_real`` when a real trial was wanted)."""

    kind: str
    source: str | None = optional()
    citation: str | None = optional()
    reason_not_real: str | None = optional()
    description: str | None = optional()
    frames: int
    rate_hz: float | None = optional()
    protocol: str
    model: str
    calibration: CalibrationSummary | None = optional()
    markers: tuple[str, ...] | None = optional()

    @property
    def is_real(self) -> bool:
        return self.kind == "real"


# --------------------------------------------------------------------------------------------
# Fig. 2: sensitivity
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class FailedRun(Record):
    """A sensitivity run whose PF run stopped (``error``): in ``Sensitivity.failed_runs`` one that
    raised ReconstructionError; in ``Sensitivity.fallback_runs`` one whose first run stopped and
    that PF's fallback (``robust_options``: less inertia, full Newton; exubio.methods.pf) finished,
    with its mean spring deflection (mm)."""

    stiffness_n_per_m: float
    ratio_s: float
    error: str
    robust_options: str | None = optional()
    robust_deflection_mm: float | None = optional()


@dataclass(frozen=True, eq=False, kw_only=True)
class Sensitivity(Record):
    """Fig. 2: PF on ``trial`` for every spring constant c (N/m) x damper-spring ratio k = d/c (s);
    ``mean_deflection_mm[a, b]``: mean spring deflection over markers and frames for ratio a and
    stiffness b (NaN: the run failed); ``wall_s`` the same grid of run times."""

    trial: str
    frames: int
    runs: int
    failed_runs: tuple[FailedRun, ...]
    fallback_runs: tuple[FailedRun, ...] = ()
    total_wall_s: float
    wall_s_per_run_max: float
    stiffness_n_per_m: np.ndarray = array(json=True)
    ratio_s: np.ndarray = array(json=True)
    mean_deflection_mm: np.ndarray = array(json=True)
    wall_s: np.ndarray = array()


# --------------------------------------------------------------------------------------------
# Fig. 3 and Table 1: residuals
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class ResidualStats(Record):
    """One method's marker residuals |model point - marker| on a trial (mm) and its run time;
    ``mean_mm`` / ``sd_mm``: per-frame mean and SD over markers (decimated, on the row's ``time_s``)."""

    ms_per_frame: float
    max_mean_residual_mm: float
    sd_at_max_mean_mm: float
    time_of_max_mean_s: float
    max_residual_mm: float
    max_residual_marker: str
    max_rmse_mm: float
    max_rmse_marker: str
    mean_residual_mm: float
    per_marker_rmse_mm: dict[str, float]
    max_abs_g: float
    mean_mm: np.ndarray = array()
    sd_mm: np.ndarray = array()


@dataclass(frozen=True, eq=False, kw_only=True)
class ResidualRow(Record):
    """Table 1 for one trial: its size, the data kind, wall times (s) and residuals of PF and LS."""

    frames: int
    duration_s: float
    data: str
    markers: int
    pf_wall_s: float
    pf: ResidualStats | Failed
    ls_wall_s: float
    ls: ResidualStats | Failed
    time_s: np.ndarray = array()

    def stats(self, method: str) -> ResidualStats | Failed:
        """``pf`` or ``ls``."""
        return {"pf": self.pf, "ls": self.ls}[method]

    def wall_time_s(self, method: str) -> float:
        return {"pf": self.pf_wall_s, "ls": self.ls_wall_s}[method]


# --------------------------------------------------------------------------------------------
# Fig. 4: SIER against the truth
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class SierMethod(Record):
    """One method on the SIER trial against the truth: RMSE of GH axial rotation (model
    coordinate and ISB Y''), of the GH marker per thorax axis (mm), of every coordinate."""

    gh_axial_rotation_rmse_deg: float
    gh_isb_axial_rotation_rmse_deg: float
    gh_marker_rmse_xyz_mm: tuple[float, float, float]
    joint_rmse_deg: dict[str, float]


@dataclass(frozen=True, eq=False, kw_only=True)
class Sier(Record):
    """Fig. 4: simulated internal-external rotation with noise and STA. Series (decimated, on
    ``time_s``) by source ("true", "input", "pf", "ls"): GH axial rotation (deg; no "input") and the
    GH marker's displacement in the thorax frame from its true first position (mm, (n, 3))."""

    gh_marker: str
    frames: int
    description: str
    input_error_rms_mm: tuple[float, float, float]
    sta_peak_mm: float
    pf: SierMethod | Failed
    ls: SierMethod | Failed
    time_s: np.ndarray = array()
    gh_rotation_deg: dict[str, np.ndarray] = array(npz="gh_rotation_{}_deg")
    marker_mm: dict[str, np.ndarray] = array(npz="marker_{}_mm")

    def method(self, method: str) -> SierMethod | Failed:
        return {"pf": self.pf, "ls": self.ls}[method]


@dataclass(frozen=True, eq=False, kw_only=True)
class SierRunMethod(Record):
    """One method on one SIER realisation: GH axial rotation and GH marker RMSE, the worst coordinate."""

    gh_axial_rotation_rmse_deg: float
    gh_marker_rmse_xyz_mm: tuple[float, float, float]
    max_joint_rmse_deg: float
    max_joint: str


@dataclass(frozen=True, eq=False, kw_only=True)
class SierRun(Record):
    """One SIER realisation (noise/STA ``seed``)."""

    seed: int
    frames: int
    pf: SierRunMethod | Failed
    ls: SierRunMethod | Failed

    def method(self, method: str) -> SierRunMethod | Failed:
        return {"pf": self.pf, "ls": self.ls}[method]


@dataclass(frozen=True, eq=False, kw_only=True)
class SierSummary(Record):
    """Median and worst over the realisations a method completed (None: none did)."""

    gh_axial_rotation_rmse_deg: MedianMax | None
    gh_marker_x_rmse_mm: MedianMax | None
    gh_marker_z_rmse_mm: MedianMax | None


@dataclass(frozen=True, eq=False, kw_only=True)
class SierRealisations(Record):
    """Fig. 4 (spread): SIER repeated with noise/STA seeds 0, 1, ... at ``rate_hz``."""

    rate_hz: float
    duration_s: float
    noise_mm: float
    sta_mm: float
    runs: tuple[SierRun, ...]
    summary: dict[str, SierSummary]
    wall_s: float
