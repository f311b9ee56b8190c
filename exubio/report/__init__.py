"""Figures and the PDF/PNG validation report (matplotlib, Agg canvas). Reads the files written by
``exubio.validation`` (as its typed results, exubio.validation.results) only and never imports the
solver (methods, backend, pipeline, exudyn)."""
from __future__ import annotations

from exubio.report.validation_report import FIGURES, REPORT_PAGES, build_report

__all__ = ["FIGURES", "REPORT_PAGES", "build_report"]
