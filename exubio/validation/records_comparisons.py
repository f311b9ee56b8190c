"""The validation study's records of its comparisons: in vivo (Fig. 5), the C3D tasks, the PF-LS
agreement, the rates against the truth, the scapula over motion. Part of
exubio.validation.results (the file format); imports no solver."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.validation.records_runs import RmsMax, Skipped
from exubio.io.records import (
    Record,
    array,
    flat,
    npz_name,
    optional,
)


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
    Ludewig in his frames per ST key at HT 30/60/90/120 (deg) and the share inside the corridor;
    the clavicle the data imply: the registered scapula's AC from the model's SC, min and max over
    the trial (mm), against the model's rigid SC-AC length."""

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
    data_ac_from_model_sc_mm: tuple[float, float] | None = optional()  # min, max over the trial (scapula.data_clavicle_mm)
    model_clavicle_mm: float | None = optional()


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
# Bone truth (exubio.validation.bone)

BONE_PUBLISHED = {"GH": (3.0, 10.0), "ST": (3.0, 6.0)}
"""Skin markers against bone, RMSE ranges in deg (Begon et al. 2018): GH; the scapula's best
methods below 120 deg of elevation."""

BONE_SHOWN = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
         "GH_phadke_Z_flexion", "GH_phadke_Y_internal_rotation", "GH_X_elevation", "HT_X_elevation")



@dataclass(frozen=True, eq=False, kw_only=True)
class BoneAngle(Record):
    """One angle of one method against bone (deg; coverage: fraction within +-2u; NaN: not measured)."""

    rmse_deg: float
    max_deg: float
    coverage: float
    measured_fraction: float


@dataclass(frozen=True, eq=False, kw_only=True)
class BoneTask(Record):
    """One bone-referenced trial: file, task, frames, each method's verdict and its angles."""

    file: str
    task: str
    n_frames: int
    verdicts: dict[str, str]
    angles: dict[str, dict[str, BoneAngle]]


@dataclass(frozen=True, eq=False, kw_only=True)
class BoneTruth(Record):
    """The chapter: the assumption every run makes, and each trial."""

    assumption: str
    tasks: dict[str, BoneTask]
