"""The validation study's results as typed records, and the files they are kept in.

``ValidationResults`` holds every section of the study (``exubio.validation.run``); the report
(``exubio.report.validation_report``) draws from it. Both go through this module, so the two
cannot disagree on a key: ``ValidationResults.save(folder)`` writes

* ``validation_runs.json``: the whole record (settings, data provenance, every number);
* ``table1.json``: the paper's Table 1 for exubio (``table1``) beside the paper's row;
* ``validation_data.npz``: the arrays the figures need (npz names ``<section>__<name>``, from
  the records' fields, see ``exubio.io.records``),

and ``ValidationResults.load(folder)`` reads them back into equal records. Imports no solver.

Units are those in the field names, as in the files: lengths in mm, angles in deg, times in s,
spring constants in N/m (the files keep their numbers bit for bit; converting to SI and back
would not). NaN stands for "not available" (null in the files). ``pf`` and ``ls`` are the
potential-field and least-squares reconstructions; trials are named "abduction", "flexion",
"sier"; joints "SC", "AC", "ST", "GH" (and "HT").
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from exubio.io.records import (
    Record,
    SchemaError,
    array,
    decode,
    encode_arrays,
    nan_to_none,
    npz_name,
    optional,
    write_json,
)
from exubio.validation.settings import ValidationSettings
from exubio.validation.records_runs import (  # noqa: F401 - the records the results file holds
    Failed,
    Skipped,
    MedianMax,
    RmsMax,
    CalibrationFrames,
    MeanMax,
    CalibrationResidual,
    EllipsoidFit,
    CalibrationSummary,
    TrialData,
    FailedRun,
    Sensitivity,
    ResidualStats,
    ResidualRow,
    SierMethod,
    Sier,
    SierRunMethod,
    SierRun,
    SierSummary,
    SierRealisations,
)
from exubio.validation.records_comparisons import (  # noqa: F401
    BoneAngle,
    BoneTask,
    BoneTruth,
    AngleComparison,
    ElevationComparison,
    CorridorMember,
    CorridorEntry,
    InvivoComparison,
    C3dTask,
    C3dTasks,
    MasslessDiagnostic,
    MasslessFailed,
    AgreementTrial,
    NotCompared,
    Agreement,
    RatesCondition,
    Rates,
    ScapulaVariant,
    ScapulaDirection,
    ScapulaSimulated,
    ScapulaCrossValidation,
)

__all__ = [
    "DATA_NPZ", "METHODS", "RUNS_JSON", "TABLE1_JSON", "TRIALS",
    "Agreement", "AgreementTrial", "AngleComparison", "C3dTask", "C3dTasks", "CalibrationFrames",
    "CalibrationResidual", "CalibrationSummary", "Check", "CorridorEntry", "CorridorMember", "ElevationComparison",
    "EllipsoidFit", "Failed", "FailedRun", "InvivoComparison", "MasslessDiagnostic", "MasslessFailed", "MeanMax",
    "MedianMax", "MismatchRun", "ModelMismatch", "NotCompared", "PaperGhMarker", "PaperMethods", "PaperNumbers",
    "PaperSensitivity", "PaperTable1Row",
    "Rates", "RatesCondition", "ScapulaCrossValidation", "ScapulaDirection", "ScapulaSimulated", "ScapulaVariant",
    "ResidualRow", "ResidualStats", "RmsMax", "SchemaError", "Sensitivity", "Sier", "SierMethod", "SierRealisations",
    "SierRun", "SierRunMethod", "SierSummary", "Skipped", "TrialData", "ValidationResults",
]

RUNS_JSON = "validation_runs.json"
TABLE1_JSON = "table1.json"
DATA_NPZ = "validation_data.npz"
METHODS = ("pf", "ls")
TRIALS = ("abduction", "flexion", "sier")
"""The study's trials: the two elevations of Fig. 5 and the simulated internal-external rotation."""

# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class PaperTable1Row(Record):
    """The paper's Table 1 row for a trial (wall times in s, residuals in mm)."""

    frames: int
    duration_s: float
    pf_wall_s: float
    ls_wall_s: float
    max_mean_residual_mm: float
    sd_at_max_mean_mm: float
    max_residual_mm: float
    max_residual_marker: str
    max_rmse_mm: float
    max_rmse_marker: str


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperMethods(Record):
    """A figure of the paper for PF and LS."""

    pf: float
    ls: float


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperGhMarker(Record):
    """The paper's SIER GH marker RMSE (mm), X and Z, PF and LS."""

    pf_x: float
    ls_x: float
    pf_z: float
    ls_z: float


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperSensitivity(Record):
    """The paper's sensitivity study (Fig. 2) and its chosen spring-damper."""

    stiffness_n_per_m: tuple[float, float]
    ratio_s: tuple[float, float]
    runs: int
    chosen_stiffness_n_per_m: float
    chosen_damping_ns_per_m: float
    finding: str


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperNumbers(Record):
    """The paper's published figures of merit (exubio.report.paper.PAPER)."""

    citation: str
    table1: dict[str, PaperTable1Row]
    pf_ms_per_frame: float
    ls_ms_per_frame: float
    sier_gh_axial_rmse_deg: PaperMethods
    sier_gh_marker_rmse_mm: PaperGhMarker
    pf_ls_max_joint_rmse_deg: float
    pf_ls_max_marker_rmse_mm: float
    pf_ls_rmse_deg_by_motion: dict[str, float]
    sensitivity: PaperSensitivity
    hardware: str


@dataclass(frozen=True, eq=False, kw_only=True)
class Check(Record):
    """A figure against a limit: ``passed`` (None: not evaluable, see ``note``). ``kind``: None (value
    <= limit), "same_sign" (the value has the limit's sign), "aim" (<= limit, an aim of the
    like-for-like comparison) or "aim_min" (>= limit)."""

    what: str
    value: float
    limit: float
    unit: str
    kind: str | None = optional()
    passed: bool | None
    note: str | None = optional()


# --------------------------------------------------------------------------------------------
# Model mismatch (exubio.validation.mismatch)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class MismatchRun(Record):
    """One simulated trial with a perturbed model (``perturbation``: exubio.synth.perturb words),
    reconstructed by ``method`` with the generic model: the worst measured angle's RMSE and the
    largest error of any measured angle (deg); ``mismatch_cost_deg``: the worst RMSE of the same
    case and motion without artefact (what the mismatch alone costs); the verdict, its non-note
    reasons, the segments the model-mismatch check names and its evidence."""

    case: str
    perturbation: tuple[str, ...]
    motion: str
    artefact: str
    method: str
    mismatch_cost_deg: float
    worst_angle: str
    worst_rmse_deg: float
    worst_max_deg: float
    angle_rmse_deg: dict[str, float]
    mean_residual_mm: float
    verdict: str
    reasons: tuple[str, ...]
    mismatch_segments: tuple[str, ...]
    scapula_contact_offset_mean_mm: float
    bias_mm: dict[str, float]


@dataclass(frozen=True, eq=False, kw_only=True)
class ModelMismatch(Record):
    """The model-mismatch section: every run; ``costly`` runs whose mismatch costs more than
    ``cost_limit_deg``, ``caught`` of them with a check naming a segment, the ``missed`` ones;
    ``no_mismatch`` runs without perturbation, those the mismatch check named anyway
    (``false_alarms``) and those not ``ok`` for any reason; perturbed runs that cost less than the
    limit yet were flagged (``flagged_cheap``)."""

    cost_limit_deg: float
    duration_s: float
    rate_hz: float
    noise_mm: float
    sta_mm: float
    runs: tuple[MismatchRun, ...]
    costly: int
    caught: int
    missed: tuple[str, ...]
    no_mismatch: int
    false_alarms: tuple[str, ...]
    no_mismatch_not_ok: tuple[str, ...]
    flagged_cheap: tuple[str, ...]


# --------------------------------------------------------------------------------------------
# Everything
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class ValidationResults(Record):
    """The whole validation study: what ran where, every section's results, the paper's numbers
    and the checks against them; ``ludewig``: Ludewig et al. 2009's means per plane and column
    (npz only). ``report_wall_s`` is set once the report is built."""

    exubio_version: str
    python: str
    machine: str
    processor: str
    quick: bool
    settings: ValidationSettings
    data: dict[str, TrialData]
    reconstruction_errors: dict[str, dict[str, str]]
    sensitivity: Sensitivity = npz_name("sens")
    table1: dict[str, ResidualRow] = npz_name("res__{}")
    sier: Sier
    sier_realisations: SierRealisations
    invivo: dict[str, InvivoComparison] = npz_name("iv__{}")
    agreement: Agreement = npz_name("agr")
    c3d_tasks: C3dTasks | Skipped = npz_name("c3d")
    truth_rmse_deg: dict[str, dict[str, dict[str, float]]]
    paper: PaperNumbers
    checks: tuple[Check, ...]
    invivo_aims: tuple[Check, ...]
    total_wall_s: float
    report_wall_s: float | None = optional()
    rates: Rates | Skipped | None = optional()
    scapula: ScapulaCrossValidation | None = optional()
    ludewig: dict[str, dict[str, np.ndarray]] = array(npz="lud__{}")
    mismatch: ModelMismatch | None = optional()  # the model-mismatch section (absent in older files)
    bone: BoneTruth | Skipped | None = optional()  # exubio against bone (exubio.validation.bone; absent in older files)

    # files ----------------------------------------------------------------------------------
    def table1_json(self) -> dict[str, Any]:
        """The content of table1.json: exubio's rows, the paper's, the units."""
        return {"rows": {k: v.to_json() for k, v in self.table1.items()},
                "paper": {k: v.to_json() for k, v in self.paper.table1.items()},
                "units": {"wall_s": "s", "residuals": "mm"}}

    def arrays(self) -> dict[str, np.ndarray]:
        """The content of validation_data.npz, by npz name."""
        return encode_arrays(self)

    def save(self, folder: str | Path, /) -> dict[str, Path]:
        """Write validation_data.npz, table1.json and validation_runs.json into ``folder`` (each
        through a temporary file); returns their paths."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = {"npz": folder / DATA_NPZ, "table1": folder / TABLE1_JSON, "runs": folder / RUNS_JSON}
        tmp = folder / "validation_data.tmp.npz"
        np.savez_compressed(tmp, **self.arrays())
        tmp.replace(paths["npz"])
        write_json(paths["table1"], self.table1_json())
        write_json(paths["runs"], self.to_json())
        return paths

    @classmethod
    def from_json(cls, runs: dict[str, Any], arrays: dict[str, np.ndarray] | None = None, /) -> ValidationResults:
        """The record from the parsed validation_runs.json and the npz arrays (SchemaError when
        they do not fit)."""
        return decode(cls, runs, arrays if arrays is not None else {})

    @classmethod
    def load(cls, folder: str | Path, /) -> ValidationResults:
        """Read the files ``save`` wrote; SchemaError if validation_runs.json, the npz or
        table1.json do not fit the records or each other."""
        folder = Path(folder)
        runs = json.loads((folder / RUNS_JSON).read_text(encoding="utf-8"))
        with np.load(folder / DATA_NPZ, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        out = cls.from_json(runs, arrays)
        table1 = folder / TABLE1_JSON
        if table1.is_file() and json.loads(table1.read_text(encoding="utf-8")) != nan_to_none(out.table1_json()):
            raise SchemaError(f"{table1} disagrees with {RUNS_JSON}")
        return out

    # questions the report asks ----------------------------------------------------------------
    def is_real(self, trial: str) -> bool:
        """Whether ``trial`` is a recorded (not simulated) trial."""
        return self.data[trial].is_real
