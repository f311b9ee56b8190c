"""PF's time base (exubio.methods.pf): the integration step the backend takes for the step asked
for, and the lead-in, the targets extrapolated backwards from the first frame so that the run
starts before it (see exubio.methods.pf's docstring for why)."""
from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np

from exubio.types import MarkerTargets

__all__ = ["LEAD_IN_MAX_BEND_M", "integration_step", "lead_in_frames", "lead_in_run", "with_lead_in"]

log = logging.getLogger("exubio.methods.pf")


def integration_step(frame_dt_s: float, step_s: float | None, cutoff_hz: float | None = None, /) -> float:
    """The step the backend takes for a requested ``step_s`` (see PFOptions).

    At least a frame: the whole number of frames closest below step_s (at least one), but only
    when the targets are low-pass filtered to cutoff_hz <= 1 / (4 step) -- the springs then see
    one frame per step, and that frame must carry everything the skipped ones did; unfiltered or
    wide-band targets get one step per frame. Below a frame: the frame period divided by the
    whole number of steps that keeps it <= step_s. None: one step per frame."""
    if step_s is None:
        return frame_dt_s
    if not step_s > 0:
        raise ValueError(f"PFOptions.step_s must be > 0 s, got {step_s}")
    if step_s < frame_dt_s * (1 - 1e-9):
        return frame_dt_s / math.ceil(frame_dt_s / step_s - 1e-9)
    per = max(int(math.floor(step_s / frame_dt_s + 1e-9)), 1)
    while per > 1 and not (cutoff_hz is not None and cutoff_hz <= 1.0 / (4.0 * per * frame_dt_s)):
        per -= 1
    return per * frame_dt_s


LEAD_IN_MAX_BEND_M = 0.05
"""The lead-in extrapolates quadratically unless that bends a marker's path by more than this
from the straight line over the lead-in (a_0 T^2 / 2: 50 mm at 0.1 s is 10 m/s^2 at the first
frame, an edge spike of the splines rather than arm motion; the validation's trials bend 4-11 mm);
then linearly."""


def lead_in_frames(lead_in_s: float, frame_dt_s: float, step_s: float, /) -> int:
    """Frames of lead-in for ``lead_in_s``: a whole number of steps (at least one when
    lead_in_s > 0), so that the first frame is a step end."""
    if not lead_in_s > 0:
        return 0
    per = max(int(round(step_s / frame_dt_s)), 1)  # frames per step (1 with sub-steps)
    steps = max(int(math.ceil(lead_in_s / (per * frame_dt_s) - 1e-9)), 1)
    return steps * per


def with_lead_in(targets: MarkerTargets, lead: int, frame_dt_s: float, /) -> MarkerTargets:
    """``targets`` with ``lead`` frames before the first, extrapolated backwards from it:
    r(t) = r_0 + v_0 t + a_0 t^2 / 2, v(t) = v_0 + a_0 t, a(t) = a_0 (t < 0; the first frame's
    spline values; a marker missing there is missing in the lead-in)."""
    if lead <= 0:
        return targets
    t, pos, vel, acc = _lead_in(targets, lead, frame_dt_s)
    return dataclasses.replace(
        targets, time_s=np.concatenate([t, targets.time_s]),
        positions_m=np.concatenate([pos, targets.positions_m]), velocities_m_s=np.concatenate([vel, targets.velocities_m_s]),
        accelerations_m_s2=np.concatenate([acc, targets.accelerations_m_s2]), gaps=())


def lead_in_run(targets: MarkerTargets, lead: int, frame_dt_s: float, /
                ) -> tuple[MarkerTargets, np.ndarray, np.ndarray]:
    """What a PF run with ``lead`` frames of lead-in reads (the values of :func:`with_lead_in`,
    without its whole-trial copies, which the run does not need): (the lead-in and the trial's
    first frame as targets: the start, pf_setup; the lead-in's positions and velocities (lead, k,
    3): the springs before the trial's own, PFSystem.run's ``lead_in``)."""
    if lead <= 0:
        return targets, targets.positions_m[:0], targets.velocities_m_s[:0]
    t, pos, vel, acc = _lead_in(targets, lead, frame_dt_s)
    start = dataclasses.replace(
        targets, time_s=np.concatenate([t, targets.time_s[:1]]), positions_m=np.concatenate([pos, targets.positions_m[:1]]),
        velocities_m_s=np.concatenate([vel, targets.velocities_m_s[:1]]),
        accelerations_m_s2=np.concatenate([acc, targets.accelerations_m_s2[:1]]), gaps=())
    return start, pos, vel


def _lead_in(targets: MarkerTargets, lead: int, frame_dt_s: float, /) -> tuple[np.ndarray, ...]:
    """The lead-in's times, positions, velocities and accelerations (see with_lead_in)."""
    t = (np.arange(-lead, 0) * frame_dt_s)[:, None, None]
    p0, v0, a0 = (np.nan_to_num(x[:1]) for x in (targets.positions_m, targets.velocities_m_s,
                                                 targets.accelerations_m_s2))
    missing = ~targets.present[:1, :, None]
    bend = 0.5 * float(np.linalg.norm(np.where(missing, 0.0, a0), axis=-1).max()) * float(t[0, 0, 0]) ** 2
    if bend > LEAD_IN_MAX_BEND_M:  # an edge acceleration of the splines (noise), not motion: extrapolate linearly
        log.info("%s: PF lead-in extrapolated linearly (the first frame's accelerations would bend it by %.0f mm)",
                 targets.source or "trial", bend * 1000)
        a0 = np.zeros_like(a0)
    pos = np.where(missing, np.nan, p0 + v0 * t + 0.5 * a0 * t**2)
    vel = np.where(missing, np.nan, v0 + a0 * t)
    acc = np.where(missing, np.nan, np.broadcast_to(a0, pos.shape))
    return targets.time_s[0] + t[:, 0, 0], pos, vel, acc
