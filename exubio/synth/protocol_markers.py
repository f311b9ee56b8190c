"""A simulated trial's markers as a protocol places them (``exubio simulate --protocol NAME``): each
tracked marker at its protocol position on its segment, the thorax landmarks at the model's IJ, PX,
C7 and T8 (or the model point the label names, such as T10, or the midpoints), under the
protocol's labels. A ``side: left`` protocol gets the mirror image of the simulated right arm
through the thorax's sagittal plane (ISB Z -> -Z), so one trial carries both arms and each arm's
true angles, with the right arm's signs, are the trial's truth."""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from exubio.errors import InputError
from exubio.protocol.bind import tracked_points
from exubio.model.kinematics import Kinematics
from exubio.types import Protocol

__all__ = ["with_protocol_markers"]

_LANDMARK_POINT = {"ij": "IJ", "px": "PX", "c7": "C7", "t8": "T8"}


def _thorax_positions(model, protocol: Protocol) -> dict[str, np.ndarray]:
    """Thorax-frame label -> its position (m) in the thorax segment frame."""
    points = {k: np.asarray(v, dtype=float) for k, v in model.segments[0].points.items()}
    frame = protocol.thorax_frame
    out = {}
    for key in frame.keys:
        label = getattr(frame, key)
        if label in points:
            out[label] = points[label]
        elif key in _LANDMARK_POINT:
            out[label] = points[_LANDMARK_POINT[key]]
        elif key == "ij_c7_midpoint":
            out[label] = (points["IJ"] + points["C7"]) / 2.0
        else:
            out[label] = (points["PX"] + points["T8"]) / 2.0
    return out


def with_protocol_markers(trial, protocols: Sequence[Protocol], /, *, noise_mm: float = 0.0, seed: int = 0):
    """``trial`` (exubio.synth.simulate.SimulatedTrial) with its markers replaced by the markers of
    ``protocols`` (one per arm), noise-free or with Gaussian noise of SD ``noise_mm`` per coordinate.
    Its soft-tissue artefact is not carried over: refused when the trial has one."""
    if np.any(trial.sta_m):
        raise InputError("a protocol's markers are simulated without soft-tissue artefact; give --sta-mm 0")
    sides = [p.side for p in protocols]
    if len(set(sides)) != len(sides):
        raise InputError(f"protocols {[p.name for p in protocols]} are for the sides {sides}: give one per arm")
    model = trial.model
    kin = Kinematics(model)
    fr = kin.frames(trial.q_true)
    R0, p0 = fr.R[:, 0], fr.p[:, 0]  # the thorax segment (fixed, but taken as it is)
    labels: list[str] = []
    columns: list[np.ndarray] = []
    for prot in protocols:
        pos = kin.points(trial.q_true, tracked_points(kin, prot), frames=fr)  # (n, k, 3) thorax frame
        if prot.side == "left":
            pos = pos * np.array([1.0, 1.0, -1.0])
        for m, col in zip(prot.markers, np.moveaxis(pos, 1, 0)):
            labels.append(m.name)
            columns.append(col)
        for label, local in _thorax_positions(model, prot).items():
            if label not in labels:
                labels.append(label)
                columns.append(p0 + np.einsum("nij,j->ni", R0, local))
    if len(set(labels)) != len(labels):
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        raise InputError(f"protocols {[p.name for p in protocols]} share marker label(s) {dup}; one label per marker")
    pos = np.stack(columns, axis=1) @ trial.lab_rotation.T + trial.lab_origin_m
    noise = (np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2]).normal(0.0, noise_mm * 1e-3, pos.shape)
             if noise_mm > 0 else np.zeros_like(pos))
    traj = dataclasses.replace(trial.trajectories, labels=tuple(labels), positions_m=pos + noise)
    return dataclasses.replace(
        trial, trajectories=traj, sta_m=np.zeros_like(pos), noise_m=noise,
        marker_segments=tuple(next((m.segment for p in protocols for m in p.markers if m.name == lab), "thorax")
                              for lab in labels),
        description=f"{trial.description}; markers of protocol(s) {', '.join(p.name for p in protocols)}")
