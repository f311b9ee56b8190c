"""Functional joint centres for a calibration: the glenohumeral centre by SCoRE (Ehrig et al.
2006; ``exubio.calibration.functional``) from a movement trial of the same session, expressed at
the static pose.

The scapula's pose comes from its rigid marker cluster (the protocol's ``cluster`` on the
scapula, e.g. the acromion cluster), else from all its markers; the humerus's from all its
markers. Both reference shapes are the markers' static positions (thorax frame), so the static
pose of each cluster is the identity about its centroid and the centre found in the scapula
cluster's frame is directly its position at the static pose."""
from __future__ import annotations

import numpy as np

from exubio.calibration.cluster import cluster_poses
from exubio.calibration.functional import FunctionalCentre, score
from exubio.errors import InputError
from exubio.types import MarkerTargets, Model, Protocol


def _segment_markers(protocol: Protocol, segment: str) -> list[int]:
    on = [j for j, m in enumerate(protocol.markers) if m.segment == segment]
    clusters: dict[str, list[int]] = {}
    for j in on:
        c = protocol.markers[j].cluster
        if c:
            clusters.setdefault(c, []).append(j)
    if clusters:  # a rigid cluster is the better pose; the largest one
        return max(clusters.values(), key=len)
    return on


def gh_joint(model: Model, /) -> str:
    """The segment whose joint is the glenohumeral joint (joint name 'gh')."""
    for s in model.segments:
        if s.joint is not None and s.joint.name == "gh":
            return s.name
    raise InputError(f"{model.source or model.name}: no joint named 'gh'; a functional glenohumeral centre needs one")


def functional_gh(model: Model, protocol: Protocol, functional: MarkerTargets, static_m: np.ndarray, /
                  ) -> tuple[np.ndarray, FunctionalCentre]:
    """(GH at the static pose in the thorax frame (3,) m, the SCoRE result) from ``functional``
    (the movement trial's prepared targets, same protocol). ``static_m``: (k, 3) the static
    pose's markers. InputError (naming the trial) when a cluster has fewer than 3 markers in
    the static or the motion does not determine the centre."""
    src = functional.source or "functional trial"
    humerus = gh_joint(model)
    scapula = model.segment(humerus).parent
    groups = {scapula: _segment_markers(protocol, scapula), humerus: [j for j, m in enumerate(protocol.markers)
                                                                       if m.segment == humerus]}
    poses = {}
    for seg, idx in groups.items():
        idx = [j for j in idx if np.isfinite(static_m[j]).all()]
        if len(idx) < 3:
            raise InputError(f"{src}: a functional glenohumeral centre needs 3 markers on the {seg} present in the "
                             f"static trial; it has {[protocol.markers[j].name for j in idx]}")
        ref = static_m[idx]
        centroid = ref.mean(axis=0)
        R, t, _ = cluster_poses(ref - centroid, functional.positions_m[:, idx])
        poses[seg] = (R, t, centroid)
    R1, t1, c1 = poses[scapula]
    R2, t2, _ = poses[humerus]
    try:
        fc = score(R1, t1, R2, t2)
    except InputError as exc:
        raise InputError(f"{src}: {exc}") from None
    return fc.centre_local1 + c1, fc
