"""The validation study's results as typed records, and the files they are kept in.

``ValidationResults`` holds every section of the study (``exubio.validation.run``); the report
(``exubio.report.validation_report``) draws from it. Both go through this module, so the two
cannot disagree on a key: ``ValidationResults.save(folder)`` writes

* ``validation_runs.json``: the whole record (settings, data provenance, every number);
* ``table1.json``: the paper's Table 1 for exubio (``table1``) beside the paper's row;
* ``validation_data.npz``: the arrays the figures need (npz names ``<section>__<name>``, from
  the records' fields, see ``exubio.validation.codec``),

and ``ValidationResults.load(folder)`` reads them back into equal records. Imports no solver.

Units are those in the field names, as in the files: lengths in mm, angles in deg, times in s,
spring constants in N/m (the files keep their numbers bit for bit; converting to SI and back
would not). NaN stands for "not available" (null in the files). ``pf`` and ``ls`` are the
potential-field and least-squares reconstructions; trials are named "abduction", "flexion",
"sier"; joints "SC", "AC", "ST", "GH" (and "HT").
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from exubio.validation.codec import (
    Record,
    SchemaError,
    array,
    decode,
    encode_arrays,
    flat,
    nan_to_none,
    npz_name,
    optional,
    write_json,
)
from exubio.validation.settings import ValidationSettings

__all__ = [
    "DATA_NPZ", "METHODS", "RUNS_JSON", "TABLE1_JSON", "TRIALS",
    "Agreement", "AgreementTrial", "AngleComparison", "C3dTask", "C3dTasks", "CalibrationFrames",
    "CalibrationResidual", "CalibrationSummary", "Check", "CorridorEntry", "CorridorMember", "ElevationComparison",
    "EllipsoidFit", "Failed", "FailedRun", "InvivoComparison", "MasslessDiagnostic", "MasslessFailed", "MeanMax",
    "MedianMax", "MismatchRun", "ModelMismatch", "NotCompared", "PaperGhMarker", "PaperMethods", "PaperNumbers",
    "PaperSensitivity", "PaperTable1Row",
    "Rates", "RatesCondition", "ScapulaCrossValidation", "ScapulaDirection", "ScapulaSimulated", "ScapulaVariant",
    "ResidualRow", "ResidualStats", "RmsMax", "SchemaError", "Sensitivity", "Sier", "SierMethod", "SierRealisations",
    "SierRun", "SierRunMethod", "SierSummary", "Skipped", "TrialData", "ValidationResults",
]

RUNS_JSON = "validation_runs.json"
TABLE1_JSON = "table1.json"
DATA_NPZ = "validation_data.npz"
METHODS = ("pf", "ls")
TRIALS = ("abduction", "flexion", "sier")
"""The study's trials: the two elevations of Fig. 5 and the simulated internal-external rotation."""

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
    """A sensitivity run that raised ReconstructionError."""

    stiffness_n_per_m: float
    ratio_s: float
    error: str


@dataclass(frozen=True, eq=False, kw_only=True)
class Sensitivity(Record):
    """Fig. 2: PF on ``trial`` for every spring constant c (N/m) x damper-spring ratio k = d/c (s);
    ``mean_deflection_mm[a, b]``: mean spring deflection over markers and frames for ratio a and
    stiffness b (NaN: the run failed); ``wall_s`` the same grid of run times."""

    trial: str
    frames: int
    runs: int
    failed_runs: tuple[FailedRun, ...]
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


# --------------------------------------------------------------------------------------------
# Fig. 5: in vivo (exubio.literature.invivo.compare_elevation)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class AngleComparison(Record):
    """One angle of one source against Ludewig et al. 2009 in Ludewig's definitions, at the
    check elevations (``InvivoComparison.ht_check_deg``): value, Ludewig's value and the deviation
    (deg, NaN = elevation not reached), the change from 30 deg minus Ludewig's, slopes over HT
    30-120 (deg/deg), the share of HT 30-120 inside the corridor of ``corridor_studies`` studies
    (over ``corridor_span_deg``), the flags, and (ST, GH) the deviation with ISB frames."""

    value_deg: tuple[float, ...]
    ludewig_deg: tuple[float, ...]
    deviation_deg: tuple[float, ...]
    max_abs_deviation_deg: float
    trend_deviation_deg: tuple[float, ...]
    slope_deg_per_deg: float
    ludewig_slope_deg_per_deg: float
    share_inside_corridor: float
    corridor_span_deg: float
    corridor_studies: int
    undetermined: bool
    inferred: bool
    isb_frame_deviation_deg: tuple[float, ...] | None = optional()


@dataclass(frozen=True, eq=False, kw_only=True)
class ElevationComparison(Record):
    """One source ("pf", "ls", "truth") of an arm raising: its HT elevation range and raising
    frames, each angle (by Ludewig's key, e.g. "ST_medRotation_X") against Ludewig; the
    decimated curves: HT elevation (deg), the raising mask, each joint's three angles (deg, (n, 3))."""

    ht_range_deg: tuple[float, float]
    raising_frames: int
    raising_ht_range_deg: tuple[float, float] | None
    angles: dict[str, AngleComparison] = flat()
    ht_deg: np.ndarray | None = array(optional=True)
    raising: np.ndarray | None = array(optional=True)
    joint_deg: dict[str, np.ndarray] = array(npz="{}_deg")


@dataclass(frozen=True, eq=False, kw_only=True)
class CorridorMember(Record):
    """A study in a corridor, with its mean curve in Ludewig's definitions (HT deg, (k, 3) deg)."""

    study: str
    citation: str
    converted: bool
    ht_deg: np.ndarray | None = array(optional=True)
    deg: np.ndarray | None = array(optional=True)


@dataclass(frozen=True, eq=False, kw_only=True)
class CorridorEntry(Record):
    """A joint's corridor: the member studies, those left out and why; its envelope (lo, hi (k, 3)
    deg, n studies) on ``InvivoComparison.corridor_ht_deg``."""

    members: tuple[CorridorMember, ...] = npz_name("member{}")
    excluded: dict[str, str]
    lo: np.ndarray | None = array(optional=True)
    hi: np.ndarray | None = array(optional=True)
    n: np.ndarray | None = array(optional=True)


@dataclass(frozen=True, eq=False, kw_only=True)
class InvivoComparison(Record):
    """A trial's arm raising compared in a plane of elevation (exubio.literature.invivo.compare_elevation),
    per source, with the corridor of comparable studies per joint (``corridor``) on the HT grid
    ``corridor_ht_deg``; ``undetermined_isb_angles``: the ISB angles the markers do not determine."""

    plane: str
    ht_check_deg: tuple[float, ...]
    definitions: dict[str, str] | None = optional()
    undetermined_angles: tuple[str, ...]
    inferred_joints: dict[str, str]
    corridor: dict[str, CorridorEntry] = npz_name("corridor__{}")
    pf: ElevationComparison | None = optional()
    ls: ElevationComparison | None = optional()
    truth: ElevationComparison | None = optional()
    undetermined_isb_angles: tuple[str, ...] | None = optional()
    corridor_ht_deg: np.ndarray | None = array(npz="corridor__ht_deg", optional=True)

    def source(self, name: str) -> ElevationComparison | None:
        """``pf``, ``ls`` or ``truth`` (None when absent)."""
        return {"pf": self.pf, "ls": self.ls, "truth": self.truth}[name]


@dataclass(frozen=True, eq=False, kw_only=True)
class C3dTask(Record):
    """A 21-marker C3D task trial: calibrated on ``static``; compared in the planes of elevation
    its raising phases match (``matched``), the others with the reason (``not_matched``)."""

    static: str
    protocol: str
    frames: int
    errors: dict[str, str]
    matched: dict[str, InvivoComparison]
    not_matched: dict[str, str]


@dataclass(frozen=True, eq=False, kw_only=True)
class C3dTasks(Record):
    """Fig. 5 (C3D tasks): the criterion (plane tolerance, minimum HT span, deg) and each trial."""

    plane_tolerance_deg: float
    min_span_deg: float
    trials: dict[str, C3dTask | Skipped]


# --------------------------------------------------------------------------------------------
# Fig. 6: PF vs LS agreement
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class MasslessDiagnostic(Record):
    """PF again with the marker-less segments almost massless, against LS."""

    segments: tuple[str, ...]
    coordinate_rmse_deg: dict[str, float]
    max_coordinate_rmse_deg: float
    max_coordinate: str
    max_marker_rmse_mm: float
    segment_orientation_difference_deg: dict[str, RmsMax]


@dataclass(frozen=True, eq=False, kw_only=True)
class MasslessFailed(Record):
    """The massless diagnostic run failed."""

    segments: tuple[str, ...]
    failed: str


@dataclass(frozen=True, eq=False, kw_only=True)
class AgreementTrial(Record):
    """PF against LS on one trial: RMSE per coordinate (deg) and model point (mm), the maxima
    over the coordinates the markers determine (``_all``: over every coordinate), per ISB angle,
    and the segments' orientation difference; arrays for Fig. 6 in coordinate / marker order."""

    coordinate_rmse_deg: dict[str, float]
    undetermined_coordinates: tuple[str, ...]
    undetermined_isb_angles: tuple[str, ...]
    max_coordinate_rmse_deg: float
    max_coordinate: str
    max_coordinate_rmse_deg_all: float
    marker_rmse_mm: dict[str, float]
    max_marker_rmse_mm: float
    max_marker: str
    isb_angle_rmse_deg: dict[str, tuple[float, float, float]]
    segment_orientation_difference_deg: dict[str, RmsMax]
    diagnostic_massless_unobserved: MasslessDiagnostic | MasslessFailed | None = optional()
    marker_rmse_causes_mm: dict[str, float] | None = optional()  # real trials: PF-LS max marker RMSE with
    # every segment's mass x 0.01 ("masses_x0.01"), and also the dampers x 0.1 (exubio.validation.agreement)
    coord_rmse_deg: np.ndarray = array()
    marker_rmse_series_mm: np.ndarray = array(npz="marker_rmse_mm")
    marker_names: np.ndarray = array()
    coordinate_names: np.ndarray = array()
    determined: np.ndarray = array()
    coord_rmse_massless_deg: np.ndarray | None = array(optional=True)


@dataclass(frozen=True, eq=False, kw_only=True)
class NotCompared(Record):
    """PF or LS failed on the trial: nothing compared."""

    failed: bool = True


@dataclass(frozen=True, eq=False, kw_only=True)
class Agreement(Record):
    """Fig. 6: PF against LS per trial, and the maxima over the trials."""

    trials: dict[str, AgreementTrial | NotCompared] = flat()
    max_coordinate_rmse_deg: float
    max_marker_rmse_mm: float


# --------------------------------------------------------------------------------------------
# Rates against the truth (exubio.validation.rates)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class RatesCondition(Record):
    """One simulated trial (noise/STA as given) under every source ("pf", "ls", their q's finite
    differences "pf_fd", "ls_fd", and noise-free "pf_no_lead_in"): RMSE against the truth per
    coordinate over the interior frames (q deg, q̇ deg/s, q̈ deg/s^2), the constraint residuals
    (max |g|, max |G q̇| 1/s, max |G q̈ + eta| 1/s^2), wall times (s), failures."""

    description: str
    noise_mm: float
    sta_mm: float
    frames: int
    rate_hz: float
    truth_rms_qd_deg_s: dict[str, float]
    truth_rms_qdd_deg_s2: dict[str, float]
    q_rmse_deg: dict[str, dict[str, float]]
    qd_rmse_deg_s: dict[str, dict[str, float]]
    qdd_rmse_deg_s2: dict[str, dict[str, float]]
    max_abs_g: dict[str, float]
    max_abs_g_qd_1_s: dict[str, float]
    max_abs_g_qdd_eta_1_s2: dict[str, float]
    wall_s: dict[str, float]
    errors: dict[str, str]


@dataclass(frozen=True, eq=False, kw_only=True)
class Rates(Record):
    """q̇ and q̈ of PF and LS against the simulated truth (``conditions``: "noise_free",
    "noise_sta"); PF's worst noise-free RMSE over the measured coordinates against the aims."""

    trial: str
    coordinates: tuple[str, ...]
    measured_coordinates: tuple[str, ...]
    conditions: dict[str, RatesCondition]
    pf_noise_free_max_qd_rmse_deg_s: float
    pf_noise_free_max_qdd_rmse_deg_s2: float
    aim_qd_deg_s: float
    aim_qdd_deg_s2: float


# --------------------------------------------------------------------------------------------
# The scapula calibrated over motion, cross-validated (exubio.validation.scapula)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class ScapulaVariant(Record):
    """One calibration of one direction: whether the motion fit was used ("used", "refused",
    "none") and its contact-point RMS off the ellipsoid before/after (mm); per method ("pf", "ls")
    the reconstructed trial's aa/ts/ai RMSE (mm), the model-minus-data ST angles (internal
    rotation, upward rotation, tilt; deg) RMSE and max over HT 30-120; PF's deviation from
    Ludewig in his frames per ST key at HT 30/60/90/120 (deg) and the share inside the corridor."""

    motion_fit: str
    reason: str | None = optional()
    contact_rms_before_mm: float | None = optional()
    contact_rms_after_mm: float | None = optional()
    determined_directions: int | None = optional()
    marker_rmse_mm: dict[str, dict[str, float]]
    st_model_minus_data_rmse_deg: dict[str, tuple[float, float, float]]
    st_model_minus_data_max_deg: dict[str, tuple[float, float, float]]
    ludewig_deviation_deg: dict[str, tuple[float, ...]]
    ludewig_share_inside_corridor: dict[str, float]


@dataclass(frozen=True, eq=False, kw_only=True)
class ScapulaDirection(Record):
    """Calibrated on ``calibration_trial``, reconstructing ``reconstructed_trial``: the variants
    "own_still", "cal_still", "cal_still_motion", "pooled_not_cross_validated"."""

    calibration_trial: str
    reconstructed_trial: str
    variants: dict[str, ScapulaVariant | Skipped]


@dataclass(frozen=True, eq=False, kw_only=True)
class ScapulaSimulated(Record):
    """The simulated subject whose ellipsoid differs: the second trial's ST max error per angle
    (deg) and its true contact points' largest distance from the calibrated ellipsoid (mm), for
    the calibration at rest ("static") and over motion ("static_motion")."""

    description: str
    st_max_error_deg: dict[str, tuple[float, float, float]]
    flexion_contacts_max_off_ellipsoid_mm: dict[str, float]


@dataclass(frozen=True, eq=False, kw_only=True)
class ScapulaCrossValidation(Record):
    """The functional scapula calibration: the simulated subject, and the real TRC subject per
    direction (e.g. "flexion_to_abduction"; empty when skipped, with the reason in ``real_skipped``)."""

    simulated: ScapulaSimulated
    real: dict[str, ScapulaDirection]
    real_skipped: str | None = optional()


# --------------------------------------------------------------------------------------------
# The paper's numbers, the checks
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class PaperTable1Row(Record):
    """The paper's Table 1 row for a trial (wall times in s, residuals in mm)."""

    frames: int
    duration_s: float
    pf_wall_s: float
    ls_wall_s: float
    max_mean_residual_mm: float
    sd_at_max_mean_mm: float
    max_residual_mm: float
    max_residual_marker: str
    max_rmse_mm: float
    max_rmse_marker: str


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperMethods(Record):
    """A figure of the paper for PF and LS."""

    pf: float
    ls: float


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperGhMarker(Record):
    """The paper's SIER GH marker RMSE (mm), X and Z, PF and LS."""

    pf_x: float
    ls_x: float
    pf_z: float
    ls_z: float


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperSensitivity(Record):
    """The paper's sensitivity study (Fig. 2) and its chosen spring-damper."""

    stiffness_n_per_m: tuple[float, float]
    ratio_s: tuple[float, float]
    runs: int
    chosen_stiffness_n_per_m: float
    chosen_damping_ns_per_m: float
    finding: str


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperNumbers(Record):
    """The paper's published figures of merit (exubio.report.paper.PAPER)."""

    citation: str
    table1: dict[str, PaperTable1Row]
    pf_ms_per_frame: float
    ls_ms_per_frame: float
    sier_gh_axial_rmse_deg: PaperMethods
    sier_gh_marker_rmse_mm: PaperGhMarker
    pf_ls_max_joint_rmse_deg: float
    pf_ls_max_marker_rmse_mm: float
    pf_ls_rmse_deg_by_motion: dict[str, float]
    sensitivity: PaperSensitivity
    hardware: str


@dataclass(frozen=True, eq=False, kw_only=True)
class Check(Record):
    """A figure against a limit: ``passed`` (None: not evaluable, see ``note``). ``kind``: None (value
    <= limit), "same_sign" (the value has the limit's sign), "aim" (<= limit, an aim of the
    like-for-like comparison) or "aim_min" (>= limit)."""

    what: str
    value: float
    limit: float
    unit: str
    kind: str | None = optional()
    passed: bool | None
    note: str | None = optional()


# --------------------------------------------------------------------------------------------
# Model mismatch (exubio.validation.mismatch)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class MismatchRun(Record):
    """One simulated trial with a perturbed model (``perturbation``: exubio.synth.perturb words),
    reconstructed by ``method`` with the generic model: the worst measured angle's RMSE and the
    largest error of any measured angle (deg); ``mismatch_cost_deg``: the worst RMSE of the same
    case and motion without artefact (what the mismatch alone costs); the verdict, its non-note
    reasons, the segments the model-mismatch check names and its evidence."""

    case: str
    perturbation: tuple[str, ...]
    motion: str
    artefact: str
    method: str
    mismatch_cost_deg: float
    worst_angle: str
    worst_rmse_deg: float
    worst_max_deg: float
    angle_rmse_deg: dict[str, float]
    mean_residual_mm: float
    verdict: str
    reasons: tuple[str, ...]
    mismatch_segments: tuple[str, ...]
    scapula_contact_offset_mean_mm: float
    bias_mm: dict[str, float]


@dataclass(frozen=True, eq=False, kw_only=True)
class ModelMismatch(Record):
    """The model-mismatch section: every run; ``costly`` runs whose mismatch costs more than
    ``cost_limit_deg``, ``caught`` of them with a check naming a segment, the ``missed`` ones;
    ``no_mismatch`` runs without perturbation, those the mismatch check named anyway
    (``false_alarms``) and those not ``ok`` for any reason; perturbed runs that cost less than the
    limit yet were flagged (``flagged_cheap``)."""

    cost_limit_deg: float
    duration_s: float
    rate_hz: float
    noise_mm: float
    sta_mm: float
    runs: tuple[MismatchRun, ...]
    costly: int
    caught: int
    missed: tuple[str, ...]
    no_mismatch: int
    false_alarms: tuple[str, ...]
    no_mismatch_not_ok: tuple[str, ...]
    flagged_cheap: tuple[str, ...]


# --------------------------------------------------------------------------------------------
# Everything
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class ValidationResults(Record):
    """The whole validation study: what ran where, every section's results, the paper's numbers
    and the checks against them; ``ludewig``: Ludewig et al. 2009's means per plane and column
    (npz only). ``report_wall_s`` is set once the report is built."""

    exubio_version: str
    python: str
    machine: str
    processor: str
    quick: bool
    settings: ValidationSettings
    data: dict[str, TrialData]
    reconstruction_errors: dict[str, dict[str, str]]
    sensitivity: Sensitivity = npz_name("sens")
    table1: dict[str, ResidualRow] = npz_name("res__{}")
    sier: Sier
    sier_realisations: SierRealisations
    invivo: dict[str, InvivoComparison] = npz_name("iv__{}")
    agreement: Agreement = npz_name("agr")
    c3d_tasks: C3dTasks | Skipped = npz_name("c3d")
    truth_rmse_deg: dict[str, dict[str, dict[str, float]]]
    paper: PaperNumbers
    checks: tuple[Check, ...]
    invivo_aims: tuple[Check, ...]
    total_wall_s: float
    report_wall_s: float | None = optional()
    rates: Rates | Skipped | None = optional()
    scapula: ScapulaCrossValidation | None = optional()
    ludewig: dict[str, dict[str, np.ndarray]] = array(npz="lud__{}")
    mismatch: ModelMismatch | None = optional()  # the model-mismatch section (absent in older files)

    # files ----------------------------------------------------------------------------------
    def table1_json(self) -> dict[str, Any]:
        """The content of table1.json: exubio's rows, the paper's, the units."""
        return {"rows": {k: v.to_json() for k, v in self.table1.items()},
                "paper": {k: v.to_json() for k, v in self.paper.table1.items()},
                "units": {"wall_s": "s", "residuals": "mm"}}

    def arrays(self) -> dict[str, np.ndarray]:
        """The content of validation_data.npz, by npz name."""
        return encode_arrays(self)

    def save(self, folder: str | Path, /) -> dict[str, Path]:
        """Write validation_data.npz, table1.json and validation_runs.json into ``folder`` (each
        through a temporary file); returns their paths."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = {"npz": folder / DATA_NPZ, "table1": folder / TABLE1_JSON, "runs": folder / RUNS_JSON}
        tmp = folder / "validation_data.tmp.npz"
        np.savez_compressed(tmp, **self.arrays())
        tmp.replace(paths["npz"])
        write_json(paths["table1"], self.table1_json())
        write_json(paths["runs"], self.to_json())
        return paths

    @classmethod
    def from_json(cls, runs: dict[str, Any], arrays: dict[str, np.ndarray] | None = None, /) -> ValidationResults:
        """The record from the parsed validation_runs.json and the npz arrays (SchemaError when
        they do not fit)."""
        return decode(cls, runs, arrays if arrays is not None else {})

    @classmethod
    def load(cls, folder: str | Path, /) -> ValidationResults:
        """Read the files ``save`` wrote; SchemaError if validation_runs.json, the npz or
        table1.json do not fit the records or each other."""
        folder = Path(folder)
        runs = json.loads((folder / RUNS_JSON).read_text(encoding="utf-8"))
        with np.load(folder / DATA_NPZ, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        out = cls.from_json(runs, arrays)
        table1 = folder / TABLE1_JSON
        if table1.is_file() and json.loads(table1.read_text(encoding="utf-8")) != nan_to_none(out.table1_json()):
            raise SchemaError(f"{table1} disagrees with {RUNS_JSON}")
        return out

    # questions the report asks ----------------------------------------------------------------
    def is_real(self, trial: str) -> bool:
        """Whether ``trial`` is a recorded (not simulated) trial."""
        return self.data[trial].is_real
