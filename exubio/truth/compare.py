"""A bone-referenced trial reconstructed by PF and LS as a lab would (``exubio.truth.lab_run``), and
each anatomical angle compared with the bone's: RMSE, maximum error and the coverage of the angle's
stated uncertainty (the fraction of its measured frames where the truth lies within +-2u).

Only frames where the angle is ``measured`` (exubio.trust.observability) enter the figures, as in
every verdict; ``measured_fraction`` says how many those are.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import ReconstructionError
from ..model.angles import ANATOMICAL_COLUMNS, anatomical_table, angles_of_frames
from .lab_run import BoneLabRun, clavicle_gap_m

__all__ = ["AngleError", "TruthComparison", "TRUTH_ANGLES", "truth_angles", "compare_bone_trial", "angle_errors",
           "angle_status", "lab_inputs", "main_reasons"]

TRUTH_SETS = ("ST", "GH", "GH_phadke", "HT")
TRUTH_ANGLES: tuple[str, ...] = tuple(c for c in ANATOMICAL_COLUMNS if c.startswith(("ST_", "GH_", "HT_")))
"""The angles bone truth of a scapula and a humerus defines (ST, GH ISB and Phadke, HT)."""


@dataclass(frozen=True)
class AngleError:
    """One angle's error against bone, over its measured frames (degrees)."""

    rmse_deg: float
    max_deg: float
    coverage: float | None
    measured_fraction: float
    median_u_deg: float | None = None
    lab: "AngleError | None" = None  # the same reconstruction judged with the u and status a lab's run gives
    rms_error_over_u: float | None = None  # about 1 where u is the error's size, below where u is wider
    # over the judged frames (measured, error finite), in order: the signed error and u (rad); for pooling
    # the frames of several trials (UncertaintyFit.judgement) and for studies of u's size
    error_rad: np.ndarray | None = field(default=None, compare=False, repr=False)
    u_rad: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def frames_within(self) -> tuple[int, int]:
        """(frames where the bone lies within +-2u, frames judged), 0, 0 without u."""
        if self.error_rad is None or self.u_rad is None:
            return 0, 0
        return int(np.sum(np.abs(self.error_rad) <= 2 * self.u_rad)), int(self.error_rad.size)


@dataclass(frozen=True, eq=False)
class TruthComparison:
    """Per method ("pf", "ls") and angle its AngleError; what was assumed; each method's verdict."""

    file: str
    task: str
    assumption: str
    angles: Mapping[str, Mapping[str, AngleError]]
    verdicts: Mapping[str, str]
    n_frames: int
    rate_hz: float
    notes: tuple[str, ...] = field(default_factory=tuple)
    clavicle_gap_mm: Mapping[str, float] | None = None  # lab_run.clavicle_gap_m's median, p95, max (mm)
    reasons: Mapping[str, tuple[str, ...]] = field(default_factory=dict)  # per method, main_reasons of its verdict
    uncertainty_model: str = ""  # a lab's STA amplitude model the uncertainties used (its file); "": the shipped one

    def _labs(self, method: str, /) -> dict[str, AngleError]:
        """Per angle measured in some frame with a u, its ``AngleError.lab`` for ``method``."""
        labs = {a: getattr(per.get(method), "lab", None) for a, per in self.angles.items()}
        return {a: lab for a, lab in labs.items() if lab is not None and lab.coverage is not None}

    def lab_coverage(self, method: str = "ls", /) -> dict[str, tuple[float, float]]:
        """Per angle measured in some frame, (coverage of +-2u, fraction of frames measured) with the u and
        status a lab's run gives (``AngleError.lab``), for ``method``."""
        return {a: (float(lab.coverage), float(lab.measured_fraction)) for a, lab in self._labs(method).items()}

    def lab_error_over_u(self, method: str = "ls", /) -> dict[str, float]:
        """Per angle of ``lab_coverage``, the RMS of error / u over its measured frames (lab's u and status)."""
        return {a: float(lab.rms_error_over_u) for a, lab in self._labs(method).items()
                if lab.rms_error_over_u is not None}

    def lab_frames_within(self, method: str = "ls", /) -> dict[str, tuple[int, int]]:
        """Per angle of ``lab_coverage``, (frames where the bone lies within +-2u, frames judged)."""
        return {a: lab.frames_within for a, lab in self._labs(method).items()}

    def to_json(self) -> dict:
        num = lambda x: None if x is None or not np.isfinite(x) else round(float(x), 4)
        return {"file": self.file, "task": self.task, "assumption": self.assumption, "n_frames": self.n_frames,
                "rate_hz": self.rate_hz, "verdicts": dict(self.verdicts), "notes": list(self.notes),
                "clavicle_gap_mm": None if self.clavicle_gap_mm is None else {k: num(v) for k, v in
                                                                             self.clavicle_gap_mm.items()},
                "reasons": {m: list(r) for m, r in self.reasons.items()},
                **({"uncertainty_model": self.uncertainty_model} if self.uncertainty_model else {}),
                "angles": {a: {m: _error_json(e, num) for m, e in per.items()} for a, per in self.angles.items()}}


def _error_json(e: AngleError, num) -> dict:
    out = {"rmse_deg": num(e.rmse_deg), "max_deg": num(e.max_deg), "coverage": num(e.coverage),
           "measured_fraction": num(e.measured_fraction), "median_u_deg": num(e.median_u_deg),
           "rms_error_over_u": num(e.rms_error_over_u)}
    if e.lab is not None:
        out["lab"] = _error_json(e.lab, num)
    return out


def truth_angles(run: BoneLabRun) -> dict[str, np.ndarray]:
    """The bone's anatomical angles (rad, (n,) each) by column name."""
    sets = angles_of_frames(run.truth)
    out: dict[str, np.ndarray] = {}
    cols = iter(TRUTH_ANGLES)
    for key in TRUTH_SETS:
        ang = np.unwrap(sets[key], axis=0) if sets[key].shape[0] > 1 else sets[key]
        for j in range(3):
            out[next(cols)] = ang[:, j]
    return out


def _wrap(d: np.ndarray) -> np.ndarray:
    return (d + np.pi) % (2 * np.pi) - np.pi


def angle_errors(estimate: np.ndarray, truth: np.ndarray, measured: np.ndarray, u: np.ndarray | None) -> AngleError:
    """RMSE, max, coverage of +-2u and the RMS of error / u over the measured frames where both are finite."""
    signed = _wrap(np.asarray(estimate) - np.asarray(truth))
    err = np.abs(signed)
    ok = measured & np.isfinite(err)
    frac = float(ok.mean()) if ok.size else 0.0
    if not ok.any():
        return AngleError(float("nan"), float("nan"), None, frac, None)
    e = err[ok]
    cov = med_u = z = uu = None
    if u is not None:
        uu = np.asarray(u, dtype=float)[ok]
        cov = float(np.mean(e <= 2 * uu))
        med_u = float(np.degrees(np.median(uu)))
        with np.errstate(divide="ignore", invalid="ignore"):
            z = float(np.sqrt(np.mean((e / uu) ** 2)))
    return AngleError(float(np.degrees(np.sqrt(np.mean(e ** 2)))), float(np.degrees(e.max())), cov, frac, med_u,
                      rms_error_over_u=z, error_rad=signed[ok], u_rad=uu)


def _protocol(run: BoneLabRun, model):
    import yaml

    from ..run.inputs import protocol_for_model

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{run.protocol_mapping['name']}.yaml"
        path.write_text(yaml.safe_dump(dict(run.protocol_mapping), sort_keys=False))
        return protocol_for_model(model, path)


STILL_THORAX_COST = ("each angle's uncertainty carries the cost of that assumption: a trunk moving unseen as much as "
                     "the trunks of real arm tasks with thorax markers do (exubio.truth.trunk_amplitude), through the "
                     "reconstruction; the 'lab' figures judge the same reconstruction with the uncertainty and status "
                     "a lab's run with thorax markers gives, without that cost")


def angle_status(inputs, rec, /, *, still_thorax: bool):
    """The angles' status and uncertainty of ``rec`` as ``exubio reconstruct`` gives them, plus (``still_thorax``)
    the cost of the still thorax this run assumes (observability.angle_determinacy,
    ``thorax_assumed_still``); without it, what a lab's run with thorax markers gives."""
    from ..trust.assess import DETERMINACY_PERIOD_S
    from ..trust.observability import angle_determinacy
    from ..trust.sta_amplitude import amplitude_of

    b, targets = inputs.binding, inputs.targets
    dt = float(np.median(np.diff(targets.time_s))) if targets.n_frames > 1 else 1.0
    return angle_determinacy(b.kin, b.points, rec.q_rad, targets.present, b.protocol.weights,
                             held=b.held, locked=b.locked, amplitude=amplitude_of(b),
                             every=max(1, int(round(DETERMINACY_PERIOD_S / dt))), residuals_m=rec.residuals_m,
                             thorax_assumed_still=still_thorax, marker_positions_m=targets.positions_m)


def _measured_and_u(det, angle: str, n: int) -> tuple[np.ndarray, np.ndarray | None]:
    """An angle's measured frames (n,) and uncertainty (n,) rad under a status ``det`` (None: every frame,
    no u)."""
    if det is None:
        return np.ones(n, bool), None
    k = det.names.index(angle)
    return det.status[:, k] == 0, None if det.uncertainty_rad is None else det.uncertainty_rad[:, k]


def main_reasons(quality, /, *, most: int = 6) -> tuple[str, ...]:
    """A verdict's fail and check reasons, the worst first, one line per kind (its first message and how
    many more of that kind): what ``exubio truth`` prints beside each verdict."""
    kinds: dict[str, list] = {}
    for r in quality.reasons:  # worst first (Quality.of)
        if r.level.rank > 0:
            kinds.setdefault(r.code, []).append(r)
    return tuple(f"{rs[0].level.value}: {rs[0].message}" + (f" (and {len(rs) - 1} more of its kind)" if len(rs) > 1 else "")
                 for rs in list(kinds.values())[:most])


def lab_inputs(run: BoneLabRun, /):
    """(the subject model, the loaded inputs) of ``run``, as ``exubio reconstruct`` loads a trial: the
    subject model is its own generic (no static was fitted)."""
    from ..model.load import model_from_mapping
    from ..run.inputs import Session
    from ..run.pipeline import load_inputs

    model = model_from_mapping(dict(run.model_mapping), f"{run.trial.path} (subject model)",
                               name=str(run.model_mapping["name"]))
    protocol = _protocol(run, model)
    return model, load_inputs(run.trajectories, Session(model, protocol, model, protocol))


def compare_bone_trial(run: BoneLabRun, /, *, methods: Sequence[str] = ("pf", "ls"),
                       amplitude: Any = None) -> tuple[TruthComparison, dict]:
    """Reconstruct ``run`` with each method (its verdict as ``exubio reconstruct`` gives it) and
    compare its angles with the bone's. ``amplitude``: the STA amplitude model of every uncertainty
    and verdict (exubio.trust.sta_amplitude.STAAmplitude; default the shipped one). Returns the
    comparison and the reconstructions by method."""
    from ..run.pipeline import assess_inputs, reconstruct

    model, inputs = lab_inputs(run)
    if amplitude is not None:  # the run's model (exubio.trust.sta_amplitude.amplitude_of), as a protocol's key gives it
        inputs.binding.keep("sta_amplitude", amplitude)
    recs, failed = {}, {}
    for m in methods:
        try:
            recs[m] = reconstruct(inputs.model, inputs.protocol, inputs.targets, method=m)
        except ReconstructionError as exc:  # one method's failure is a finding of the comparison, not its end
            failed[m] = str(exc)
    if not recs:
        raise ReconstructionError(f"{run.trial.path}: every method failed: "
                                  + "; ".join(f"{m.upper()}: {r}" for m, r in failed.items()))
    assessment = assess_inputs(inputs, list(recs.values()))
    still = {m: angle_status(inputs, rec, still_thorax=True) for m, rec in recs.items()}
    lab = {m: angle_status(inputs, rec, still_thorax=False) for m, rec in recs.items()}
    truth = truth_angles(run)
    per_angle: dict[str, dict[str, AngleError]] = {a: {} for a in TRUTH_ANGLES}
    verdicts = {m: f"failed: {reason}" for m, reason in failed.items()}
    reasons: dict[str, tuple[str, ...]] = {}
    for m, rec in recs.items():
        q = assessment.quality[m]
        verdicts[m] = q.verdict.label if hasattr(q.verdict, "label") else str(q.verdict)
        reasons[m] = main_reasons(q)
        names, table = anatomical_table(model, rec.q_rad)
        for a in TRUTH_ANGLES:
            j = names.index(a)
            judged = [angle_errors(table[:, j], truth[a], *_measured_and_u(det, a, rec.n_frames))
                      for det in (still[m], lab[m])]
            per_angle[a][m] = replace(judged[0], lab=judged[1])
    gap = clavicle_gap_m(run) * 1000.0
    seen = gap[np.isfinite(gap)]
    gap_mm = ({"median": float(np.median(seen)), "p95": float(np.percentile(seen, 95)), "max": float(seen.max())}
              if seen.size else None)
    notes = () if gap_mm is None else (
        f"the still thorax against the pins: the bone's AC, carried by the scapula, lies off the sphere about SC on "
        f"which the model's rigid clavicle keeps it by {gap_mm['median']:.0f} mm (median; 95th percentile "
        f"{gap_mm['p95']:.0f}, max {gap_mm['max']:.0f} mm): no reconstruction under the assumption can follow that "
        f"part (a trunk that moved in the lab, a girdle unlike the model's), and the errors there are the "
        f"assumption's as much as exubio's (lab_run.clavicle_gap_m)",)
    comp = TruthComparison(str(run.trial.path), f"{run.trial.lab} {run.trial.task}",
                           run.assumption.text + "; " + STILL_THORAX_COST, per_angle,
                           {m: verdicts[m] for m in methods if m in verdicts}, run.trial.n_frames,
                           run.trajectories.rate_hz, notes, gap_mm, reasons,
                           getattr(amplitude, "path", "") if amplitude is not None else "")
    return comp, recs
