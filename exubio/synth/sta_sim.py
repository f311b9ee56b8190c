"""The bone STA model (``exubio.synth.sta_bone``) applied to a simulated trial.

For every segment the model covers (scapula, humerus) and that carries markers of the simulation:
the markers' positions in the segment's ISB anatomical frame at the first frame (the start posture,
where the artefact is zero) and the model's drivers from the simulated truth (HT elevation from the
thorax Y axis, the scapula's rotation from the first frame, the GH angles) give the cluster's rigid
motion over the bone (rotation about the centroid of the simulation's markers of that segment, and
translation of that centroid) plus each marker's non-rigid motion (the regression of a data marker
drawn at random, seeded), and the cluster's rigid motion also carries a draw of what the regression
leaves on held-out tasks (the model's ``residual``, a smooth random process seeded by the trial's
seed: ``exubio.synth.sta_residual``). Markers of the other segments keep the per-marker artefact they were given
(clavicle, forearm, hand: ``sta_mm``; thorax: none): the data hold no other bone.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from exubio.errors import InputError
from exubio.synth.sta_bone import BoneStaModel, load_sta_model, segment_displacements, simulation_drivers

__all__ = ["PER_MARKER", "apply_bone_sta", "resolve_sta_model"]

PER_MARKER = "per-marker"


def resolve_sta_model(value: "str | Path | BoneStaModel | None", /) -> BoneStaModel | None:
    """None for the per-marker model (None, 'per-marker'), else the bone model: a shipped name
    ('bone'), a JSON path or a BoneStaModel."""
    if value is None or isinstance(value, BoneStaModel):
        return value
    if str(value).strip().lower() in (PER_MARKER, "per_marker", "permarker"):
        return None
    return load_sta_model(value)


def apply_bone_sta(model, kin, q: np.ndarray, R_seg: np.ndarray, points_thorax: np.ndarray, segs: Sequence[str],
                   sta_model: BoneStaModel, per_marker: np.ndarray, rng: np.random.Generator, /, *,
                   residual_rng: np.random.Generator | None = None, rate_hz: float | None = None,
                   ) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """The artefact (n, k, 3) in the thorax frame: ``per_marker`` with the markers of the model's
    segments replaced by the bone model's (with ``residual_rng`` and ``rate_hz``: its rigid part
    includes a draw of the held-out residual, where the model has one). Returns (artefact, the
    segments replaced, the rigid part alone (n, k, 3), zero elsewhere)."""
    from exubio.model.angles import segment_anatomical_rotations

    need = [s for s in ("scapula", "humerus") if s not in model.segment_names]
    if need:
        raise InputError(f"the bone STA model's drivers need the {' and '.join(need)} of model '{model.name}'")
    Rg = segment_anatomical_rotations(model, q, kinematics=kin, rotations=R_seg)
    drivers = simulation_drivers(Rg["scapula"], Rg["humerus"])
    out = np.array(per_marker, dtype=float, copy=True)
    rigid_all = np.zeros_like(out)
    done = []
    for name, seg in sta_model.segments.items():
        idx = [i for i, s in enumerate(segs) if s == name]
        if not idx or name not in Rg:
            continue
        R = Rg[name]
        local0 = points_thorax[0, idx] @ R[0]  # bone-frame coordinates at the start (rows: R0^T p)
        rigid, nonrigid = segment_displacements(seg, drivers, local0, rng, residual_rng=residual_rng, rate_hz=rate_hz)
        rigid_all[:, idx] = np.einsum("nij,nkj->nki", R, rigid)
        out[:, idx] = np.einsum("nij,nkj->nki", R, rigid + nonrigid)
        done.append(name)
    return out, tuple(done), rigid_all


def describe(sta_model: BoneStaModel, replaced: Sequence[str], sta_mm: float) -> str:
    """One line for a trial's metadata: which model moved which markers."""
    name = sta_model.name or "bone STA model"
    res = [s for s in replaced if sta_model.segments[s].residual is not None]
    extra = f" + held-out residual on the {', '.join(res)}" if res else ""
    return (f"bone STA model '{name}' on the {', '.join(replaced) or 'no'} markers (rigid cluster motion over the "
            f"bone from the simulated angles{extra} + non-rigid rest); per-marker STA {sta_mm:g} mm on the other "
            f"segments' markers (none on the thorax)")
