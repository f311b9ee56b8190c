"""What the model's shoulder girdle cannot follow of the bones, measured on bone-referenced trials:
the part of every angle's stated uncertainty beside noise and the skin's artefact
(``exubio.trust.angle_uncertainty.girdle_angle_variance``).

exubio's girdle is a rigid clavicle turning about a sternoclavicular joint fixed in the thorax, a
scapula held on a thorax ellipsoid and hinged to the clavicle at AC, and a humerus about a GH centre
fixed in the scapula. A real girdle is not that chain: a scapula lifts off the thorax as it tilts,
the clavicle's length to the acromion changes, the joint centres move. With skin markers that do not
slide at all, the reconstruction still misses the bones by what the chain cannot do.

That part is measured with no skin in it. A bone trial is set up as ``exubio truth`` sets it up
(``exubio.truth.lab_run``: the subject's own landmarks at rest, a perfect static calibration, the
thorax taken as still), but with each skin marker carried rigidly by its bone from where it sits at
rest (``setup_lab_run(without_sta=True)``), and reconstructed by LS. In every frame the error of the
model's scapula and humerus ISB frames against the bones' is a rotation vector in the model frame's
own axes, g (n, 6: scapula, humerus). Like the artefact's amplitude (``exubio.truth.sta_amplitude``)
it grows with the humerus's rotation from rest, theta (rad; no error at rest by construction).

The girdle's error and the skin's are not independent. The same trial reconstructed from its skin
markers misses the bones by g + s, s the part the skin's sliding adds; on the pins the two partly
cancel (the skin over the scapula slides along the thorax as the model's scapula does on its
ellipsoid, while the bone tilts off it: in the S2M abduction the model's ST posterior tilt is 5.6 deg
RMS off the bone with the markers carried by the bones and 2.2 deg with the skin's). The uncertainty
already carries s through the skin's amplitude model, so what the girdle adds to an angle's variance
is var(g) + 2 cov(g, s) along that angle. Pooled per rad^2 of theta,

    C = sum_t (g g^T + g s^T + s g^T) / sum_t theta^2   (6 x 6, symmetric, not positive definite)

is the model; an angle whose direction e gets e C e^T < 0 (the skin takes back part of the girdle's
error) gets nothing, so u never falls below its skin's and noise's part. C is a lower bound of what a
lab's model misses (the calibration here is perfect) and holds whatever the still thorax cost the
trial; a trial whose LS verdict with the markers carried by the bones is ``fail`` is left out of a
fit (its trunk moved: its errors are not the girdle's).

Fitted on the three standing S2M pin trials of the ISB STA data-sharing sample, it ships in
``exubio/data/sta_amplitude_s2m.json`` (``girdle_second_moment``); ``studies/bone_u_girdle.py``
fits it and judges it one task out and on held-out tasks.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import InputError
from .sta_amplitude import _rotvec
from .sta_format import BoneTrial

__all__ = ["GirdleMotion", "girdle_motion", "fit_girdle", "GIRDLE_SEGMENTS"]

GIRDLE_SEGMENTS = ("scapula", "humerus")


@dataclass(frozen=True, eq=False)
class GirdleMotion:
    """One trial's girdle error: ``xi`` (n, 6) rad, the model's scapula and humerus ISB frames turned
    onto the bones' with the markers carried by the bones (g: rotation vectors in the model frames'
    axes; NaN where a bone is not seen); ``skin`` (n, 6) rad, the same from the skin markers as
    recorded (g + s); ``theta`` (n,) rad, the humerus's rotation from rest; ``verdict``: the LS verdict
    with the markers carried by the bones."""

    file: str
    xi: np.ndarray
    skin: np.ndarray
    theta: np.ndarray
    verdict: str


def _frame_errors(run) -> tuple[np.ndarray, np.ndarray, str]:
    """(xi (n, 6), theta (n,), LS verdict) of one BoneLabRun reconstructed by LS."""
    from ..model.angles import segment_anatomical_rotations
    from ..run.pipeline import assess_inputs, reconstruct
    from ..trust.angle_uncertainty import _driver
    from .compare import lab_inputs

    model, inputs = lab_inputs(run)
    rec = reconstruct(inputs.model, inputs.protocol, inputs.targets, method="ls")
    quality = assess_inputs(inputs, [rec]).quality["ls"]
    kin = inputs.binding.kin
    frames = segment_anatomical_rotations(model, rec.q_rad, kinematics=kin)
    R, _ = kin.poses(rec.q_rad)
    xi = np.concatenate([_rotvec(np.swapaxes(frames[s], 1, 2) @ run.truth[s]) for s in GIRDLE_SEGMENTS], axis=1)
    return xi, _driver([s.name for s in model.segments], R), str(quality.verdict.value)


def girdle_motion(trial: BoneTrial, generic_model: Mapping[str, Any], /, *, rate_hz: float) -> GirdleMotion:
    """The girdle error of one bone trial (module docstring): LS reconstructions of its markers carried
    rigidly by the bones and of its skin markers as recorded."""
    from .lab_run import setup_lab_run

    xi, theta, verdict = _frame_errors(setup_lab_run(trial, generic_model, rate_hz=rate_hz, without_sta=True))
    skin, _, _ = _frame_errors(setup_lab_run(trial, generic_model, rate_hz=rate_hz))
    return GirdleMotion(str(trial.path), xi, skin, theta, verdict)


def fit_girdle(motions: Sequence[GirdleMotion], /) -> np.ndarray:
    """C (6, 6) rad^2 per rad^2 of theta: var(g) + 2 cov(g, s), pooled over the ``motions`` whose LS
    verdict is not ``fail`` (module docstring)."""
    use = [m for m in motions if m.verdict != "fail"]
    if not use:
        raise InputError("fit_girdle: every trial's LS verdict is 'fail' (its trunk moved); no girdle error to fit")
    num, den = np.zeros((6, 6)), 0.0
    for m in use:
        g, s = m.xi, m.skin - m.xi
        ok = np.isfinite(g).all(axis=1) & np.isfinite(s).all(axis=1) & np.isfinite(m.theta)
        gs = g[ok].T @ s[ok]
        num += g[ok].T @ g[ok] + gs + gs.T
        den += float(np.sum(m.theta[ok] ** 2))
    if den <= 0:
        raise InputError("fit_girdle: the humerus never moves from rest in these trials; no girdle error to fit")
    return num / den
