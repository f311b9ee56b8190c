"""Are the thorax landmarks labelled right? Checked before the thorax frame is built from them.

Every other check and both methods work in the ISB thorax frame built from the thorax landmarks
(IJ, PX, C7, T8, or IJ with the midpoints IJ-C7 and PX-T8): two of them exchanged (a manubrium and
a xiphoid marker swapped) turn the frame upside down or inside out, and what fails then (PF
diverging, LS residuals of 70 mm over every girdle marker) names everything but the thorax.

The check: the median distances over the trial between the thorax landmarks, and from each to the
markers of the clavicle (or, without any, of the scapula), compared with the same distances on the
generic model in its reference posture (scaled by one factor, 0.7-1.4), for every assignment of
the trial's thorax labels to the landmarks. When another assignment fits better than the file's by
``SWAP_RATIO``, the file's labels are refused with the assignment that fits and its evidence:
nothing downstream can be right until they are fixed. Pure numpy.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import Kinematics
from exubio.protocol.labels import resolve_labels
from exubio.types import Model, Protocol, Trajectories

__all__ = ["SWAP_RATIO", "ThoraxLabels", "check_thorax_labels", "thorax_label_fit"]

SWAP_RATIO = 1.5
"""Measured on the 10 real trials of ../shared/data (``python studies/thorax_labels.py``): as
labelled, the file's labels are the best assignment on every trial (7.5-29.3 mm RMS: the generic
thorax is not the subject's), the next one 1.62-1.87 times worse; with any two landmarks exchanged
(54 cases: 6 pairs on 8 C3D trials, 3 on 2 TRC trials) the file's labels fit 1.62-8.66 times worse
than the assignment that undoes the exchange (the weakest: XYP with C7 or T10): all refused."""

_MODEL_POINT = {"ij": ("IJ",), "px": ("PX",), "c7": ("C7",), "t8": ("T8",),
                "ij_c7_midpoint": ("IJ", "C7"), "px_t8_midpoint": ("PX", "T8")}


@dataclass(frozen=True)
class ThoraxLabels:
    """keys: the thorax-frame keys (ij, px, ...); labels: the file's label of each; best: the labels
    in the order that fits the model best; rms_mm: fit of the file's labels; best_rms_mm: of the best."""

    keys: tuple[str, ...]
    labels: tuple[str, ...]
    best: tuple[str, ...]
    rms_mm: float
    best_rms_mm: float

    @property
    def swapped(self) -> bool:
        return self.best != self.labels and self.rms_mm > SWAP_RATIO * self.best_rms_mm

    def relabel(self) -> dict[str, str]:
        """The relabel (file label -> read as) that gives the best assignment."""
        return {b: a for a, b in zip(self.labels, self.best) if a != b}


def _model_positions(model: Model, protocol: Protocol, keys, refs) -> np.ndarray:
    kin = Kinematics(model)
    R, p = kin.poses(np.zeros(model.n_coordinates))
    glob: dict[str, np.ndarray] = {}
    for seg in model.segments:
        i = model.segment_index(seg.name)
        for name, local in seg.points.items():
            glob.setdefault(name, p[i] + R[i] @ np.asarray(local, dtype=float))
    frame = protocol.thorax_frame
    out = []
    for k in keys:
        label = getattr(frame, k)
        names = (label,) if label in glob and k in ("ij", "px", "c7", "t8") else _MODEL_POINT[k]
        if any(n not in glob for n in names):
            return np.zeros((0, 3))
        out.append(np.mean([glob[n] for n in names], axis=0))
    for m in refs:
        seg = model.segment(m.segment)
        i = model.segment_index(m.segment)
        out.append(p[i] + R[i] @ np.asarray(m.local_position_m, dtype=float))
        del seg
    return np.array(out)


BLOCK_FRAMES = 8192
"""Frames whose landmark distances are computed together (their differences: ~1 kB a frame)."""


def thorax_label_fit(traj: Trajectories, protocol: Protocol, model: Model, /) -> ThoraxLabels | None:
    """The fit of every assignment of the trial's thorax labels (None: an identity thorax frame,
    or landmarks the model lacks)."""
    frame = protocol.thorax_frame
    if frame.is_identity:
        return None
    match = resolve_labels(protocol, traj.labels, source=traj.source)
    keys = frame.keys
    refs = [m for m in protocol.markers if m.segment == "clavicle" and match.columns.get(m.name) is not None]
    if not refs:
        refs = [m for m in protocol.markers if m.segment == "scapula" and match.columns.get(m.name) is not None]
    M = _model_positions(model, protocol, keys, refs)
    if M.shape[0] == 0:
        return None
    cols = [match.thorax_columns[k] for k in keys] + [match.columns[m.name] for m in refs]
    P = traj.positions_m[:, cols]
    dist = np.empty((P.shape[0], len(cols), len(cols)))
    for a in range(0, P.shape[0], BLOCK_FRAMES):  # a block at a time: no (frames, n, n, 3) array of a long trial
        Q = P[a:a + BLOCK_FRAMES]
        dist[a:a + BLOCK_FRAMES] = np.linalg.norm(Q[:, :, None] - Q[:, None], axis=-1)
    with np.errstate(invalid="ignore"):
        D = np.nanmedian(dist, axis=0)
    DM = np.linalg.norm(M[:, None] - M[None], axis=-1)
    nk, n = len(keys), len(cols)
    pairs = [(i, j) for i in range(nk) for j in range(i + 1, n)]
    m = np.array([DM[i, j] for i, j in pairs])
    costs = {}
    for perm in itertools.permutations(range(nk)):
        idx = list(perm) + list(range(nk, n))
        d = np.array([D[idx[i], idx[j]] for i, j in pairs])
        ok = np.isfinite(d)
        if ok.sum() < nk:
            return None
        s = float(np.clip((d[ok] @ m[ok]) / (m[ok] @ m[ok]), 0.7, 1.4))
        costs[perm] = float(np.sqrt(np.mean((d[ok] - s * m[ok]) ** 2)) * 1000)
    identity = tuple(range(nk))
    best = min(costs, key=costs.get)
    labels = tuple(getattr(frame, k) for k in keys)
    return ThoraxLabels(keys, labels, tuple(labels[i] for i in best), costs[identity], costs[best])


def check_thorax_labels(traj: Trajectories, protocol: Protocol, model: Model, /) -> ThoraxLabels | None:
    """Refuse (InputError naming the file, the labels and the fix) a trial whose thorax landmarks
    look exchanged; else the fit (None where it cannot be judged)."""
    fit = thorax_label_fit(traj, protocol, model)
    if fit is not None and fit.swapped:
        relabel = ", ".join(f"{a}: {b}" for a, b in fit.relabel().items())
        where = ", ".join(f"{k} = {lab}" for k, lab in zip(fit.keys, fit.labels))
        raise InputError(
            f"{traj.source or 'trial'}: the thorax landmarks look mislabelled ({where}): read as "
            f"{', '.join(fit.best)} they fit the model's thorax with {fit.best_rms_mm:.0f} mm RMS, as labelled with "
            f"{fit.rms_mm:.0f} mm; the thorax frame would be wrong and every angle with it. Fix the labels in the "
            f"file, or add `relabel: {{{relabel}}}` to the protocol (or --relabel {','.join(f'{a}={b}' for a, b in fit.relabel().items())})")
    return fit
