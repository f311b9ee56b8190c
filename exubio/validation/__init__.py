"""The validation study of the paper (its Fig. 2-6 and Table 1) run on exubio, with typed results.

``run_validation(out_dir)`` (``exubio.validation.run``) computes every section, saves the results
(``ValidationResults.save``: ``validation_runs.json``, ``table1.json``, ``validation_data.npz``) and
has ``exubio.report.build_report`` draw ``validation.pdf`` and the PNGs from them.

The results are typed records (``exubio.validation.results``, which imports no solver): the study
writes them and the report reads them (``ValidationResults.load``), so both agree by construction.
Importing this package does not import the solver; ``run_validation`` is loaded on first use.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from exubio.validation.results import (
    Agreement,
    AgreementTrial,
    AngleComparison,
    C3dTask,
    C3dTasks,
    CalibrationSummary,
    Check,
    ElevationComparison,
    Failed,
    InvivoComparison,
    PaperNumbers,
    ResidualRow,
    ResidualStats,
    SchemaError,
    Sensitivity,
    Sier,
    SierRealisations,
    Skipped,
    TrialData,
    ValidationResults,
)
from exubio.validation.settings import QUICK_SETTINGS, ValidationSettings

if TYPE_CHECKING:
    from exubio.validation.run import run_validation

__all__ = ["QUICK_SETTINGS", "Agreement", "AgreementTrial", "AngleComparison", "C3dTask", "C3dTasks",
           "CalibrationSummary", "Check", "ElevationComparison", "Failed", "InvivoComparison", "PaperNumbers",
           "ResidualRow", "ResidualStats", "SchemaError", "Sensitivity", "Sier", "SierRealisations", "Skipped",
           "TrialData", "ValidationResults", "ValidationSettings", "run_validation"]


def __getattr__(name: str) -> Any:
    if name == "run_validation":  # deferred: the study imports the solver, the results do not
        from exubio.validation.run import run_validation

        return run_validation
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
