"""The trials of the validation study and running PF and LS on them.

Abduction and flexion are the real TRC trials of ``../shared/data/trc`` when the subject
calibration (``exubio.calibration``) and the ``thoracoscapular_9`` protocol are available
(``real_trial``); otherwise simulated trials (``exubio.synth.simulate``) with noise and STA stand in,
and their ``TrialData`` says why. SIER is always simulated.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from exubio.errors import ExubioError, ReconstructionError
from exubio.io.trial import read_trial
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.io.resources import shipped_file
from exubio.synth.simulate import Motion, SimulatedTrial, simulate_trial
from exubio.types import MarkerTargets, Model, Protocol, Reconstruction
from exubio.io.records import decode
from exubio.validation.paths import shared_data_dir
from exubio.validation.results import (
    CalibrationFrames,
    CalibrationResidual,
    CalibrationSummary,
    EllipsoidFit,
    Failed,
    MeanMax,
    TrialData,
)
from exubio.validation.settings import ValidationSettings

log = logging.getLogger(__name__)

__all__ = ["LUDEWIG_PLANE", "PLOT_SAMPLES", "REAL_PROTOCOL", "REAL_TRIALS", "Progress", "Trial", "plot_stride",
           "prepare_trials", "real_trial", "run_method", "simulated", "why_no_real_trial"]

Progress = Callable[[str], None]
"""Receives one line of progress text."""

LUDEWIG_PLANE = {"abduction": "frontal", "flexion": "sagittal"}  # the trials' planes of elevation
PLOT_SAMPLES = 6000  # time series are stored decimated to about this many samples
REAL_TRIALS = {"abduction": "tsm_rmr_ABD01.trc", "flexion": "tsm_rmr_FLX01.trc"}
REAL_PROTOCOL = "thoracoscapular_9.yaml"
SETH_CITATION = ("Seth A, Dong M, Matias R, Delp S (2019) Front Neurorobot 13:90 (CC BY 4.0), "
                 "via ComputationalBiomechanicsLab/rmr-solver")


@dataclass
class Trial:
    """A trial while the study runs: model, protocol, targets, where it comes from (``data``),
    the truth of a simulated one (``sim``), and per method ("pf", "ls") its reconstruction (None
    when it failed, with the message in ``errors``) and wall time (s)."""

    name: str
    model: Model
    protocol: Protocol
    targets: MarkerTargets
    data: TrialData
    sim: SimulatedTrial | None = None
    recon: dict[str, Reconstruction | None] = field(default_factory=dict)
    wall_s: dict[str, float] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)

    def failure(self, method: str) -> Failed:
        """The record of a method that did not run or failed on this trial."""
        return Failed(failed=self.errors.get(method, "not run"))


def plot_stride(n: int) -> int:
    """Decimation step that leaves about PLOT_SAMPLES of ``n`` samples."""
    return max(1, math.ceil(n / PLOT_SAMPLES))


def why_no_real_trial(name: str) -> str | None:
    """Why the real trial ``name`` cannot be used (missing file or module), or None."""
    trc = shared_data_dir() / "trc" / REAL_TRIALS[name]
    missing = []
    if not trc.exists():
        missing.append(f"trial file {trc}")
    if not shipped_file("exubio.protocols", REAL_PROTOCOL, "protocols").exists():
        missing.append(f"protocol {REAL_PROTOCOL}")
    if importlib.util.find_spec("exubio.calibration") is None:
        missing.append("subject calibration module exubio.calibration")
    return ("not available: " + ", ".join(missing)) if missing else None


def _known(cls: type, d: dict[str, Any]) -> dict[str, Any]:
    """The entries of ``d`` that record ``cls`` has fields for."""
    return {f.name: d[f.name] for f in dataclasses.fields(cls)}


def real_trial(name: str) -> tuple[Model, Protocol, MarkerTargets, CalibrationSummary] | None:
    """The real TRC trial ``name`` ("abduction" or "flexion") of ../shared/data/trc with the
    thoracoscapular_9 protocol and the generic model calibrated to the subject on the trial's own
    still frames (exubio.calibration: the TRC trials come without a static trial): (model, protocol,
    targets, calibration summary), or None when ``why_no_real_trial`` names something missing.
    The one function to change when the real data or their calibration change."""
    if why_no_real_trial(name) is not None:
        return None
    from exubio.calibration import calibrate_model, calibrated_protocol

    trc = shared_data_dir() / "trc" / REAL_TRIALS[name]
    protocol_path = shipped_file("exubio.protocols", REAL_PROTOCOL, "protocols")
    model, protocol = load_model_and_protocol(protocol_path=protocol_path)
    traj = read_trial(trc)
    targets = prepare_targets(traj, protocol)  # labels, frame, filter: independent of the model points
    calibrated, report = calibrate_model(model, protocol, traj, targets=targets)
    info = report.to_dict()
    summary = decode(CalibrationSummary, {
        "frames": _known(CalibrationFrames, info["frames"]), "scale_factors": info["scale_factors"],
        "residual_mm": _known(CalibrationResidual, info["residual_mm"]),
        "generic_offset_mm": _known(MeanMax, info["generic_offset_mm"]),
        "ellipsoid": _known(EllipsoidFit, info["ellipsoid"])})
    return calibrated, calibrated_protocol(protocol, calibrated), targets, summary


def simulated(model: Model, protocol: Protocol, motion: Motion, duration_s: float, rate_hz: float,
              s: ValidationSettings, seed: int) -> tuple[SimulatedTrial, MarkerTargets]:
    """A simulated trial with the settings' noise and STA, and its prepared targets."""
    sim = simulate_trial(model, motion, duration_s=duration_s, rate_hz=rate_hz, noise_mm=s.noise_mm,
                         sta_mm=s.sta_mm, seed=seed)
    return sim, prepare_targets(sim.trajectories, protocol)


def prepare_trials(s: ValidationSettings, progress: Progress) -> dict[str, Trial]:
    """Abduction and flexion (real when available and wanted, else simulated) and SIER."""
    model, protocol = load_model_and_protocol()
    trials: dict[str, Trial] = {}
    for k, name in enumerate(("abduction", "flexion")):
        real = "not used in this run (ValidationSettings.real_trials is False)"
        if s.real_trials:
            real = why_no_real_trial(name)
            if real is None:
                progress(f"{name}: calibrating the model to the real trial {REAL_TRIALS[name]}")
                try:
                    got = real_trial(name)
                except ExubioError as exc:
                    got, real = None, f"the real trial could not be prepared: {exc}"
                if got is not None:
                    m, p, tg, cal = got
                    trials[name] = Trial(name, m, p, tg, TrialData(
                        kind="real", source=str(shared_data_dir() / "trc" / REAL_TRIALS[name]),
                        citation=SETH_CITATION, frames=tg.n_frames,
                        rate_hz=float(1.0 / np.median(np.diff(tg.time_s))), protocol=p.name, model=m.name,
                        calibration=cal, markers=tuple(p.marker_names)))
                    continue
        progress(f"{name}: real trial {real}; simulating it")
        sim, tg = simulated(model, protocol, Motion.parse(name), s.trial_duration_s, s.trial_rate_hz, s, s.seed + k)
        trials[name] = Trial(name, model, protocol, tg, TrialData(
            kind="simulated", reason_not_real=real, description=sim.description, frames=tg.n_frames,
            protocol=protocol.name, model=model.name), sim=sim)
    sim, tg = simulated(model, protocol, Motion.SIER, s.sier_duration_s, s.sier_rate_hz, s, s.seed)
    trials["sier"] = Trial("sier", model, protocol, tg, TrialData(
        kind="simulated", description=sim.description, frames=tg.n_frames, protocol=protocol.name,
        model=model.name), sim=sim)
    return trials


def run_method(trial: Trial, method: str, progress: Progress) -> None:
    """Reconstruct ``trial`` with ``method`` ("pf" or "ls") into ``trial.recon``, timing it; a
    ReconstructionError is recorded in ``trial.errors``."""
    progress(f"{trial.name}: {method.upper()} on {trial.targets.n_frames} frames")
    t0 = time.perf_counter()
    try:
        trial.recon[method] = reconstruct(trial.model, trial.protocol, trial.targets, method=method)
    except ReconstructionError as exc:
        trial.recon[method] = None
        trial.errors[method] = str(exc)
        log.warning("%s %s failed: %s", trial.name, method, exc)
    trial.wall_s[method] = time.perf_counter() - t0
