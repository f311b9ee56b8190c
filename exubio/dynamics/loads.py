"""External loads on the arm for inverse dynamics: a force applied at a point fixed in a segment
plus a free moment, per frame, already on the trial's time grid (exubio.prep.loads reads, filters
and resamples them from a CSV file or a C3D's analog channels).

Frames of the vectors (``frame``):
- ``lab``: the lab's axes (the trial file's); needs the thorax's motion in the lab;
- ``thorax``: the ISB thorax frame (the model's world: X anterior, Y superior, Z right);
- ``segment``: the model frame of ``segment`` (the thorax axes in the model's reference posture,
  carried by the segment as it moves; for a left arm, the mirrored model's).
Lab and thorax vectors of a left arm are mirrored as its markers are (Z -> -Z of the thorax frame).
The point (``point_m``) is always in the model frame of ``segment``, whose origin is the segment's
proximal joint centre (GH for the humerus, the elbow centre for the ulna and the radius, the wrist
centre for the hand, SC for the clavicle, AC for the scapula).

A load is the force and moment the environment applies to the body (a hand pushing on a handle
receives the handle's reaction): it adds to what the joints must hold as -F, -(r x F + M).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import cross

__all__ = ["LOAD_FRAMES", "ExternalLoad", "load_wrenches"]

LOAD_FRAMES = ("lab", "thorax", "segment")


@dataclass(frozen=True)
class ExternalLoad:
    """force_N, moment_Nm, point_m: (n, 3) on the trial's frames (module docstring); segment: a
    model segment; frame: one of LOAD_FRAMES; source: the file (and columns) it came from."""

    segment: str
    frame: str
    force_N: np.ndarray
    moment_Nm: np.ndarray
    point_m: np.ndarray
    source: str = ""

    def describe(self) -> str:
        peak = float(np.nanmax(np.linalg.norm(self.force_N, axis=-1))) if self.force_N.size else 0.0
        peak_m = float(np.nanmax(np.linalg.norm(self.moment_Nm, axis=-1))) if self.moment_Nm.size else 0.0
        return (f"external load from {self.source or 'the API'} on the {self.segment} (vectors in the {self.frame} "
                f"frame; peak |F| {peak:.4g} N, peak |M| {peak_m:.4g} N m)")


def load_wrenches(loads, segment_names, R_seg: np.ndarray, p_seg: np.ndarray, thorax_rotation: np.ndarray | None,
                  mirrored: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Per segment, the external force (n, S, 3) and its moment about the thorax-frame origin
    (n, S, 3), thorax-frame coordinates, of ``loads``. R_seg (n, S, 3, 3), p_seg (n, S, 3): the
    segments' model frames; ``thorax_rotation`` (n, 3, 3) thorax-to-lab (lab-frame loads only)."""
    n, S = p_seg.shape[:2]
    F = np.zeros((n, S, 3))
    Q = np.zeros((n, S, 3))
    names = list(segment_names)
    for load in loads:
        if load.segment not in names:
            raise InputError(f"{load.source}: segment '{load.segment}' is not in the model; its segments are {names}")
        s = names.index(load.segment)
        force, moment = np.asarray(load.force_N, dtype=float), np.asarray(load.moment_Nm, dtype=float)
        if force.shape != (n, 3) or moment.shape != (n, 3):
            raise InputError(f"{load.source}: the load has {force.shape[0]} samples, the trial {n} frames")
        if load.frame == "lab":
            if thorax_rotation is None:
                raise InputError(f"{load.source}: its vectors are in the lab frame, but the trial has no thorax "
                                 f"markers to place the thorax in the lab; give them in the thorax frame")
            force = np.einsum("nji,nj->ni", thorax_rotation, force)  # R^T v
            moment = np.einsum("nji,nj->ni", thorax_rotation, moment)
        if load.frame in ("lab", "thorax") and mirrored:  # a left arm is mirrored through the sagittal plane
            force = force * np.array([1.0, 1.0, -1.0])
            moment = moment * np.array([-1.0, -1.0, 1.0])
        if load.frame == "segment":
            force = np.einsum("nij,nj->ni", R_seg[:, s], force)
            moment = np.einsum("nij,nj->ni", R_seg[:, s], moment)
        elif load.frame not in LOAD_FRAMES:
            raise InputError(f"{load.source}: frame '{load.frame}': expected one of {list(LOAD_FRAMES)}")
        r = p_seg[:, s] + np.einsum("nij,nj->ni", R_seg[:, s], np.broadcast_to(load.point_m, (n, 3)))
        F[:, s] += force
        Q[:, s] += cross(r, force) + moment
    return F, Q
