"""A method's outcome on one trial, one typed object from the pipeline to the CLI, a study and the
report: the reconstruction (with its verdict), the trial's assessment, the anatomical angles and
joint moments as written, and the result set's files with the summary.json made from them inside
the write (``write_outcome``: nothing outside it builds that dict)."""
from __future__ import annotations

import dataclasses
import math
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from exubio.run.summary_file import RunNotes, agreement_entry, trial_summary
from exubio.run.trial_files import AngleOutputs, write_outputs
from exubio.trust.assess import TrialAssessment
from exubio.trust.quality import Quality
from exubio.types import Reconstruction

__all__ = ["MethodOutcome", "reported", "run_metadata", "write_outcome"]


@dataclass(frozen=True)
class MethodOutcome:
    """One method's outcome on one trial. ``reconstruction`` carries the verdict (``quality``) and,
    for a result set kept from an earlier run of the same inputs, ``resumed_from``; ``assessment``:
    the trial's (every method's; None for a kept set: its summary.json says it); ``angles``: the
    anatomical angles with their status and uncertainty, and the joint moments, as the files give
    them (None for a kept set); ``paths``: the result set's files by kind
    (exubio.io.result_names.SUFFIXES); ``summary``: the summary.json written from this outcome;
    ``metadata``: what the .npz records of the run (``run_metadata``)."""

    method: str
    stem: str
    reconstruction: Reconstruction
    assessment: TrialAssessment | None = None
    angles: AngleOutputs | None = None
    paths: Mapping[str, Path] = field(default_factory=dict)
    summary: Mapping[str, Any] = field(default_factory=dict)
    metadata: Mapping[str, Any] = field(default_factory=dict)  # the run's, as the .npz records it

    @property
    def quality(self) -> Quality | None:
        return self.reconstruction.quality

    @property
    def resumed(self) -> bool:
        return self.reconstruction.resumed_from is not None

    @property
    def moments(self) -> Any:
        """The joint moments (exubio.dynamics.moments.Moments) or None."""
        return None if self.angles is None else self.angles.moments

    @property
    def agreement_deg(self) -> dict[str, float]:
        """PF-LS RMSE (deg) of each anatomical angle over the frames where both methods measure it,
        as the result reports it (agreement_entry: 4 decimals; an angle without such frames left
        out); empty without both methods. A kept set's comes from its summary.json."""
        entry = (agreement_entry(self.assessment.agreement_deg) if self.assessment is not None
                 else self.summary.get("pf_ls_agreement_deg"))
        return {k: v for k, v in (entry or {}).items() if isinstance(v, float) and math.isfinite(v)}


def run_metadata(inputs: Any, trial_path: str | Path, method: str) -> dict[str, Any]:
    """What the .npz records of the run (``inputs``: exubio.run.pipeline.TrialInputs)."""
    import exubio

    return {
        "exubio_version": exubio.__version__,
        "python": platform.python_version(),
        "trial": os.path.abspath(trial_path),
        "model": inputs.model.source,
        "model_name": inputs.model.name,
        "body_mass_kg": inputs.model.body_mass_kg,
        "protocol": inputs.protocol.source,
        "protocol_name": inputs.protocol.name,
        "held_coordinates": list(inputs.protocol.held_coordinates),
        "protocol_relabel": dict(inputs.protocol.relabel),
        "method": method,
        "units": {"angles_in_files": "deg", "positions_in_npz": "m", "time": "s"},
        "ignored_labels": list(inputs.trial.ignored_labels),
        "units_in_trial_file": inputs.trial.units_in_file,
        "rate_hz": inputs.trial.rate_hz,
    }


def write_outcome(outcome: MethodOutcome, inputs: Any, trial_path: str | Path, out_dir: str | Path, /, *,
                  notes: RunNotes | None = None, streamed: Mapping[str, Any] | None = None,
                  overwrite: bool = True) -> MethodOutcome:
    """Write the outcome's result set (exubio.run.trial_files.write_outputs: all or nothing) with its
    summary.json, made here from the outcome (exubio.run.summary_file.trial_summary, PF's inertia
    scale, the joint moments' entry); returns the outcome with its ``paths`` and ``summary``."""
    from exubio.dynamics.moments import moments_summary
    from exubio.run.moments_outputs import moments_entry, pf_inertia_entry

    recon, stem = outcome.reconstruction, outcome.stem
    summ = trial_summary(recon, outcome.assessment, inputs, source=str(trial_path), stem=stem, notes=notes or RunNotes(),
                         quality=outcome.quality)
    if (pf_inertia := pf_inertia_entry(recon.info)) is not None:
        summ["pf_inertia_scale"] = pf_inertia
    if outcome.moments is not None:
        summ["moments"] = moments_entry(outcome.moments, moments_summary(outcome.moments), stem)
    meta = run_metadata(inputs, trial_path, outcome.method)
    paths = write_outputs(recon, out_dir, stem, metadata=meta, summary_data=summ, angles=outcome.angles,
                          streamed=None if streamed is None else dict(streamed), overwrite=overwrite)
    return dataclasses.replace(outcome, paths=paths, summary=summ, metadata={**meta, "signs": outcome.angles.signs})


def reported(outcome: MethodOutcome, /, *, model: Any = None) -> Any:
    """The outcome as the trial report draws it (exubio.report.trial_report.ReportedResult), from
    memory: its reconstruction, metadata and summary (as their files hold them: the same JSON), its
    angles at the precision of the CSV (what a report of the files draws, so the two are the same
    picture), the joint moments and ``model`` (the one it was reconstructed with). A set kept from
    an earlier run: read from its files."""
    from exubio.io.results import as_in_json, as_in_table
    from exubio.model.signs import convert
    from exubio.report.trial_report import Angles, ReportedResult, read_result

    if outcome.resumed or outcome.angles is None:
        return read_result(outcome.paths["npz"])
    a, recon = outcome.angles, outcome.reconstruction

    def as_read(rad):  # radians -> the CSV's degrees -> radians, as read_angles_csv gives them
        return np.radians(as_in_table(np.degrees(rad)))

    values = convert(a.names, as_read(convert(a.names, a.values_rad, "isb", a.signs)), a.signs, "isb")
    u = None if a.uncertainty_rad is None else as_read(np.asarray(a.uncertainty_rad, dtype=float))
    angles = Angles(as_in_table(recon.time_s), tuple(a.names), values, np.asarray(a.status, dtype=np.int8),
                    None if u is None or np.isnan(u).all() else u, a.signs)
    return ReportedResult(Path(outcome.paths["npz"]), recon, as_in_json(outcome.metadata, strict=False),
                          as_in_json(outcome.summary), angles, model=model, moments=outcome.moments)
