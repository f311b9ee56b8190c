"""Compatibility: the validation study moved to the package ``exubio.validation`` (typed results
in ``exubio.validation.results``). This module keeps the old names importable; ``run_validation``
here returns the content of validation_runs.json as a dict, as it did (NaN as float('nan')).
New code: ``from exubio.validation import run_validation`` (returns ``ValidationResults``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from exubio.validation.c3d_tasks import C3D_TASKS
from exubio.validation.checks import AIM_SHARE_INSIDE, AIMS_CORRIDOR, AIMS_DEVIATION_DEG
from exubio.validation.determinacy import (
    UNDETERMINED_RELATIVE_SINGULAR_VALUE,
    UNDETERMINED_SHARE,
    undetermined_coordinates,
    unobserved_segments,
)
from exubio.validation.paths import portable_paths, shared_data_dir
from exubio.validation.run import run_validation as _run_validation
from exubio.validation.settings import QUICK_SETTINGS, ValidationSettings
from exubio.validation.trials import (
    LUDEWIG_PLANE,
    PLOT_SAMPLES,
    REAL_PROTOCOL,
    REAL_TRIALS,
    Progress,
    why_no_real_trial,
)
from exubio.validation.trials import real_trial as _real_trial

__all__ = ["AIM_SHARE_INSIDE", "AIMS_CORRIDOR", "AIMS_DEVIATION_DEG", "C3D_TASKS", "LUDEWIG_PLANE", "PLOT_SAMPLES",
           "QUICK_SETTINGS", "REAL_PROTOCOL", "REAL_TRIALS", "UNDETERMINED_RELATIVE_SINGULAR_VALUE",
           "UNDETERMINED_SHARE", "ValidationSettings", "_real_trial", "portable_paths", "run_validation",
           "shared_data_dir", "undetermined_coordinates", "unobserved_segments", "why_no_real_trial"]


def run_validation(out_dir: str | Path = "reports/validation", /, *, quick: bool = False,
                   progress: Progress | None = None, settings: ValidationSettings | None = None) -> dict[str, Any]:
    """``exubio.validation.run_validation``, returning the content of validation_runs.json as a dict."""
    return _run_validation(out_dir, quick=quick, progress=progress, settings=settings).to_json()
