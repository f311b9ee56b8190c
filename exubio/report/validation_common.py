"""What every page of the validation report shares: page sizes, colours, labels and citations,
the accessors of the typed results (``exubio.validation.results``) that tolerate a failed or absent
part, number formatting, a new Agg-canvas figure, the footers and the table helper.

Figures are drawn on ``matplotlib.figure.Figure`` objects with the Agg canvas (no pyplot state).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from exubio.validation.results import (
    TRIALS,
    AgreementTrial,
    AngleComparison,
    ElevationComparison,
    Failed,
    ResidualStats,
    SierMethod,
    ValidationResults,
)


A4 = (8.27, 11.69)
A4_LANDSCAPE = (11.69, 8.27)
C_PF, C_LS, C_TRUE, C_INPUT, C_REF = "black", "tab:red", "tab:blue", "tab:cyan", "tab:green"
C_CORRIDOR = "#9bc59d"
MOTION_LABEL = {"abduction": "abduction-adduction", "flexion": "flexion-extension",
                "sier": "simulated internal-external rotation (SIER)"}
ANGLE_TITLES = {
    "SC": ("SC Y: protraction (+) / retraction (−)", "SC X′: elevation (−)", "SC Z″: posterior rotation (+)"),
    "ST": ("ST Y: internal rotation (+)", "ST X′: upward rotation (−)", "ST Z″: posterior tilt (+)"),
    "GH": ("GH X: elevation (−)", "GH Z′: forward flexion (+)", "GH Y″: internal (+) / external (−) rot."),
}
LUDEWIG_COLUMNS = {
    "SC": ("SC_protraction_Y", "SC_elevation_X", "SC_rotation_Z"),
    "ST": ("ST_protraction_Y", "ST_medRotation_X", "ST_tilt_Z"),
    "GH": ("GH_abduction_X", "GH_flexion_Z", "GH_rotation_Y"),
}
LUDEWIG_CITATION = ("Ludewig et al. 2009, J Bone Joint Surg Am 91(2):378-389 (bone pins, n = 12, mean; "
                    "via the Spartacus dataset, Moissenet et al. 2024, doi 10.5281/zenodo.11455521)")
CORPUS_NOTE = ("studies from the Spartacus shoulder kinematics dataset (Moissenet et al. 2025, "
               "doi 10.1016/j.jbiomech.2025.112642), each cited on the numbers page")
MESKERS_NOTE = ("Meskers et al. 1998 (electromagnetic tracking), the paper's second in vivo reference, could not "
                "be included: no numeric table, regression or digitised curve of it was available to the project "
                "(see ../shared/reference/reference_kinematics.md); its curves are not redrawn from the figure.")


def _source_label(r: ValidationResults, trial: str) -> str:
    d = r.data[trial]
    if d.is_real:
        return f"REAL trial {Path(d.source).name} (Seth et al. 2019), subject-calibrated model"
    s = r.settings
    if trial == "sier":
        return f"simulated, noise SD {s.noise_mm:g} mm, STA {s.sta_mm:g} mm"
    return f"SIMULATED (real trial not available), noise {s.noise_mm:g} mm, STA {s.sta_mm:g} mm"


def _residuals(stats: ResidualStats | Failed) -> ResidualStats | None:
    return stats if isinstance(stats, ResidualStats) else None


def _sier_xyz(m: SierMethod | Failed) -> tuple[float | None, ...]:
    """A method's GH marker RMSE per axis on SIER (None when it failed)."""
    return m.gh_marker_rmse_xyz_mm if isinstance(m, SierMethod) else (None, None, None)


def _sier_rotation(m: SierMethod | Failed) -> float | None:
    """A method's GH axial rotation RMSE on SIER (None when it failed)."""
    return m.gh_axial_rotation_rmse_deg if isinstance(m, SierMethod) else None


def _angle(src: ElevationComparison | None, key: str) -> AngleComparison | None:
    """A source's comparison of angle ``key`` (None when the source or the angle is absent)."""
    return src.angles.get(key) if src is not None else None


def _agreement(r: ValidationResults, trial: str) -> AgreementTrial | None:
    a = r.agreement.trials.get(trial)
    return a if isinstance(a, AgreementTrial) else None


def _fmt(v: Any, spec: str = ".2f", none: str = "n/a") -> str:
    if v is None:
        return none
    try:
        if not np.isfinite(v):
            return none
    except TypeError:
        return str(v)
    return format(v, spec)


def _new_figure(size) -> Figure:
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def _paragraphs(fig: Figure, paragraphs, y: float, *, width: int, fontsize: float, gap: float) -> float:
    """Paragraphs of text from ``y`` down, each wrapped at ``width`` characters (0.022 per line,
    ``gap`` between paragraphs); returns the y below the last."""
    import textwrap

    for text in paragraphs:
        for line in textwrap.wrap(text, width):
            fig.text(0.03, y, line, fontsize=fontsize)
            y -= 0.022
        y -= gap
    return y


def _footer(fig: Figure, text: str) -> None:
    fig.text(0.01, 0.005, text, fontsize=6.5, color="0.35", ha="left", va="bottom", wrap=True)


def _data_footer(r: ValidationResults) -> str:
    parts = [f"{t}: {_source_label(r, t)}" for t in TRIALS]
    return "Data: " + "; ".join(parts) + f". exubio {r.exubio_version}" + \
        (" — QUICK RUN (short trials, smoke test only)" if r.quick else "")


def _definition_note() -> str:
    return ("Angles in Ludewig et al. 2009's own definitions (from the Spartacus metadata, exubio.model.frame_definitions): "
            "thorax and humerus as ISB; clavicle Z SC→AC; scapula Z TS→AC, X normal to AI-TS-AC (built on AC, not "
            "ISB's AA); SC, AC, ST Y-X′-Z″, GH X-Z′-Y″, no sign change (raw Euler angles).")


def _table(ax, cells, col_labels, *, col_widths=None, fontsize=7.0, header_color="#dde6f0", row_scale=1.35,
           header_lines=1):
    ax.axis("off")
    tab = ax.table(cellText=cells, colLabels=col_labels, loc="upper center", cellLoc="center",
                   colWidths=col_widths)
    tab.auto_set_font_size(False)
    tab.set_fontsize(fontsize)
    tab.scale(1.0, row_scale)
    for (row, _), cell in tab.get_celld().items():
        if row == 0:
            cell.set_facecolor(header_color)
            cell.set_text_props(fontweight="bold")
            cell.set_height(cell.get_height() * header_lines)
    return tab
