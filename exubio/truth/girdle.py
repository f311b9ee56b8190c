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
it grows with the humerus's rotation from rest, theta (rad), but not from zero: the calibration's
frames are the bones' by construction, yet wherever else the arm hangs near rest the scapula is
already off the model's by a few degrees (it protracts in an adduction or a reach, shrugs in eating,
while the humerus has barely turned: on the pins 1-2.5 deg RMS about the scapula's Y axis with theta
under 10 deg, 2.5-6 deg at 10-20 deg). Its spread is taken as growing with theta + theta_0: theta_0
(``girdle_offset``) is the offset under which the error's own spread is best predicted on a trial
left out, each trial in turn (the mean Gaussian log-likelihood per frame of g per axis, over a grid
of 5 deg steps); on the three standing S2M pin trials 35 deg (with no offset, every trial's
held-out likelihood is far lower: the frames near rest are off the model by far more than theta^2
allows; ``studies/bone_u_girdle.py`` prints the table).

The girdle's error and the skin's are not independent. The same trial reconstructed from its skin
markers misses the bones by g + s, s the part the skin's sliding adds; on the pins the two partly
cancel (the skin over the scapula slides along the thorax as the model's scapula does on its
ellipsoid, while the bone tilts off it: in the S2M abduction the model's ST posterior tilt is 5.6 deg
RMS off the bone with the markers carried by the bones and 2.2 deg with the skin's). The uncertainty
already carries s through the skin's amplitude model, so what the girdle adds to an angle's variance
is var(g) + 2 cov(g, s) along that angle. Pooled per rad^2 of theta,

    C = sum_t (g g^T + g s^T + s g^T) / sum_t theta^2   (6 x 6, symmetric, not positive definite)

with theta + theta_0 in place of theta, is the model; an angle whose direction e gets e C e^T < 0 (the
skin takes back part of the girdle's error) gets nothing, so u never falls below its skin's and
noise's part. C is a lower bound of what a lab's model misses (the calibration here is perfect) and
holds whatever the still thorax cost the trial; a trial whose LS verdict with the markers carried by
the bones is ``fail`` is left out of a fit (its trunk moved: its errors are not the girdle's).

Fitted on the three standing S2M pin trials of the ISB STA data-sharing sample, it ships in
``exubio/data/sta_amplitude_s2m.json`` (``girdle_second_moment``, ``girdle_driver_offset_rad``); ``studies/bone_u_girdle.py``
fits it and judges it one task out and on held-out tasks.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import InputError
from .sta_amplitude import _rotvec
from .sta_format import BoneTrial

__all__ = ["GirdleMotion", "girdle_motion", "fit_girdle", "girdle_offset", "offset_likelihoods", "GIRDLE_SEGMENTS",
           "OFFSET_GRID_DEG"]

GIRDLE_SEGMENTS = ("scapula", "humerus")
OFFSET_GRID_DEG = tuple(range(0, 95, 5))
"""The offsets theta_0 (deg) ``girdle_offset`` chooses from."""


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


def _usable(motions: Sequence[GirdleMotion], what: str) -> list[GirdleMotion]:
    use = [m for m in motions if m.verdict != "fail"]
    if not use:
        raise InputError(f"{what}: every trial's LS verdict is 'fail' (its trunk moved); no girdle error to fit")
    return use


def _finite(m: GirdleMotion) -> np.ndarray:
    return np.isfinite(m.xi).all(axis=1) & np.isfinite(m.skin).all(axis=1) & np.isfinite(m.theta)


def fit_girdle(motions: Sequence[GirdleMotion], /, *, offset_rad: float = 0.0) -> np.ndarray:
    """C (6, 6) rad^2 per rad^2 of theta + ``offset_rad``: var(g) + 2 cov(g, s), pooled over the
    ``motions`` whose LS verdict is not ``fail`` (module docstring)."""
    num, den = np.zeros((6, 6)), 0.0
    for m in _usable(motions, "fit_girdle"):
        ok = _finite(m)
        g, s = m.xi[ok], m.skin[ok] - m.xi[ok]
        gs = g.T @ s
        num += g.T @ g + gs + gs.T
        den += float(np.sum((m.theta[ok] + offset_rad) ** 2))
    if den <= 0:
        raise InputError("fit_girdle: the humerus never moves from rest in these trials; no girdle error to fit")
    return num / den


def offset_likelihoods(motions: Sequence[GirdleMotion], /) -> dict[float, float]:
    """Offset theta_0 (deg, ``OFFSET_GRID_DEG``) -> the mean over the usable ``motions`` (LS verdict not
    ``fail``; two at least) of the mean Gaussian log-likelihood per frame of each one's girdle error g,
    per axis, under the spread var_axis (theta + theta_0)^2 fitted on the others (module docstring)."""
    use = _usable(motions, "girdle_offset")
    if len(use) < 2:
        raise InputError("girdle_offset: one usable trial; the offset is judged on a trial left out (two at least)")
    data = [(m.xi[ok], m.theta[ok]) for m in use for ok in (_finite(m),)]
    out = {}
    for deg in OFFSET_GRID_DEG:
        t0 = np.radians(deg)
        lik = []
        for i, (g, th) in enumerate(data):
            others = [d for j, d in enumerate(data) if j != i]
            var = sum(np.sum(x ** 2, axis=0) for x, _ in others) / sum(np.sum((t + t0) ** 2) for _, t in others)
            spread = th + t0 > 1e-9  # (a frame of no spread, theta at rest with no offset, is no Gaussian)
            v = np.outer((th[spread] + t0) ** 2, var)
            g = g[spread]
            with np.errstate(divide="ignore", invalid="ignore"):
                lik.append(float(np.mean(np.sum(-0.5 * (g ** 2 / v + np.log(2 * np.pi * v)), axis=1))))
        out[float(deg)] = float(np.mean(lik)) if np.all(np.isfinite(lik)) else -np.inf
    return out


def girdle_offset(motions: Sequence[GirdleMotion], /) -> float:
    """theta_0 (rad): the offset of ``OFFSET_GRID_DEG`` whose held-out likelihood (``offset_likelihoods``)
    is highest (the smaller one on a tie)."""
    lik = offset_likelihoods(motions)
    return float(np.radians(max(lik, key=lambda d: (lik[d], -d))))
