"""The study's verdicts: checks of exubio's figures against the paper's (``paper_checks``) and
the aims of the like-for-like comparison with Ludewig et al. 2009 (``invivo_aims``). Computed from
the typed results alone (no solver)."""
from __future__ import annotations

import dataclasses

import numpy as np

from exubio.validation.results import (
    METHODS,
    Agreement,
    Check,
    InvivoComparison,
    PaperNumbers,
    Sensitivity,
    Sier,
    SierMethod,
    SierRealisations,
)

__all__ = ["AIM_SHARE_INSIDE", "AIMS_CORRIDOR", "AIMS_DEVIATION_DEG", "invivo_aims", "paper_checks"]

# the aims for the like-for-like comparison (Ludewig's frames)
AIMS_DEVIATION_DEG = (("ST_medRotation_X", "ST upward rotation", 8.0), ("GH_abduction_X", "GH elevation", 8.0),
                      ("ST_protraction_Y", "ST internal rotation", 10.0))
AIMS_CORRIDOR = (("ST_medRotation_X", "ST upward rotation"), ("ST_protraction_Y", "ST internal rotation"),
                 ("ST_tilt_Z", "ST tilt"), ("GH_abduction_X", "GH elevation"), ("GH_rotation_Y", "GH axial rotation"))
AIM_SHARE_INSIDE = 0.8
SENSITIVITY_WALL_LIMIT_S = 600.0


def paper_checks(sier: Sier, realisations: SierRealisations, agreement: Agreement, sensitivity: Sensitivity,
                 invivo: dict[str, InvivoComparison], paper: PaperNumbers) -> tuple[Check, ...]:
    """exubio's figures against the paper's limits (value <= limit), and the sign of two
    in vivo trends against Ludewig's."""
    out = []

    def check(what: str, value: float, limit: float, unit: str) -> None:
        out.append(Check(what=what, value=value, limit=limit, unit=unit,
                         passed=bool(np.isfinite(value) and value <= limit)))

    pf = sier.pf
    if isinstance(pf, SierMethod):
        check("SIER: PF GH axial rotation RMSE vs truth", pf.gh_axial_rotation_rmse_deg,
              paper.sier_gh_axial_rmse_deg.pf, "deg")
        x, _, z = pf.gh_marker_rmse_xyz_mm
        check(f"SIER: PF GH marker ({sier.gh_marker}) X RMSE vs truth", x, paper.sier_gh_marker_rmse_mm.pf_x, "mm")
        check(f"SIER: PF GH marker ({sier.gh_marker}) Z RMSE vs truth", z, paper.sier_gh_marker_rmse_mm.pf_z, "mm")
    real = realisations.summary.get("pf")
    if real is not None and real.gh_axial_rotation_rmse_deg is not None:
        n = len(realisations.runs)
        check(f"SIER, {n} noise/STA seeds: PF GH axial rotation RMSE, worst seed",
              real.gh_axial_rotation_rmse_deg.max, paper.sier_gh_axial_rmse_deg.pf, "deg")
        check(f"SIER, {n} noise/STA seeds: PF GH marker X RMSE, worst seed", real.gh_marker_x_rmse_mm.max,
              paper.sier_gh_marker_rmse_mm.pf_x, "mm")
        check(f"SIER, {n} noise/STA seeds: PF GH marker Z RMSE, worst seed", real.gh_marker_z_rmse_mm.max,
              paper.sier_gh_marker_rmse_mm.pf_z, "mm")
    check("PF vs LS: max joint-coordinate RMSE over all motions (coordinates the markers determine)",
          agreement.max_coordinate_rmse_deg, paper.pf_ls_max_joint_rmse_deg, "deg")
    check("PF vs LS: max marker-trajectory RMSE over all motions", agreement.max_marker_rmse_mm,
          paper.pf_ls_max_marker_rmse_mm, "mm")
    causes = {n: a.marker_rmse_causes_mm for n, a in agreement.trials.items()
              if getattr(a, "marker_rmse_causes_mm", None)}
    if causes:  # why it is not met, measured (issue 21): the check stays as it is
        out[-1] = dataclasses.replace(out[-1], note="measured causes, PF-LS max marker RMSE with every segment's mass "
                                      "x 0.01 / and the dampers x 0.1: " + "; ".join(
                                          f"{n} {c['masses_x0.01']:.2f} / {c['masses_x0.01_dampers_x0.1']:.2f} mm"
                                          for n, c in causes.items())
                                      + " (inertia of the arm, then PF's damper lag d/c on markers the rigid model "
                                        "cannot fit exactly)")
        # the check restated as what the measurement says PF must meet: LS's solution once PF's
        # own physics (inertia, damper lag) is taken away, on every real trial
        check("PF vs LS: max marker-trajectory RMSE on the real trials with PF's inertia and damper lag taken "
              "away (masses x 0.01, dampers x 0.1)",
              max(c["masses_x0.01_dampers_x0.1"] for c in causes.values()), paper.pf_ls_max_marker_rmse_mm, "mm")
    check("sensitivity study: 32 PF runs, total wall time", sensitivity.total_wall_s, SENSITIVITY_WALL_LIMIT_S, "s")
    check(f"sensitivity study: PF runs of {sensitivity.runs} that stop", len(sensitivity.failed_runs), 0, "runs")
    if sensitivity.fallback_runs:  # finished, on PF's fallback: said with the first run's reason
        out[-1] = dataclasses.replace(out[-1], note="finished on PF's fallback (" + "; ".join(
            f"c {f.stiffness_n_per_m:g} N/m, k {f.ratio_s:g} s: {f.robust_options}, {f.robust_deflection_mm:.1f} mm "
            f"mean deflection; its first run: {f.error}" for f in sensitivity.fallback_runs) + ")")
    for name in ("abduction", "flexion"):
        angles = invivo[name].pf.angles if invivo[name].pf is not None else {}
        for col in ("ST_medRotation_X", "SC_elevation_X"):
            if col in angles:
                slope, ref = angles[col].slope_deg_per_deg, angles[col].ludewig_slope_deg_per_deg
                label = {"ST_medRotation_X": "ST upward rotation (X')", "SC_elevation_X": "SC elevation (X')"}[col]
                out.append(Check(what=f"{name}: PF {label} slope over HT 30-120 deg has Ludewig's sign",
                                 value=slope, limit=ref, unit="deg/deg", kind="same_sign",
                                 passed=bool(np.isfinite(slope) and np.sign(slope) == np.sign(ref))))
    return tuple(out)


def invivo_aims(invivo: dict[str, InvivoComparison]) -> tuple[Check, ...]:
    """The issue's aims for the like-for-like comparison, per trial and method (not checks of the
    paper: the paper compared in ISB frames)."""
    out = []
    for name in ("abduction", "flexion"):
        for method in METHODS:
            src = invivo[name].source(method)
            angles = src.angles if src is not None else {}
            for key, label, limit in AIMS_DEVIATION_DEG:
                if key in angles:
                    dev = angles[key].max_abs_deviation_deg
                    out.append(Check(what=f"{name}: {method.upper()} {label} within {limit:g} deg of Ludewig at HT "
                                          f"30/60/90/120 (Ludewig's frames)",
                                     value=dev, limit=limit, unit="deg", kind="aim",
                                     passed=bool(np.isfinite(dev) and dev <= limit)))
            for key, label in AIMS_CORRIDOR:
                e = angles.get(key)
                if e is None:
                    continue
                if not np.isfinite(e.share_inside_corridor):
                    out.append(Check(what=f"{name}: {method.upper()} {label} inside the corridor over HT 30-120",
                                     value=float("nan"), limit=AIM_SHARE_INSIDE, unit="share", kind="aim_min",
                                     passed=None, note=f"not evaluable: {e.corridor_studies} comparable study "
                                                       f"in this plane, no corridor"))
                    continue
                out.append(Check(what=f"{name}: {method.upper()} {label} inside the corridor of "
                                      f"{e.corridor_studies} studies over HT 30-120 ({e.corridor_span_deg:.0f} deg covered)",
                                 value=e.share_inside_corridor, limit=AIM_SHARE_INSIDE, unit="share",
                                 kind="aim_min", passed=bool(e.share_inside_corridor >= AIM_SHARE_INSIDE)))
    return tuple(out)
