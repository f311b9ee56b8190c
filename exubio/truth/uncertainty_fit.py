"""A lab's own uncertainty model: the STA amplitude model behind every angle's stated uncertainty
(exubio.trust.sta_amplitude), fitted on the lab's bone-referenced trials as the shipped one was
fitted on the S2M pins, for a protocol's ``uncertainty_model:`` key.

Two parts come from the trials (each module says how):
- the skin's artefact: each bone's skin-marker cluster, its rigid rotation and translation and its
  non-rigid rest, per rad of the humerus's rotation from rest (``exubio.truth.sta_amplitude``);
- the model girdle's own error: the model's scapula and humerus frames off the bones with the markers
  carried by the bones, with its covariance with the skin's part, and the offset at rest its spread
  grows from (``exubio.truth.girdle``; LS runs of each trial, the trials whose LS verdict is ``fail``
  left out; the offset needs two usable trials, else the shipped one is kept).

The unseen trunk's motion (what ``exubio truth`` adds where it takes the thorax as still) cannot come
from these files, which hold no thorax: the shipped model's is kept, and the file says so.

How far to trust it is measured on the same trials, one out (``judge``): each trial in turn is left
out of both parts, reconstructed by LS as a lab would (``exubio.truth.compare``), and every ST, GH and
HT angle's error against its bone is compared with the u a lab's run gives with the model of the other
trials (thorax markers assumed: no still-thorax term), over the frames where the angle is measured. An
honest u holds the bone within +-2u in about 95 % of those frames.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import InputError
from ..trust.sta_amplitude import STAAmplitude, shipped_amplitude
from .girdle import GIRDLE_SEGMENTS, GirdleMotion, fit_girdle, girdle_motion, girdle_offset
from .sta_amplitude import fit_sta_amplitude
from .sta_format import BoneTrial, read_sta_trial

__all__ = ["HeldOut", "UncertaintyFit", "fit_uncertainty_model"]


@dataclass(frozen=True)
class HeldOut:
    """One trial judged with the model of the others: its LS verdict, and per ST, GH and HT angle the
    fraction of its measured frames where the bone lies within +-2u and the fraction of frames measured
    (angles measured in no frame left out). ``skipped``: why it could not be judged, or ''."""

    trial: str
    verdict: str
    angles: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    skipped: str = ""
    error_over_u: Mapping[str, float] = field(default_factory=dict)  # per angle, the RMS of error / u
    frames: Mapping[str, tuple[int, int]] = field(default_factory=dict)  # per angle, (within +-2u, judged) frames


@dataclass(frozen=True, eq=False)
class UncertaintyFit:
    """The fitted model and what it was fitted on: each trial's girdle motion (its LS verdict says
    whether the girdle's part used it)."""

    amplitude: STAAmplitude
    girdle: tuple[GirdleMotion, ...]
    held_out: tuple[HeldOut, ...] = ()

    @property
    def girdle_trials(self) -> tuple[str, ...]:
        return tuple(Path(g.file).name for g in self.girdle if g.verdict != "fail")

    def pooled(self) -> dict[str, tuple[int, int, int]]:
        """Per angle, over the judged trials whose LS verdict is not ``fail``: (frames where the bone lies
        within +-2u, frames judged, trials), where any frame was judged: the coverage a 95 % band promises
        over a lab's trials. A trial's frames are not independent draws (the same skin over the same
        motion), so one trial's coverage scatters far more than the pooled frames'."""
        out: dict[str, list[int]] = {}
        for h in self.held_out:
            if h.skipped or h.verdict == "fail":
                continue
            for a, (w, n) in h.frames.items():
                if n:
                    acc = out.setdefault(a, [0, 0, 0])
                    acc[0] += w
                    acc[1] += n
                    acc[2] += 1
        return {a: (w, n, t) for a, (w, n, t) in out.items()}

    def judgement(self) -> dict:
        """``held_out`` as the model file records it (``STAAmplitude.judgement``): per trial its LS verdict,
        why it was not judged, and per angle the coverage of +-2u and the fraction of frames measured; the
        cells counted, below 90 % and above 99 % (empty without a judgement)."""
        if not self.held_out:
            return {}
        cov = [c for h in self.held_out for c, _ in h.angles.values()]
        z = [h.error_over_u[a] for h in self.held_out for a in h.angles if a in h.error_over_u]

        def cell(h, a, c, f):
            out = {"coverage": round(float(c), 4), "measured_fraction": round(float(f), 4)}
            if h.frames.get(a, (0, 0))[1]:
                out["frames"] = int(h.frames[a][1])  # judged: measured, the error finite
            if a in h.error_over_u and np.isfinite(h.error_over_u[a]):
                out["rms_error_over_u"] = round(float(h.error_over_u[a]), 4)
            return out

        pooled = self.pooled()
        return {"method": "each trial left out of both parts, reconstructed by LS with the model of the others; the "
                          "u of a lab's run with thorax markers; over each angle's measured frames (rms_error_over_u: "
                          "about 1 where u is the error's size, below 1 where u is wider); pooled: per angle, the "
                          "measured frames of every trial whose LS verdict is not fail together",
                "cells": len(cov), "below_90": sum(c < 0.90 for c in cov), "above_99": sum(c > 0.99 for c in cov),
                **({"median_rms_error_over_u": round(float(np.nanmedian(z)), 4)} if z else {}),
                **({"pooled": {a: {"coverage": round(w / n, 4), "frames": n, "trials": t}
                               for a, (w, n, t) in pooled.items()},
                    "pooled_below_90": sum(w / n < 0.90 for w, n, _ in pooled.values()),
                    "pooled_above_99": sum(w / n > 0.99 for w, n, _ in pooled.values())} if pooled else {}),
                "trials": {h.trial: {"ls_verdict": h.verdict, **({"skipped": h.skipped} if h.skipped else {}),
                                     "angles": {a: cell(h, a, c, f) for a, (c, f) in h.angles.items()}}
                           for h in self.held_out}}


def fit_uncertainty_model(paths: Sequence[str | Path], /, *, rate_hz: float, generic_model: dict | None = None,
                          source: str = "", judge: bool = False) -> UncertaintyFit:
    """The amplitude and girdle parts (module docstring) fitted on the bone-referenced trials ``paths``
    (ISB STA data-sharing .mat files, all at ``rate_hz``), with the shipped model's trunk; ``judge``:
    also each trial judged with the model of the others (``held_out``; two trials at least). InputError
    naming the file where a trial lacks the scapula or the humerus, or when every trial's LS verdict is
    ``fail``."""
    from ..errors import ModelError
    from ..io.yaml import read_yaml
    from ..model.load import DEFAULT_MODEL

    if not paths:
        raise InputError("no bone-referenced trial given")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"--rate {rate_hz}: expected the trials' sampling rate, a positive number of Hz")
    trials: list[BoneTrial] = []
    for p in paths:
        t = read_sta_trial(p)
        missing = [b for b in GIRDLE_SEGMENTS if b not in t.segments]
        if missing:
            raise InputError(f"{p}: no {' and no '.join(missing)} in the trial (has {', '.join(t.segments)}); the "
                             "uncertainty model needs the scapula and the humerus tracked by bone")
        trials.append(t)
    generic = generic_model if generic_model is not None else read_yaml(DEFAULT_MODEL, error=ModelError)
    names = ", ".join(t.path.name for t in trials)
    amp = fit_sta_amplitude([(t, float(rate_hz)) for t in trials],
                            source=source or f"exubio uncertainty-fit on {names} ({rate_hz:g} Hz)")
    motions = tuple(girdle_motion(t, generic, rate_hz=float(rate_hz)) for t in trials)
    if all(m.verdict == "fail" for m in motions):
        raise InputError(f"{names}: the LS verdict of every trial with its markers carried by the bones is 'fail' (the "
                         "trunk moved, or the model cannot follow the girdle); no girdle error to fit from them")
    amp = _with_girdle(amp, motions, rate_hz)
    held = ()
    if judge and len(trials) > 1:
        held = tuple(_judged(i, trials, motions, rate_hz, generic) for i in range(len(trials)))
    return UncertaintyFit(amp, motions, held)


def _with_girdle(amp: STAAmplitude, motions: Sequence[GirdleMotion], rate_hz: float) -> STAAmplitude:
    """``amp`` with the girdle part fitted on ``motions`` (its offset chosen on them where two are usable,
    else the shipped model's) and the shipped model's trunk."""
    used = [Path(m.file).name for m in motions if m.verdict != "fail"]
    shipped = shipped_amplitude()
    if len(used) >= 2:
        offset = girdle_offset(list(motions))
        how = f"offset {np.degrees(offset):.0f} deg chosen on them, one trial out"
    else:
        offset = shipped.girdle_offset_rad
        how = f"offset {np.degrees(offset):.0f} deg the shipped model's: one usable trial cannot choose it"
    return dataclasses.replace(
        amp, girdle=fit_girdle(list(motions), offset_rad=offset), girdle_offset_rad=offset,
        girdle_source=("exubio.truth.girdle.fit_girdle on " + ", ".join(used) + f" ({rate_hz:g} Hz, LS; trials whose LS "
                       f"verdict is 'fail' with the markers carried by the bones left out; {how})"),
        trunk=shipped.trunk, trunk_nodes=shipped.trunk_nodes, trunk_table=shipped.trunk_table,
        trunk_source=("the shipped model's (bone-referenced files hold no thorax): " + shipped.trunk_source
                      if shipped.has_trunk else ""))


def _judged(i: int, trials: Sequence[BoneTrial], motions: Sequence[GirdleMotion], rate_hz: float, generic: Any) -> HeldOut:
    """Trial i judged with the model of the others (module docstring)."""
    from .compare import compare_bone_trial
    from .lab_run import setup_lab_run

    name = trials[i].path.name
    others = [j for j in range(len(trials)) if j != i]
    try:
        amp = _with_girdle(fit_sta_amplitude([(trials[j], float(rate_hz)) for j in others]),
                           [motions[j] for j in others], rate_hz)
    except InputError as exc:
        return HeldOut(name, "", skipped=f"no model from the other trials: {exc}")
    comp, _ = compare_bone_trial(setup_lab_run(trials[i], generic, rate_hz=float(rate_hz)), methods=("ls",),
                                 amplitude=amp)
    verdict = comp.verdicts.get("ls", "")
    if "ls" not in comp.verdicts or verdict.startswith("failed"):
        return HeldOut(name, verdict, skipped="LS failed")
    return HeldOut(name, verdict, comp.lab_coverage("ls"), error_over_u=comp.lab_error_over_u("ls"),
                   frames=comp.lab_frames_within("ls"))
