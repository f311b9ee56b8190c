"""Build the validation report from the study's typed results (``exubio.validation.results``,
read with ``ValidationResults.load`` from the files ``exubio.validation.run_validation`` saved):
``validation.pdf`` (title page with the summary, one page per figure, Table 1 and the Ludewig
comparison tables) and one PNG per figure.

This module assembles the pages and writes the files; the pages are drawn in
``validation_paper_figures`` (Figs. 2-5), ``validation_exubio_figures`` (Figs. 6-8),
``validation_tables`` (the table pages) and ``validation_summary`` (the summary), on what
``validation_common`` shares. Figures are drawn on ``matplotlib.figure.Figure`` objects with the
Agg canvas (no pyplot state). Angles are in degrees, lengths in mm, times in s; every figure names
its data source.
"""
from __future__ import annotations

from pathlib import Path


from exubio.report.page_figures import pdf_pages
from exubio.report.validation_exubio_figures import fig_agreement, fig_mismatch, fig_rates
from exubio.report.validation_paper_figures import fig_invivo, fig_residuals, fig_sensitivity, fig_sier
from exubio.report.validation_summary import summary_pages
from exubio.report.validation_tables import bone_page, ludewig_page, scapula_page, sier_realisations_page, table1_page
from exubio.validation.results import ValidationResults

__all__ = ["FIGURES", "REPORT_PAGES", "build_report"]

FIGURES = ("fig2_sensitivity.png", "fig3_residuals.png", "fig4_sier.png", "fig5_invivo.png",
           "fig6_pf_ls_agreement.png", "fig7_model_mismatch.png", "fig8_rates.png")
REPORT_PAGES = ("summary", "fig2_sensitivity", "fig3_residuals", "table1", "fig4_sier", "sier_realisations",
                "fig5_invivo", "ludewig_deviations", "fig6_pf_ls_agreement", "fig7_model_mismatch", "fig8_rates",
                "scapula_calibration", "bone_truth")
"""Pages of validation.pdf in order; ludewig_deviations is two pages (numbers, corridor studies)."""


def build_report(folder: str | Path, /, *, dpi: int | None = None) -> dict[str, Path]:
    """Write ``validation.pdf`` and the figure PNGs into ``folder`` from the results that
    ``exubio.validation.run_validation`` saved there (``ValidationResults.load``); returns the
    written paths by name. dpi: PNG resolution (default 130; 60 for a quick run)."""
    folder = Path(folder)
    r = ValidationResults.load(folder)
    if dpi is None:
        dpi = 60 if r.quick else 130
    figures = {
        "fig2_sensitivity": fig_sensitivity(r),
        "fig3_residuals": fig_residuals(r),
        "fig4_sier": fig_sier(r),
        "fig5_invivo": fig_invivo(r),
        "fig6_pf_ls_agreement": fig_agreement(r),
        "fig7_model_mismatch": fig_mismatch(r),
        "fig8_rates": fig_rates(r),
    }
    pages = {"summary": summary_pages(r), "table1": table1_page(r), "ludewig_deviations": ludewig_page(r),
             "sier_realisations": sier_realisations_page(r), "scapula_calibration": scapula_page(r),
             "bone_truth": bone_page(r), **figures}
    written: dict[str, Path] = {}
    for name, fig in figures.items():
        path = folder / f"{name}.png"
        tmp = folder / f"{name}.tmp.png"
        fig.savefig(tmp, dpi=dpi)
        tmp.replace(path)
        written[name] = path
    pdf_path = folder / "validation.pdf"
    tmp_pdf = folder / "validation.tmp.pdf"
    with pdf_pages(tmp_pdf) as pdf:
        for name in REPORT_PAGES:
            for page in (pages[name] if isinstance(pages[name], list) else [pages[name]]):
                pdf.savefig(page)
        info = pdf.infodict()
        info["Title"] = "exubio validation report"
        info["Subject"] = "potential-field vs least-squares upper-limb kinematics; data: " + \
            ", ".join(f"{k} {v.kind}" for k, v in r.data.items())
        info["Creator"] = f"exubio {r.exubio_version}"
    tmp_pdf.replace(pdf_path)
    written["pdf"] = pdf_path
    return written
