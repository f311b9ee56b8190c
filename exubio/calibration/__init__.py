"""Subject calibration: a generic model fitted to a subject from a static pose (and optionally a
functional movement trial). A pure step: arrays and a Model in, a Model and a CalibrationReport
out; no file is read or written here (``exubio.run.pipeline`` does that).

Modules, one job each: ``window`` (which frames hold the static pose), ``scaling`` (segment scale
factors), ``posefit`` (the static pose and the scales of the scaled generic model), ``cluster`` (the poses
of marker clusters),
``functional`` (SCoRE joint centres, SARA axes), ``ellipsoid`` (the thorax ellipsoid through the
scapula contact points), ``scapula_motion`` (the ellipsoid through the scapula postures of a
movement trial), ``registration`` (marker <-> model point), ``report`` (the typed result) and
``core`` (the calibration itself).
"""
from exubio.calibration.core import calibrate_model
from exubio.calibration.ellipsoid import fit_ellipsoid
from exubio.calibration.registration import calibrated_protocol, joint_centre_points, marker_point_names
from exubio.calibration.report import CalibrationReport, MarkerCalibration, format_report
from exubio.calibration.scaling import DEFAULT_SCALE_GROUPS, SCALE_BOUNDS, scale_model
from exubio.calibration.scapula_motion import ScapulaMotionFit, fit_scapula_motion
from exubio.calibration.window import find_still_frames, parse_frames

__all__ = [
    "CalibrationReport",
    "DEFAULT_SCALE_GROUPS",
    "MarkerCalibration",
    "SCALE_BOUNDS",
    "ScapulaMotionFit",
    "calibrate_model",
    "calibrated_protocol",
    "find_still_frames",
    "fit_scapula_motion",
    "fit_ellipsoid",
    "format_report",
    "joint_centre_points",
    "marker_point_names",
    "parse_frames",
    "scale_model",
]
