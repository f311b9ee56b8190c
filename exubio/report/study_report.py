"""The report of a study: ``study.report.pdf`` from ``study.json`` (written by exubio.run.study), one
row per trial with its verdicts, residuals, PF-LS agreement and wall time, failures with their
reason; counts on top. Reads the table only (no solver)."""
from __future__ import annotations

import json
import textwrap
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from exubio.io.results import atomic_write

__all__ = ["build_study_report"]

ROWS_PER_PAGE = 32
_VERDICT_COLOURS = {"ok": "#d8f0d8", "check": "#fde7c4", "fail": "#f6cccc"}


def _fmt(v, spec=".2f") -> str:
    return "" if v is None or v == "" else format(v, spec)


def _page(title: str, rows: list[dict], counts: dict, page: int, pages: int) -> Figure:
    fig = Figure(figsize=(11.69, 8.27))
    FigureCanvasAgg(fig)
    fig.text(0.03, 0.96, title, fontsize=12, weight="bold", va="top")
    fig.text(0.03, 0.925, "  ".join(f"{k}: {v}" for k, v in counts.items()) + f"   (page {page}/{pages})",
             fontsize=8.5, va="top")
    head = ["subject", "session", "trial", "status", "PF", "LS", "frames", "PF res. mm", "LS res. mm",
            "PF-LS deg", "wall s", "error"]
    cells, colours = [], []
    for r in rows:
        cells.append([r["subject"], r["session"], r["trial"], r["status"], r["pf_verdict"] or "", r["ls_verdict"] or "",
                      _fmt(r["frames"], "d") if isinstance(r["frames"], int) else "", _fmt(r["pf_residual_mm"]),
                      _fmt(r["ls_residual_mm"]), _fmt(r["pf_ls_max_rmse_deg"]), _fmt(r["wall_s"], ".1f"),
                      textwrap.shorten(r["error"] or "", 60)])
        worst = "fail" if r["status"] == "failed" else max(
            (v for v in (r["pf_verdict"], r["ls_verdict"]) if v), key=["ok", "check", "fail"].index, default="ok")
        colours.append([_VERDICT_COLOURS.get(worst, "white")] * len(head))
    ax = fig.add_axes((0.02, 0.06, 0.96, 0.84))
    ax.axis("off")
    if cells:
        t = ax.table(cellText=cells, colLabels=head, cellColours=colours, loc="upper center", cellLoc="left",
                     colWidths=[0.07, 0.06, 0.17, 0.08, 0.05, 0.05, 0.05, 0.06, 0.06, 0.06, 0.05, 0.24])
        t.auto_set_font_size(False)
        t.set_fontsize(6.5)
        t.scale(1.0, 1.15)
    fig.text(0.03, 0.03, "verdicts: ok = nothing found; check = read the trial's reasons (its report, summary.json); "
             "fail = the angles are wrong as they stand. Residual: mean marker-model distance. PF-LS: the largest "
             "RMSE between the two methods over the coordinates the markers determine.", fontsize=7)
    return fig


def build_study_report(study_json: str | Path, pdf_path: str | Path, /) -> Path:
    data = json.loads(Path(study_json).read_text(encoding="utf-8"))
    rows = data["trials"]
    pages = max(1, -(-len(rows) // ROWS_PER_PAGE))
    figs = [_page(f"exubio study: {data['study']}", rows[k * ROWS_PER_PAGE:(k + 1) * ROWS_PER_PAGE], data["counts"],
                  k + 1, pages) for k in range(pages)]

    def write(tmp: Path) -> None:
        with PdfPages(tmp) as pdf:
            for f in figs:
                pdf.savefig(f)

    return atomic_write(pdf_path, write)
