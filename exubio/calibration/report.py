"""What a calibration fitted and how well: typed results, their plain-data form and a text table."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np


@dataclass(frozen=True)
class MarkerCalibration:
    """One protocol marker's calibration.

    point: the model point (on ``segment``) that now holds the marker's registered position.
    local_position_m: (3,) that position in the calibrated segment frame (m).
    registered: False when the marker had no sample in the calibration frames (optional marker):
        it keeps its scaled generic position and has no residual.
    residual_mm: RMS over the calibration frames of |model point - marker| on the calibrated
        model, each frame solved with the constrained LS (NaN when not registered).
    generic_offset_mm: |registered - scaled generic position| (the scaled generic model's static
        residual). fit_weight: the marker's robust weight in the anatomical fit (0..1].
    """

    name: str
    segment: str
    point: str
    local_position_m: np.ndarray
    registered: bool
    residual_mm: float
    generic_offset_mm: float
    fit_weight: float


@dataclass(frozen=True)
class CalibrationReport:
    """What a calibration fitted and how well (see the module docstring).

    frames: (start, stop, step) of the frames whose mean is the static pose.
    scale_factors: segment -> isotropic scale factor (segments of a group share it).
    static_q_rad: (m,) the static pose. ellipsoid_scale: the fitted common radii factor (after
    the thorax scale). constraint_abs: max |g| at the static pose (the ellipsoid fit's residual).
    """

    source: str
    frames: tuple[int, int, int]
    frames_chosen_automatically: bool
    rate_hz: float
    body_mass_kg: float
    generic_model: str
    protocol: str
    scale_factors: Mapping[str, float]
    thorax_scale_measured: bool
    static_q_rad: np.ndarray
    coordinate_names: tuple[str, ...]
    ellipsoid_centre_m: np.ndarray
    ellipsoid_radii_m: np.ndarray
    ellipsoid_scale: float
    constraint_abs: float
    markers: tuple[MarkerCalibration, ...]
    fit_iterations: int
    window_motion_mm: Mapping[str, float] = dataclasses.field(default_factory=dict)  # RMS motion of
    # each marker about its mean over the calibration frames: a "static" window that moves
    static_pose_at_limit_deg: Mapping[str, float] = dataclasses.field(default_factory=dict)  # coordinate ->
    # its static value (deg) where that lies at (within AT_LIMIT_TOLERANCE_RAD of) or beyond its range
    functional: Mapping[str, Any] = dataclasses.field(default_factory=dict)  # {"gh": SCoRE summary, or why unused}
    ellipsoid_poses_mm: Mapping[str, float] = dataclasses.field(default_factory=dict)  # static pose -> largest
    # distance of its contact points from the fitted ellipsoid (0 with one static: it passes through them)
    joint_centres_mm: Mapping[str, list] = dataclasses.field(default_factory=dict)  # joint -> thorax frame, static
    landmark_offsets_mm: Mapping[str, float] = dataclasses.field(default_factory=dict)  # landmark marker ->
    # its distance from the landmark it is placed over, on the calibrated model
    fit_stop: Mapping[str, str] = dataclasses.field(default_factory=dict)  # how the fits stopped
    # (exubio.types.StopReason labels): "start_pose" (the best start posture's pose-only fit),
    # "pose_and_scales" (the final joint fit), "reweighting" ("converged": the robust weights
    # settled; "max_iterations": not within MAX_REWEIGHTING), "pose of <trial>" per further static

    @property
    def residual_mm(self) -> dict[str, float]:
        """Calibration residual per registered marker (mm)."""
        return {m.name: m.residual_mm for m in self.markers if m.registered}

    @property
    def mean_residual_mm(self) -> float:
        vals = list(self.residual_mm.values())
        return float(np.mean(vals)) if vals else float("nan")

    @property
    def generic_offset_mm(self) -> dict[str, float]:
        return {m.name: m.generic_offset_mm for m in self.markers if m.registered}

    def to_dict(self) -> dict[str, Any]:
        """Plain data (mm, deg) for the model file's ``calibration`` section and JSON. Kept by hand
        with ``from_dict`` (exubio.io.records' exception, which writes and reads the report through
        them): the file groups the fields otherwise (frames, ellipsoid, markers by name), adds
        summaries computed from them (the residuals' mean and max, the frame count) and fixed
        definitions."""
        reg = [m for m in self.markers if m.registered]
        res = np.array([m.residual_mm for m in reg])
        off = np.array([m.generic_offset_mm for m in reg])
        worst = reg[int(np.argmax(res))].name if reg else None
        return {
            "method": "exubio.calibration: anatomical fit (pose + segment scales, robust) -> registration -> ellipsoid",
            "source": self.source,
            "frames": {"start": self.frames[0], "stop": self.frames[1], "step": self.frames[2],
                       "n_frames": len(range(*self.frames)), "chosen_automatically": self.frames_chosen_automatically,
                       "rate_hz": self.rate_hz},
            "body_mass_kg": self.body_mass_kg,
            "generic_model": self.generic_model,
            "protocol": self.protocol,
            "scale_factors": {k: round(float(v), 6) for k, v in self.scale_factors.items()},
            "thorax_scale_measured": self.thorax_scale_measured,
            "static_pose_deg": {n: round(float(np.degrees(v)), 4)
                                for n, v in zip(self.coordinate_names, self.static_q_rad)},
            "ellipsoid": {"centre_mm": [round(float(v) * 1000, 4) for v in self.ellipsoid_centre_m],
                          "radii_mm": [round(float(v) * 1000, 4) for v in self.ellipsoid_radii_m],
                          "radii_scale_fitted": round(float(self.ellipsoid_scale), 6),
                          "max_abs_g_at_static_pose": float(self.constraint_abs)},
            "residual_mm": {
                "definition": "RMS over the calibration frames of |model point - marker|, calibrated model, "
                              "constrained LS per frame",
                "mean": float(res.mean()) if reg else None,
                "max": float(res.max()) if reg else None,
                "max_marker": worst,
            },
            "generic_offset_mm": {
                "definition": "|registered - scaled generic model point| at the static pose "
                              "(the scaled generic model's static residual)",
                "mean": float(off.mean()) if reg else None,
                "max": float(off.max()) if reg else None,
            },
            "markers": {
                m.name: {
                    "segment": m.segment,
                    "point": m.point,
                    "registered": m.registered,
                    "residual_mm": None if not m.registered else round(float(m.residual_mm), 3),
                    "generic_offset_mm": None if not m.registered else round(float(m.generic_offset_mm), 3),
                    "fit_weight": round(float(m.fit_weight), 4),
                    "local_position_mm": [round(float(v) * 1000, 4) for v in m.local_position_m],
                }
                for m in self.markers
            },
            "fit_iterations": self.fit_iterations,
            "window_motion_mm": {k: round(float(v), 3) for k, v in self.window_motion_mm.items()},
            "static_pose_at_limit_deg": {k: round(float(v), 3) for k, v in self.static_pose_at_limit_deg.items()},
            "functional": dict(self.functional),
            "ellipsoid_poses_mm": {k: float(v) for k, v in self.ellipsoid_poses_mm.items()},
            "joint_centres_mm": {"definition": "joint centres in the thorax frame at the static pose",
                                 **{k: list(v) for k, v in self.joint_centres_mm.items()}},
            "landmark_offsets_mm": {k: round(float(v), 2) for k, v in self.landmark_offsets_mm.items()},
            "fit_stop": dict(self.fit_stop),
        }


    @staticmethod
    def from_dict(d: Mapping[str, Any], /) -> "CalibrationReport":
        """The report as a model file's ``calibration`` section records it (to_dict): what a
        session folder's calibration, reused, reports (its values as written: mm to the µm)."""
        names = tuple(d["static_pose_deg"])
        markers = tuple(MarkerCalibration(
            name, m["segment"], m["point"], np.asarray(m["local_position_mm"], float) / 1000.0, bool(m["registered"]),
            float("nan") if m["residual_mm"] is None else float(m["residual_mm"]),
            float("nan") if m["generic_offset_mm"] is None else float(m["generic_offset_mm"]), float(m["fit_weight"]))
            for name, m in d["markers"].items())
        fr, el = d["frames"], d["ellipsoid"]
        return CalibrationReport(
            source=d["source"], frames=(fr["start"], fr["stop"], fr["step"]),
            frames_chosen_automatically=bool(fr["chosen_automatically"]), rate_hz=float(fr["rate_hz"]),
            body_mass_kg=float(d["body_mass_kg"]), generic_model=d["generic_model"], protocol=d["protocol"],
            scale_factors=dict(d["scale_factors"]), thorax_scale_measured=bool(d["thorax_scale_measured"]),
            static_q_rad=np.radians([float(v) for v in d["static_pose_deg"].values()]), coordinate_names=names,
            ellipsoid_centre_m=np.asarray(el["centre_mm"], float) / 1000.0,
            ellipsoid_radii_m=np.asarray(el["radii_mm"], float) / 1000.0,
            ellipsoid_scale=float(el["radii_scale_fitted"]), constraint_abs=float(el["max_abs_g_at_static_pose"]),
            markers=markers, fit_iterations=int(d["fit_iterations"]),
            window_motion_mm=dict(d.get("window_motion_mm") or {}),
            static_pose_at_limit_deg=dict(d.get("static_pose_at_limit_deg") or {}),
            functional=dict(d.get("functional") or {}),
            ellipsoid_poses_mm=dict(d.get("ellipsoid_poses_mm") or {}),
            joint_centres_mm={k: v for k, v in (d.get("joint_centres_mm") or {}).items() if k != "definition"},
            landmark_offsets_mm=dict(d.get("landmark_offsets_mm") or {}), fit_stop=dict(d.get("fit_stop") or {}))


SKIN_FIT_CAVEAT = (
    "  the ellipsoid now follows the skin's poses of the scapula: on bone pins such a fit took ST upward rotation "
    "1-10 deg farther from the bone than the static calibration alone (ST internal rotation closer), and each ST "
    "and GH angle's uncertainty of the trials reconstructed with this model carries the scapula cluster's whole "
    "sliding (studies/README.md, 'A scapula trial against bone')")


def format_report(report: CalibrationReport, /) -> str:
    """A short text table of the calibration for the terminal."""
    lines = [f"calibration of {report.source or 'trial'}, frames {report.frames[0]}:{report.frames[1]}"
             + (" (still stretch found automatically)" if report.frames_chosen_automatically else "")]
    lines.append("scale factors: " + ", ".join(f"{k} {v:.3f}" for k, v in report.scale_factors.items()))
    lines.append(f"ellipsoid: centre {np.round(report.ellipsoid_centre_m * 1000, 1).tolist()} mm, radii "
                 f"{np.round(report.ellipsoid_radii_m * 1000, 1).tolist()} mm, |g| at the static pose "
                 f"{report.constraint_abs:.1e}")
    lines.append(f"{'marker':<12} {'segment':<9} {'residual mm':>11} {'generic offset mm':>18} {'fit weight':>10}")
    for m in report.markers:
        if m.registered:
            lines.append(f"{m.name:<12} {m.segment:<9} {m.residual_mm:>11.2f} {m.generic_offset_mm:>18.1f} {m.fit_weight:>10.2f}")
        else:
            lines.append(f"{m.name:<12} {m.segment:<9} {'not in the calibration frames: scaled generic position':>41}")
    lines.append(f"calibration residual: mean {report.mean_residual_mm:.2f} mm (RMS over the calibration frames, "
                 f"calibrated model, constrained LS per frame)")
    unsettled = {k: v for k, v in report.fit_stop.items() if v not in ("converged", "stalled")}
    if unsettled:
        lines.append("fits that stopped before converging: " + ", ".join(f"{k} ({v})" for k, v in unsettled.items()))
    if report.joint_centres_mm:
        lines.append("joint centres at the static pose (thorax frame, mm): " + "; ".join(
            f"{k} {[round(v, 1) for v in p]}" for k, p in report.joint_centres_mm.items()))
    if report.landmark_offsets_mm:
        lines.append("landmark markers, distance from their landmark (mm): " + ", ".join(
            f"{k} {v:.0f}" for k, v in report.landmark_offsets_mm.items()))
    gh = (report.functional or {}).get("gh")
    if gh:
        if gh.get("used"):
            lines.append(f"glenohumeral centre: SCoRE on {gh['trial']} ({gh.get('n_frames_used')} frames, rotation range "
                         f"{gh.get('rotation_range_deg', float('nan')):.0f} deg, RMS {gh.get('rms_mm', float('nan')):.1f} mm), "
                         f"{gh['shift_from_marker_fit_mm']:.1f} mm from the marker fit's")
        else:
            lines.append(f"glenohumeral centre: the functional trial was not used: {gh['reason']}")
    sc = (report.functional or {}).get("scapula")
    if sc:
        if sc.get("used"):
            b, a = sc["contact_distance_before_mm"]["movement"]["all"], sc["contact_distance_after_mm"]["movement"]["all"]
            lines.append(f"thorax ellipsoid: through {sc['frames_used']} scapula postures of {sc['trial']} and the "
                         f"static pose: contact points {b['rms']:.1f} -> {a['rms']:.1f} mm RMS off it (max {b['max']:.0f} "
                         f"-> {a['max']:.0f} mm); centre moved {sc['centre_shift_mm']} mm, radii x {sc['radius_scale']}; "
                         f"{sc['determined_directions']} of 6 parameter directions determined by the postures "
                         f"(scapula rotation range {sc['scapula_rotation_range_deg']:.0f} deg)")
            lines.append(SKIN_FIT_CAVEAT)
        else:
            lines.append(f"thorax ellipsoid: the scapula trial was not used: {sc['reason']}")
    if len(report.ellipsoid_poses_mm) > 1:
        lines.append("ellipsoid fitted through the contact points of " + ", ".join(
            f"{k} (off by up to {v:.1f} mm)" for k, v in report.ellipsoid_poses_mm.items()))
        lines.append(SKIN_FIT_CAVEAT)
    pose = ", ".join(f"{n} {np.degrees(v):.0f}" for n, v in zip(report.coordinate_names, report.static_q_rad))
    lines.append(f"static pose (deg): {pose}")
    return "\n".join(lines)
