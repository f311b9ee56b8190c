"""The report of a study: ``study.report.pdf`` from ``study.json`` (written by exubio.run.study).
Page 1 opens with the counts and each method's verdicts over the study; then one row per trial
(subject, session, trial, status, verdicts, frames, residuals, PF-LS agreement, wall time, a
failure's reason and the reasons of every check and fail verdict), every name and reason written in full, wrapped inside its column, the rows
shaded by their worst verdict and paginated to fit (a row is never split across pages); a footer
with the page number on every page. Then the rhythm pages of the trials that raise the arm (per
method and plane: the group, then each subject; exubio.report.rhythm_page). Reads the table and
the trials' result files only (no solver)."""
from __future__ import annotations

import json
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from exubio.io.results import atomic_write
from exubio.report.calibration_page import short_paths
from exubio.report.page_figures import pdf_pages
from exubio.method_registry import method_names, method_style

__all__ = ["build_study_report"]

_PAGE = (11.69, 8.27)  # A4 landscape, inches
_LEFT, _RIGHT = 0.03, 0.97
_SIZE = 6.5  # table font size (monospace, so a column's width in characters is exact)
_EM = 0.6  # a monospace character's width, in font sizes
_PITCH = 1.2  # line pitch, in font sizes
_VERDICT_COLOURS = {"ok": "#d8f0d8", "check": "#fde7c4", "fail": "#f6cccc"}
_ORDER = ["ok", "check", "fail"]
_FOOTER = ("verdicts: ok = nothing found; check = read the trial's reasons (its report, summary.json); fail = the "
           "angles are wrong as they stand. Residual: mean marker-model distance. PF-LS: the largest RMSE between "
           "the two methods over the coordinates the markers determine. Wall: the trial's time on its worker.")


@dataclass(frozen=True)
class _Column:
    head: str
    key: str
    chars: int  # width in characters (the wrap width is one less: a space between columns)
    spec: str = ""  # a number's format; "" for text, which wraps


def _columns() -> tuple[_Column, ...]:
    """The table's columns: per method of exubio.method_registry its verdict and mean residual."""
    labels = {m: method_style(m).label for m in method_names()}
    return (_Column("subject", "subject", 14), _Column("session", "session", 14), _Column("trial", "trial", 30),
            _Column("status", "status", 9), *(_Column(lab, f"{m}_verdict", 6) for m, lab in labels.items()),
            _Column("frames", "frames", 8, "d"), *(_Column(f"{lab} res mm", f"{m}_residual_mm", 11, ".2f")
                                                   for m, lab in labels.items()),
            _Column("PF-LS deg", "pf_ls_max_rmse_deg", 11, ".2f"), _Column("wall s", "wall_s", 8, ".1f"),
            _Column("why: a failure, every check and fail reason", "error", 0))


def _char_width() -> float:
    """One monospace character's width as a fraction of the page width."""
    return _SIZE * _EM / 72 / _PAGE[0]


def _line() -> float:
    """One table line's height as a fraction of the page height."""
    return _SIZE * _PITCH / 72 / _PAGE[1]


def _widths() -> list[int]:
    """Every column's width in characters; the reason takes what the others leave."""
    total = int((_RIGHT - _LEFT) / _char_width())
    fixed = sum(c.chars for c in _columns() if c.chars)
    return [c.chars or total - fixed for c in _columns()]


def _wrap(text: str, width: int) -> list[str]:
    """``text`` in lines of at most ``width`` characters, broken at spaces, ``_``, ``-``, ``.`` or
    ``/`` where it can and inside a word where it must (a trial name is written in full)."""
    lines: list[str] = []
    for part in text.split("\n"):
        rest = part
        while len(rest) > width:
            cut = max(rest.rfind(ch, 0, width + (ch == " ")) for ch in " _-./")
            cut = width if cut <= 0 else cut + (rest[cut] != " ")
            lines.append(rest[:cut].rstrip())
            rest = rest[cut:].lstrip(" ")
        lines.append(rest)
    return lines or [""]


def _cell(row: dict, col: _Column) -> str:
    v = row.get(col.key)
    if col.key == "error":  # a failure's reason, then the reasons of every check and fail verdict
        v = "; ".join(x for x in (row.get("error"), row.get("reasons")) if x)
    if v is None or v == "":
        return ""
    if col.spec:
        if col.spec == "d" and not isinstance(v, int):
            return str(v)
        return format(v, col.spec)
    return short_paths(str(v)) if col.key == "error" else str(v)


def _worst(row: dict) -> str:
    if row.get("status") == "failed":
        return "fail"
    verdicts = [v for v in (row.get(f"{m}_verdict") for m in method_names()) if v in _ORDER]
    return max(verdicts, key=_ORDER.index, default="")


MAX_CELL_LINES = 8
"""A cell's lines at the most (a failure's reason longer than that ends with where it is in full)."""


def _row_lines(row: dict, widths: list[int]) -> list[list[str]]:
    cells = []
    for c, w in zip(_columns(), widths):
        lines = _wrap(_cell(row, c), w - 1)
        if len(lines) > MAX_CELL_LINES:
            more = " ... (in full in study.json)"
            lines = lines[:MAX_CELL_LINES - 1] + [lines[MAX_CELL_LINES - 1][:max(0, w - 1 - len(more))] + more]
        cells.append(lines)
    return cells


def _tallies(rows: list[dict]) -> str:
    out = []
    for method, key in ((method_style(m).label, f"{m}_verdict") for m in method_names()):
        n = {v: sum(r.get(key) == v for r in rows) for v in _ORDER}
        if sum(n.values()):
            out.append(f"{method}: " + ", ".join(f"{k} {v}" for k, v in n.items()))
    return "   ".join(out)


def _header(fig: Figure, data: dict, first: bool) -> float:
    """The page's title (and on page 1 the study's counts and verdicts); the top of the table."""
    fig.text(_LEFT, 0.965, f"exubio study: {data['study']}", fontsize=12, weight="bold", va="top")
    y = 0.93
    if first:
        counts = "   ".join(f"{k}: {v}" for k, v in data.get("counts", {}).items())
        lines = [f"{len(data['trials'])} trials   {counts}"]
        tallies = _tallies(data["trials"])
        if tallies:
            lines.append(f"verdicts   {tallies}")
        if data.get("source"):
            lines.append(f"study file: {data['source']}")
        fig.text(_LEFT, y, "\n".join(lines), fontsize=8.5, va="top", linespacing=1.4)
        y -= len(lines) * 8.5 * 1.4 / 72 / _PAGE[1] + 0.015
    return y


def _footer(fig: Figure, page: int, pages: int) -> float:
    """The footer (the legend and the page number) at the foot; its top."""
    size = 7.0
    chars = int((_RIGHT - _LEFT - 0.1) * _PAGE[0] * 72 / (size * 0.55))
    lines = textwrap.wrap(_FOOTER, chars)
    fig.text(_LEFT, 0.025, "\n".join(lines), fontsize=size, va="bottom", linespacing=1.3)
    fig.text(_RIGHT, 0.025, f"page {page} of {pages}", fontsize=8, va="bottom", ha="right")
    return 0.025 + len(lines) * size * 1.3 / 72 / _PAGE[1] + 0.015


def _draw_table(fig: Figure, rows: list[tuple[dict, list[list[str]]]], widths: list[int], top: float) -> None:
    line, cw = _line(), _char_width()
    xs = [_LEFT]
    for w in widths[:-1]:
        xs.append(xs[-1] + w * cw)
    for x, c in zip(xs, _columns()):
        fig.text(x, top, c.head, fontsize=_SIZE, family="monospace", weight="bold", va="top")
    y = top - line * 1.3
    for row, cells in rows:
        n = max(len(c) for c in cells)
        colour = _VERDICT_COLOURS.get(_worst(row))
        if colour:
            fig.patches.append(Rectangle((_LEFT - 0.003, y - n * line - 0.002), _RIGHT - _LEFT + 0.006,
                                         n * line + 0.002, transform=fig.transFigure, facecolor=colour,
                                         edgecolor="none", zorder=-1))
        for x, lines in zip(xs, cells):
            if any(lines):
                fig.text(x, y, "\n".join(lines), fontsize=_SIZE, family="monospace", va="top", linespacing=_PITCH)
        y -= n * line + 0.003


def _paginate(data: dict, widths: list[int]) -> list[list[tuple[dict, list[list[str]]]]]:
    """The rows in pages, each page filled down to its footer; a row stays on one page."""
    line = _line()
    pages: list[list] = [[]]
    probe = Figure(figsize=_PAGE)
    floor = _footer(probe, 1, 1)
    room = _header(probe, data, True) - line * 1.3 - floor
    for row in data["trials"]:
        cells = _row_lines(row, widths)
        h = max(len(c) for c in cells) * line + 0.003
        if pages[-1] and h > room:
            pages.append([])
            room = _header(probe, data, False) - line * 1.3 - floor
        pages[-1].append((row, cells))
        room -= h
    return pages


def study_pages(data: dict) -> list[Figure]:
    """The report's pages as figures (a study.json's content)."""
    widths = _widths()
    pages = _paginate(data, widths)
    figs = []
    for k, rows in enumerate(pages):
        fig = Figure(figsize=_PAGE)
        FigureCanvasAgg(fig)
        top = _header(fig, data, k == 0)
        _footer(fig, k + 1, len(pages))
        if rows:
            _draw_table(fig, rows, widths, top)
        else:
            fig.text(_LEFT, top, "no trial in this study", fontsize=9, va="top")
        figs.append(fig)
    return figs


def rhythm_pages(study_dir: Path, data: dict) -> Iterator[Figure]:
    """The study's rhythm pages (exubio.report.rhythm_page) from its trials' result files, one at a
    time, each drawn into the figure of the one before (write each before asking for the next);
    none when no trial raises the arm."""
    from exubio.errors import InputError
    from exubio.report.rhythm_page import each_study_rhythm_page
    from exubio.scapulohumeral.files import study_rhythm

    try:
        groups = study_rhythm(study_dir)
    except InputError:
        return iter(())
    return each_study_rhythm_page(groups, data.get("study", ""), reuse=True)


def build_study_report(study_json: str | Path, pdf_path: str | Path, /) -> Path:
    data = json.loads(Path(study_json).read_text(encoding="utf-8"))
    table = study_pages(data)

    def write(tmp: Path) -> None:
        with pdf_pages(tmp) as pdf:
            for f in table:
                pdf.savefig(f)
            for f in rhythm_pages(Path(study_json).parent, data):
                pdf.savefig(f)

    return atomic_write(pdf_path, write)
