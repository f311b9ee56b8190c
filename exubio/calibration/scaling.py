"""Segment scaling: isotropic factors per segment (or group), the thorax scale from its landmarks,
and the linear map from scale factors to marker points used by the anatomical fit."""
from __future__ import annotations

import dataclasses
from typing import Mapping

import numpy as np

from exubio.calibration.window import _nanmean
from exubio.prep.thorax import isb_landmarks, thorax_frame, to_thorax_frame
from exubio.protocol.labels import resolve_labels
from exubio.types import Model, Protocol, Trajectories

DEFAULT_SCALE_GROUPS: Mapping[str, str] = {"ulna": "forearm", "radius": "forearm"}
"""Segments that share one scale factor (group name); every other segment is its own group."""

SCALE_BOUNDS = (0.7, 1.4)
SCALE_PRIOR_M2 = 1e-4  # cost of (s - 1)^2, in m^2: 10 % costs like 1 mm of one marker


def _groups(model: Model, groups: Mapping[str, str]) -> dict[str, str]:
    return {s.name: groups.get(s.name, s.name) for s in model.segments}


def scale_model(model: Model, factors: Mapping[str, float], /) -> Model:
    """The model with each segment scaled isotropically about its origin by ``factors[segment]``
    (missing segments: 1): its points, centre of mass and the joint-centre offsets of its children
    scale, its inertia scales with the square (same mass, radii of gyration scale with length);
    the thorax factor also scales the ellipsoid's centre and radii."""
    segs = []
    for seg in model.segments:
        s = float(factors.get(seg.name, 1.0))
        joint = seg.joint
        if joint is not None:
            sp = float(factors.get(seg.parent, 1.0))
            joint = dataclasses.replace(joint, centre_m=np.asarray(joint.centre_m, dtype=float) * sp)
        segs.append(dataclasses.replace(
            seg, joint=joint, com_m=np.asarray(seg.com_m, dtype=float) * s,
            inertia_kgm2=np.asarray(seg.inertia_kgm2, dtype=float) * s * s,
            points={k: np.asarray(v, dtype=float) * s for k, v in seg.points.items()}))
    st = float(factors.get(model.segments[0].name, 1.0))
    ell = dataclasses.replace(model.ellipsoid, centre_m=np.asarray(model.ellipsoid.centre_m) * st,
                              radii_m=np.asarray(model.ellipsoid.radii_m) * st)
    return dataclasses.replace(model, segments=tuple(segs), ellipsoid=ell)


def _thorax_scale(model: Model, protocol: Protocol, traj: Trajectories, frames: range) -> float | None:
    """Measured / model distances between the thorax-frame landmarks (least-squares ratio)."""
    frame = protocol.thorax_frame
    if frame.is_identity:
        return None
    thorax = model.segments[0]
    match = resolve_labels(protocol, traj.labels, source=traj.source)
    keys = frame.keys
    if "c7" not in keys:
        return None  # only the two midpoints: no landmark distances to scale the thorax with
    isb = {"ij": "IJ", "px": "PX", "c7": "C7", "t8": "T8"}
    lab = {k: traj.positions_m[list(frames), match.thorax_columns[k]] for k in keys}
    rot, origin = thorax_frame(*isb_landmarks(lab))
    measured, modelled = {}, {}
    for k in keys:
        label = getattr(frame, k)
        name = label if label in thorax.points else isb[k] if isb[k] in thorax.points else None
        if name is None:
            continue
        local = _nanmean(to_thorax_frame(lab[k][:, None, :], rot, origin)[:, 0], axis=0)
        if np.all(np.isfinite(local)):
            measured[k], modelled[k] = local, np.asarray(thorax.points[name], dtype=float)
    ks = sorted(measured)
    dm, dg = [], []
    for i in range(len(ks)):
        for j in range(i + 1, len(ks)):
            dm.append(np.linalg.norm(measured[ks[i]] - measured[ks[j]]))
            dg.append(np.linalg.norm(modelled[ks[i]] - modelled[ks[j]]))
    if len(dm) < 1 or np.dot(dg, dg) <= 0:
        return None
    return float(np.clip(np.dot(dm, dg) / np.dot(dg, dg), *SCALE_BOUNDS))


def _scale_design(model: Model, fr, seg_index: np.ndarray, local_generic: np.ndarray, group_of: dict[str, str],
                  group_names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """For the rotations of ``fr`` (frames of the unscaled ``model`` at some q), the linear maps
    from the group scale factors s to the marker points, V (k, 3, n_groups): r_i = V_i @ s, and
    to the segment origins, O (n_seg, 3, n_groups): p_seg = O_seg @ s (a segment's factor scales
    its points and its children's joint-centre offsets)."""
    names = model.segment_names
    col = {g: j for j, g in enumerate(group_names)}
    O = np.zeros((len(names), 3, len(group_names)))
    for i, seg in enumerate(model.segments):
        if seg.parent is not None:
            par = names.index(seg.parent)
            O[i] = O[par]
            O[i, :, col[group_of[seg.parent]]] += fr.R[par] @ np.asarray(seg.joint.centre_m, dtype=float)
    V = O[seg_index].copy()
    for i, s in enumerate(seg_index):
        V[i, :, col[group_of[names[s]]]] += fr.R[s] @ local_generic[i]
    return V, O

