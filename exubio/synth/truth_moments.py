"""The exact joint moments of a simulated trial: ``<stem>.truth_moments.csv``, exubio.dynamics on
the simulation's exact q, q', q'' (analytic signals; the girdle's two solved coordinates by implicit
differentiation of the ellipsoid constraints), with the trial's model, its body mass and the hand
load, and the thorax's exact motion in the lab where the trunk moves (exubio.synth.thorax_lean).
tests/dynamics/test_dynamics_truth.py checks the file against biorbd's inverse dynamics of the same
states on the exported .bioMod, so the truth does not rest on the code it judges."""
from __future__ import annotations

from pathlib import Path

from exubio.dynamics.moments import joint_moments
from exubio.dynamics.moments_file import write_moments_csv
from exubio.synth.simulate import SimulatedTrial

__all__ = ["truth_moments_path", "write_truth_moments"]


def truth_moments_path(path_c3d) -> Path:
    p = Path(path_c3d)
    stem = p.with_suffix("") if p.suffix.lower() == ".c3d" else p
    return stem.with_name(stem.name + ".truth_moments.csv")


def write_truth_moments(trial: SimulatedTrial, path_c3d, /, *, hand_load_kg: float = 0.0) -> Path:
    """Write the exact moments of ``trial`` (its model: lengths and body mass) beside ``path_c3d``."""
    moments = joint_moments(trial.model, trial.q_true, trial.qd_true, trial.qdd_true, time_s=trial.time_s,
                            hand_load_kg=hand_load_kg, thorax=trial.thorax_motion)
    return write_moments_csv(truth_moments_path(path_c3d), moments, comments=(
        "truth: the simulation's exact q, q', q'' (analytic; the girdle's solved coordinates by implicit "
        "differentiation of the ellipsoid constraints)", f"trial: {trial.description}", moments.info["thorax"]))
