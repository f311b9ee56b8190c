"""Leave-postures-out evaluation of the scapula calibrations against the locator
(``exubio.truth.locator``): per participant and calibration, for every static posture the
calibration did not use, the distance of each corrected landmark from the locator and the angle
between their ISB scapula frames; and the summaries (median, max) per posture group.

A posture is the trial name without its repeat (``flex_90_avant``): a calibration at
``flex_45_1`` leaves out ``flex_45_2`` too (the same posture again is no test of carrying the
correction to another posture). Postures left out by every calibration of the participant are
``common`` (for a participant every calibration could run on): the like-with-like comparison.
A trial whose locator is displaced (``exubio.truth.locator.locator_displaced``) is left out, and said.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from exubio.truth.locator import (LANDMARKS, RECOMMENDED_ELEVATIONS, RECOMMENDED_PLANE, Frame, LocatorData,
                                  LocatorTrial, Posture, Side, System, apply_calibration, calibrate,
                                  calibration_trials, locator_displaced, orientation_error)

__all__ = ["COMMON", "METHODS", "RECOMMENDED", "Evaluation", "Method", "PostureResult", "Summary", "evaluate",
           "posture_group", "summarize"]

COMMON = "common held-out"  # the group name of the summary over the postures every calibration left out


@dataclass(frozen=True)
class Method:
    """A calibration as a lab would run it: whose landmarks it corrects, at which nominal
    elevations of the calibration plane (``()``: none, the landmarks as they are; ``("all",)``:
    every plain elevation the participant has), in which tracked frame."""

    name: str
    tracked: System
    elevations: tuple[str, ...] = ()
    frame: Frame = Frame.ISB


METHODS = (
    Method("skin", System.SKIN),
    Method("cluster", System.CLUSTER),
    Method("skin single 45", System.SKIN, ("45",)),
    Method("skin double 45+120", System.SKIN, RECOMMENDED_ELEVATIONS),
    Method("skin multiple", System.SKIN, ("all",)),
    Method("skin registration single 45", System.SKIN, ("45",), Frame.REGISTRATION),
    Method("skin registration double 45+120", System.SKIN, ("45", "120"), Frame.REGISTRATION),
    Method("cluster single 45", System.CLUSTER, ("45",)),
    Method("cluster double 45+120", System.CLUSTER, ("45", "120")),
)
RECOMMENDED = METHODS[3]
assert RECOMMENDED.tracked is System.SKIN and RECOMMENDED.elevations == RECOMMENDED_ELEVATIONS


@dataclass(frozen=True)
class PostureResult:
    """One held-out trial under one calibration: distance_m (AA, TS, AI) of the corrected from the
    locator's landmarks, orientation_rad between their ISB frames; NaN where the file lacks a
    landmark. common: every calibration ran for the participant and none used this posture."""

    participant: str
    method: str
    file: str
    group: str
    distance_m: tuple[float, float, float]
    orientation_rad: float
    common: bool


@dataclass(frozen=True)
class Evaluation:
    """The evaluation of a locator file. calibrated_on: (participant, method, the calibration
    trials' files); notes: what could not be evaluated and why (a calibration that lacks its
    postures, a landmark missing from the file)."""

    source: str
    plane: str
    side: Side
    methods: tuple[Method, ...]
    results: tuple[PostureResult, ...]
    calibrated_on: tuple[tuple[str, str, tuple[str, ...]], ...]
    notes: tuple[str, ...]


@dataclass(frozen=True)
class Summary:
    """Median and max over n held-out trials (n_finite per landmark and for the orientation)."""

    participant: str
    method: str
    group: str
    n: int
    median_m: tuple[float, float, float]
    max_m: tuple[float, float, float]
    median_orientation_rad: float
    max_orientation_rad: float
    n_finite: tuple[int, int, int, int]


def posture_group(posture: Posture, /) -> str:
    """``abd 45`` ... ``flex 150/max``; flexion 90 forward/back: ``flex 90 fwd/back``."""
    if posture.variant:
        return f"{posture.plane} {posture.elevation} fwd/back"
    if posture.elevation in ("150", "max"):
        return f"{posture.plane} 150/max"
    return f"{posture.plane} {posture.elevation}"


def evaluate(data: LocatorData, /, *, methods: Sequence[Method] = METHODS, plane: str = RECOMMENDED_PLANE,
             side: Side = "left") -> Evaluation:
    """Every method on every participant of ``data``, calibrated on the statics of ``plane`` it
    names, judged on every other posture."""
    results: list[PostureResult] = []
    calibrated_on: list[tuple[str, str, tuple[str, ...]]] = []
    notes: list[str] = []
    for participant in data.participants:
        trials = []
        for t in data.of(participant):
            why = locator_displaced(t)
            if why:
                notes.append(f"{participant} {t.posture.file}: left out: {why}")
            else:
                trials.append(t)
        runs: list[tuple[Method, object, set[str]]] = []
        for method in methods:
            if not method.elevations:
                runs.append((method, None, set()))
                continue
            chosen, absent = calibration_trials(trials, plane=plane, elevations=method.elevations,
                                                tracked=method.tracked)
            if absent or not chosen:
                what = ", ".join(absent) if absent else f"{plane} static"
                notes.append(f"{participant}: {method.name} not run: no {what} with all three landmarks of the "
                             f"locator and the {method.tracked.value}")
                continue
            cal = calibrate(chosen, tracked=method.tracked, frame=method.frame, side=side)
            runs.append((method, cal, {t.posture.name for t in chosen}))
            calibrated_on.append((participant, method.name, tuple(t.posture.file for t in chosen)))
        used_by_any = set().union(*(used for _, _, used in runs)) if runs else set()
        all_ran = len(runs) == len(methods)  # else no posture is common: the comparison would not be like with like
        for method, cal, used in runs:
            held = [t for t in trials if t.posture.name not in used]
            if not held:
                notes.append(f"{participant}: {method.name}: every posture was a calibration posture")
                continue
            results += _judge(participant, method, cal, held, used_by_any if all_ran else None, side)
        for t in trials:
            for system in System:
                missing = [lm for lm, row in zip(LANDMARKS, t.positions_m[system]) if not np.isfinite(row).all()]
                if missing:
                    notes.append(f"{participant} {t.posture.file}: no {system.value} {', '.join(missing)} in the "
                                 f"file: not evaluated there for the calibrations of the {system.value}"
                                 if system is not System.LOCATOR else
                                 f"{participant} {t.posture.file}: no locator {', '.join(missing)}: no truth there")
    return Evaluation(data.source, plane, side, tuple(methods), tuple(results), tuple(calibrated_on), tuple(notes))


def _judge(participant: str, method: Method, cal, held: list[LocatorTrial], used_by_any: set[str] | None,
           side: Side) -> list[PostureResult]:
    tracked = np.stack([t.positions_m[method.tracked] for t in held])
    truth = np.stack([t.positions_m[System.LOCATOR] for t in held])
    corrected = tracked if cal is None else apply_calibration(cal, tracked)
    dist = np.linalg.norm(corrected - truth, axis=-1)
    ori = orientation_error(corrected, truth, side=side)
    return [PostureResult(participant, method.name, t.posture.file, posture_group(t.posture),
                          tuple(float(v) for v in dist[i]), float(ori[i]), used_by_any is not None and t.posture.name not in used_by_any)
            for i, t in enumerate(held)]


def summarize(evaluation: Evaluation, /, *, by_group: bool = True, pooled: bool = True) -> tuple[Summary, ...]:
    """Median and max per participant, method and posture group (``by_group``), and over the
    common held-out postures (group ``COMMON``); with ``pooled``, the same over all participants
    (participant ``all``)."""
    keys: dict[tuple[str, str, str], list[PostureResult]] = {}
    for r in evaluation.results:
        who = [r.participant] + (["all"] if pooled else [])
        groups = ([r.group] if by_group else []) + ([COMMON] if r.common else [])
        for p in who:
            for g in groups:
                keys.setdefault((p, r.method, g), []).append(r)
    order_p = {p: i for i, p in enumerate(dict.fromkeys([r.participant for r in evaluation.results] + ["all"]))}
    order_m = {m.name: i for i, m in enumerate(evaluation.methods)}
    out = []
    for (p, m, g), rs in sorted(keys.items(), key=lambda kv: (order_p[kv[0][0]], order_m[kv[0][1]],
                                                              kv[0][2] == COMMON, _group_order(kv[0][2]))):
        d = np.array([r.distance_m for r in rs])
        o = np.array([r.orientation_rad for r in rs])
        out.append(Summary(p, m, g, len(rs), _stat(np.nanmedian, d), _stat(np.nanmax, d),
                           _nan_or(np.nanmedian, o), _nan_or(np.nanmax, o),
                           (*(int(np.isfinite(d[:, j]).sum()) for j in range(3)), int(np.isfinite(o).sum()))))
    return tuple(out)


def _group_order(group: str) -> tuple:
    plane, _, rest = group.partition(" ")
    elev = rest.split(" ")[0].split("/")[0]
    return (plane, math.inf if not elev.isdigit() else float(elev), rest)


def _nan_or(f, x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(f(x)) if x.size else math.nan


def _stat(f, d: np.ndarray) -> tuple[float, float, float]:
    return tuple(_nan_or(f, d[:, j]) for j in range(3))  # type: ignore[return-value]
