"""A corridor of published study means for one joint-angle set and one plane of arm elevation,
all expressed in one target definition (e.g. Ludewig et al. 2009's frames and sequence).

Studies build their frames from different landmarks and decompose in different sequences, so
their numbers are not comparable as published. A study's curve is brought into the target
definition on the model's bone geometry: with the study's frames P_s (proximal) and C_s (distal)
and the target's P_t, C_t, all built on the model's landmarks (``exubio.model.angles.definition_frame``),
the same bone rotation reads R_t = (P_s^T P_t)^T R_s (C_s^T C_t), decomposed in the target's
sequence. This needs all three of the study's angles, unless the study's frames and sequence are
the target's (then each angle is taken as published). The frame offsets are those of the model's
(generic or subject-calibrated) bones, not of each study's subjects: the corridor says what the
studies measured in the target's terms on this skeleton.

A study is left out, with the reason, when its frames cannot be built from the model's landmarks
(imaging-device axes, glenoid landmarks, T1/T7), when the metadata marks it not in vivo or its
motion passive, when its numbers are not given as a right side, when it gives per-shoulder curves
only, or when it publishes fewer than three angles of a set that needs converting.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from exubio.model.angles import definition_frame, euler_angles, rotation_from_euler
from exubio.model.frame_definitions import JointDefinition, NotBuildable
from exubio.literature.reference import LUDEWIG_ID, ReferenceCurve, Study, load_corpus, study_definition
from exubio.types import Model

__all__ = ["Corridor", "StudyCurve", "build_corridor", "convert_angles", "share_inside", "target_definition", "why_excluded",
           "CORRIDOR_MIN_STUDIES", "HT_GRID_DEG"]

HT_GRID_DEG = np.arange(0.0, 181.0, 1.0)
CORRIDOR_MIN_STUDIES = 2
"""A corridor needs at least this many study means at an elevation; below it the band is not drawn
and no share inside is computed there."""


@dataclass(frozen=True)
class StudyCurve:
    """One study's mean curve in the target definition, on its own HT grid (deg)."""

    study: Study
    ht_deg: np.ndarray
    angles_deg: np.ndarray  # (k, 3); NaN where the study has no such angle
    converted: bool  # False: the study's definition is the target's, taken as published


@dataclass
class Corridor:
    """Spread (min, max) of the included study means at every HT elevation of ``HT_GRID_DEG``."""

    joint: str
    plane: str
    definition: JointDefinition
    members: list[StudyCurve] = field(default_factory=list)
    excluded: dict[str, str] = field(default_factory=dict)  # study label -> reason

    def envelope(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lo, hi, n) on HT_GRID_DEG, each (g, 3); lo/hi NaN where fewer than
        CORRIDOR_MIN_STUDIES studies cover the elevation."""
        g = HT_GRID_DEG.size
        stack = np.full((len(self.members), g, 3), np.nan)
        for k, m in enumerate(self.members):
            for i in range(3):
                ok = np.isfinite(m.angles_deg[:, i])
                if ok.sum() >= 2:
                    h = m.ht_deg[ok]
                    inside = (HT_GRID_DEG >= h.min()) & (HT_GRID_DEG <= h.max())
                    stack[k, inside, i] = np.interp(HT_GRID_DEG[inside], h, m.angles_deg[ok, i])
        n = np.isfinite(stack).sum(axis=0)
        if stack.shape[0] == 0:
            return np.full((g, 3), np.nan), np.full((g, 3), np.nan), n
        filled = np.where(np.isfinite(stack), stack, np.inf)
        lo = np.where(n >= 1, filled.min(axis=0), np.nan)
        hi = np.where(n >= 1, np.where(np.isfinite(stack), stack, -np.inf).max(axis=0), np.nan)
        lo = np.where(n >= CORRIDOR_MIN_STUDIES, lo, np.nan)
        hi = np.where(n >= CORRIDOR_MIN_STUDIES, hi, np.nan)
        return lo, hi, n


def target_definition(joint: str, study_id: str = LUDEWIG_ID) -> JointDefinition:
    """The definition ``study_id`` (default Ludewig et al. 2009) used for ``joint``, from the
    corpus metadata."""
    studies, curves = load_corpus()
    study = studies[study_id]
    seq = next((c.sequence for c in curves if c.study.id == study_id and c.joint == joint), None)
    d = study_definition(study, joint, seq) if seq else None
    if d is None:
        raise KeyError(f"{study.label} defines no {joint} angles in the corpus")
    return d


def why_excluded(model: Model, curve: ReferenceCurve, target: JointDefinition) -> str | None:
    """Why ``curve`` cannot join a corridor in ``target`` on this model (None: it can)."""
    s = curve.study
    if not s.in_vivo:
        return "not in vivo (metadata: in_vivo false)"
    if not s.active:
        return "passive motion (metadata: active false)"
    if not s.side_as_right:
        return "numbers not given as a right side (metadata: side_as_right false)"
    if not curve.is_mean:
        return "per-shoulder curves only, no mean"
    d = study_definition(s, curve.joint, curve.sequence)
    if d is None:
        return f"no {curve.joint} frame definition in the metadata"
    try:
        for f in (d.parent, d.child):
            definition_frame(model, f)
    except NotBuildable as exc:
        return f"frames not buildable on the model: {exc}"
    if not _same(d, target) and any(x is None for x in curve.dofs):
        return (f"publishes {sum(x is not None for x in curve.dofs)} of the 3 {curve.joint} angles in other frames "
                f"than the target's: cannot be converted")
    return None


def _same(a: JointDefinition, b: JointDefinition) -> bool:
    return a.parent.same_axes(b.parent) and a.child.same_axes(b.child) and a.letters == b.letters


def _to_target(model: Model, curve: ReferenceCurve, target: JointDefinition) -> StudyCurve:
    d = study_definition(curve.study, curve.joint, curve.sequence)
    assert d is not None
    if _same(d, target):
        lo = max(x[0].min() for x in curve.dofs if x is not None)
        hi = min(x[0].max() for x in curve.dofs if x is not None)
        grid = np.unique(np.concatenate([x[0] for x in curve.dofs if x is not None]))
        grid = grid[(grid >= lo) & (grid <= hi)]
        ang = np.column_stack([np.interp(grid, *x) if x is not None else np.full(grid.size, np.nan)
                               for x in curve.dofs])
        return StudyCurve(curve.study, grid, ang, converted=False)
    lo = max(x[0].min() for x in curve.dofs)
    hi = min(x[0].max() for x in curve.dofs)
    grid = np.unique(np.concatenate([x[0] for x in curve.dofs]))
    grid = grid[(grid >= lo) & (grid <= hi)]
    raw = np.column_stack([np.interp(grid, *x) for x in curve.dofs])
    return StudyCurve(curve.study, grid, convert_angles(model, d, target, raw), converted=True)


def convert_angles(model: Model, source: JointDefinition, target: JointDefinition, angles_deg: np.ndarray, /
                   ) -> np.ndarray:
    """Angles (k, 3) deg of ``source``'s definition re-expressed in ``target``'s, on the model's
    bone geometry (module docstring): R_t = (P_s^T P_t)^T R_s (C_s^T C_t)."""
    Rs = rotation_from_euler(np.radians(np.atleast_2d(angles_deg)), source.letters)
    P = definition_frame(model, source.parent).T @ definition_frame(model, target.parent)
    C = definition_frame(model, source.child).T @ definition_frame(model, target.child)
    t = target.letters
    return np.degrees(np.unwrap(euler_angles(P.T @ Rs @ C, t, negative_middle=(t[0] == t[2])), axis=0))


def build_corridor(model: Model, joint: str, plane: str, target: JointDefinition | None = None) -> Corridor:
    """The corridor of every corpus study's mean ``joint`` curve during arm elevation in ``plane``
    ("frontal", "sagittal", "scapular"), in ``target`` (default: Ludewig et al. 2009's definition)."""
    target = target or target_definition(joint)
    _, curves = load_corpus()
    out = Corridor(joint, plane, target)
    for c in curves:
        if c.joint != joint or c.motion != plane:
            continue
        why = why_excluded(model, c, target)
        if why is not None:
            out.excluded.setdefault(c.study.label, why)
            continue
        if any(m.study.id == c.study.id for m in out.members):
            continue
        out.members.append(_to_target(model, c, target))
    for m in out.members:
        out.excluded.pop(m.study.label, None)
    return out


def share_inside(corridor: Corridor, ht_deg: np.ndarray, values_deg: np.ndarray, dof: int, /, *,
                 ht_range: tuple[float, float] = (30.0, 120.0),
                 envelope: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> tuple[float, float]:
    """Fraction of ``ht_range`` (1-deg steps) at which the curve (values against ht, binned by
    mean per degree) lies inside the corridor of angle ``dof``, over the elevations where both the
    curve and a corridor (>= CORRIDOR_MIN_STUDIES studies) exist; and the covered span in degrees.
    (nan, 0) when they never overlap. ``envelope``: corridor.envelope(), when the caller has it."""
    lo, hi, _ = envelope if envelope is not None else corridor.envelope()
    sel = (HT_GRID_DEG >= ht_range[0]) & (HT_GRID_DEG <= ht_range[1])
    binned = np.full(HT_GRID_DEG.size, np.nan)
    idx = np.round(np.asarray(ht_deg, dtype=float)).astype(int)
    vals = np.asarray(values_deg, dtype=float)
    for g in np.flatnonzero(sel):
        m = (idx == int(HT_GRID_DEG[g])) & np.isfinite(vals)
        if m.any():
            binned[g] = vals[m].mean()
    ok = sel & np.isfinite(binned) & np.isfinite(lo[:, dof])
    if not ok.any():
        return float("nan"), 0.0
    inside = (binned[ok] >= lo[ok, dof]) & (binned[ok] <= hi[ok, dof])
    return float(inside.mean()), float(ok.sum() - 1)
