"""How well a bone STA model (``exubio.synth.sta_bone``) reproduces trials it was not fitted to:
leave one task out. For each held-out trial and segment, the model fitted on the other trials
predicts the cluster's rigid motion from the held-out trial's drivers; compared with the data:

* rotation (deg): the norm of the rigid rotation vector; translation (mm): of the centroid;
* displacement (mm): each skin marker's displacement in the bone frame from its start position
  (the whole artefact, non-rigid rest included) against the predicted rigid displacement.

For each: the RMS of the data, the RMS of the residual (data - model), and R^2 = 1 - SS_residual /
SS_data, the sums taken about zero (the artefact is defined from the start posture, where it is
zero): the fraction of the artefact the model reproduces. Plus the non-rigid rest's RMS (mm).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from exubio.synth.sta_bone import (DEFAULT_DRIVERS, DEFAULT_RIDGE, RIDGE, ROTATION_COURSE, SegmentData, fit_segment, held_out_residual,
                                   rigid_displacements, segment_data)
from exubio.synth.sta_residual import correlation_time

__all__ = ["HeldOut", "HeldOutAmplitude", "held_out_amplitude", "leave_one_task_out", "score_segment"]


@dataclass(frozen=True)
class HeldOut:
    """One held-out (task, segment): ``stats`` name -> (rms data, rms residual, R^2) for
    'rotation_deg', 'translation_mm', 'displacement_mm'; ``nonrigid_mm`` the rest's RMS per
    coordinate; ``frames``."""

    task: str
    segment: str
    stats: Mapping[str, tuple[float, float, float]]
    nonrigid_mm: float
    frames: int


def _stat(data: np.ndarray, resid: np.ndarray, scale: float) -> tuple[float, float, float]:
    sd = float(np.sum(data * data))
    sr = float(np.sum(resid * resid))
    n = data.shape[0] * (data.shape[1] if data.ndim == 3 else 1)
    return scale * np.sqrt(sd / n), scale * np.sqrt(sr / n), (1.0 - sr / sd) if sd > 0 else float("nan")


def score_segment(seg, d: SegmentData, *, segment: str = "") -> HeldOut:
    """Compare a fitted SegmentSta with one trial's SegmentData."""
    ok = np.isfinite(d.Y).all(axis=1) & np.isfinite(d.X).all(axis=1)
    pred = d.X[ok] @ seg.rigid_coef
    Y = d.Y[ok]
    ref = d.split.reference
    disp_data = rigid_displacements(Y, ref) + d.nonrigid[ok]  # = markers - reference, exactly
    disp_model = rigid_displacements(pred, ref)
    stats = {
        "rotation_deg": _stat(Y[:, :3], Y[:, :3] - pred[:, :3], float(np.degrees(1.0))),
        "translation_mm": _stat(Y[:, 3:], Y[:, 3:] - pred[:, 3:], 1e3),
        "displacement_mm": _stat(disp_data, disp_data - disp_model, 1e3),
    }
    nr = d.nonrigid[ok]
    return HeldOut(d.task, segment, stats, float(1e3 * np.sqrt(np.mean(nr * nr))), int(ok.sum()))


def leave_one_task_out(paths: Sequence[str | Path], /, *, rate_hz: float,
                       drivers: Mapping[str, Sequence[str]] | None = None,
                       ridge: float | Mapping[str, float] | None = None) -> list[HeldOut]:
    """For each trial of ``paths`` and each segment: fit on the others, score on it (``drivers``
    and ``ridge`` as in ``fit_sta_model``)."""
    from exubio.truth.sta_format import read_sta_trial

    drivers = dict(DEFAULT_DRIVERS if drivers is None else drivers)
    trials = [read_sta_trial(p) for p in paths]
    out = []
    for s, drv in drivers.items():
        data = [segment_data(t, s, drv, rate_hz=rate_hz) for t in trials]
        for i, held in enumerate(data):
            r = ridge.get(s, RIDGE) if isinstance(ridge, Mapping) else (DEFAULT_RIDGE.get(s, RIDGE) if ridge is None else ridge)
            seg = fit_segment([d for j, d in enumerate(data) if j != i], drv, ridge=r,
                              rotation_course=ROTATION_COURSE.get(s, True))
            out.append(score_segment(seg, held, segment=s))
    return out


def score_other(seg_models: Mapping, trial, *, rate_hz: float, n_reference: int | None = None) -> list[HeldOut]:
    """Score a fitted model's segments on another subject's trial (e.g. ARTANIM with the S2M model;
    ``n_reference``: its start posture in frames, where the calibration window does not fit)."""
    return [score_segment(m, segment_data(trial, s, m.drivers, rate_hz=rate_hz, n_reference=n_reference), segment=s)
            for s, m in seg_models.items() if s in trial.segments]


@dataclass(frozen=True)
class HeldOutAmplitude:
    """One held-out (task, segment): RMS of the cluster's rotation (deg, norm of the rotation
    vector) and of its centroid's translation (mm, norm), for the data, the regression's mean course
    alone and the simulated artefact (mean course + residual draws, pooled over the seeds); the
    residual's correlation time (s) in the data and in the draws (mean)."""

    task: str
    segment: str
    rotation_deg: tuple[float, float, float]
    translation_mm: tuple[float, float, float]
    correlation_s: tuple[float, float]


def _rms_norm(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x * x, axis=-1))))


def held_out_amplitude(paths: Sequence[str | Path], /, *, rate_hz: float, seeds: int = 20) -> list[HeldOutAmplitude]:
    """For each S2M-like trial and segment: the model built on the OTHER trials as ``fit_sta_model``
    builds it (the regression, and its residual process measured by leave one out among them),
    driven by the held-out trial's own drivers; its simulated artefact against the trial's
    (``seeds`` draws of the residual, seeds 1..seeds)."""
    from exubio.truth.sta_format import read_sta_trial

    trials = [read_sta_trial(p) for p in paths]
    if len(trials) < 3:
        raise ValueError("a held-out amplitude needs at least three trials (two to measure the residual on)")
    out = []
    for s, drv in DEFAULT_DRIVERS.items():
        ridge = DEFAULT_RIDGE.get(s, RIDGE)
        data = [segment_data(t, s, drv, rate_hz=rate_hz) for t in trials]
        for i, held in enumerate(data):
            rest = [d for j, d in enumerate(data) if j != i]
            kw = dict(ridge=ridge, rotation_course=ROTATION_COURSE.get(s, True))
            seg = fit_segment(rest, drv, **kw)
            proc = held_out_residual(rest, drv, **kw)
            ok = np.isfinite(held.Y).all(axis=1) & np.isfinite(held.X).all(axis=1)
            pred = held.X[ok] @ seg.rigid_coef
            Y = held.Y[ok]
            draws = [pred + proc.draw(held.theta[ok], rate_hz, np.random.default_rng(k)) for k in range(1, seeds + 1)]
            sim = np.concatenate(draws)
            out.append(HeldOutAmplitude(
                held.task, s,
                tuple(float(np.degrees(_rms_norm(a[:, :3]))) for a in (Y, pred, sim)),
                tuple(1e3 * _rms_norm(a[:, 3:]) for a in (Y, pred, sim)),
                (correlation_time([Y - pred], rate_hz),
                 float(np.mean([correlation_time([d - pred], rate_hz) for d in draws])))))
    return out
