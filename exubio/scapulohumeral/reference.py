"""The in vivo corridor of the rhythm's angles in the trial's own frames and sequences.

The published studies (exubio/data: the Spartacus corpus, Ludewig et al. 2009 among them) are
brought into exubio's ISB definitions (Wu et al. 2005 frames from the model's landmarks; ST and
SC in Y-X'-Z'', GH in Phadke's X-Z'-Y'') on the model's bones by
``exubio.literature.corridor.build_corridor``: the corridor is what the studies measured, in the
trial's angles, on this skeleton. Raw signs, as the angles CSV.

The plane of the trial's raising is read off its HT plane of elevation (ISB HT Y-X'-Y'' first
angle) over the raising frames with HT elevation 30-120 deg: the nearest of the studies' planes
(frontal 0, scapular 40, sagittal 90 deg) within PLANE_TOLERANCE_DEG, else none (said, no corridor).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from exubio.literature.corridor import HT_GRID_DEG, build_corridor
from exubio.literature.invivo import PLANE_OF_ELEVATION_DEG
from exubio.model.frame_definitions import ISB_WU2005, JointDefinition
from exubio.scapulohumeral.table import RHYTHM_ANGLES, TrialRhythm
from exubio.types import Model

__all__ = ["ISB_DEFINITIONS", "ANGLE_OF", "PLANE_TOLERANCE_DEG", "Reference", "trial_plane", "reference"]

ISB_DEFINITIONS: dict[str, JointDefinition] = {
    "ST": JointDefinition("ST", ISB_WU2005["thorax"], ISB_WU2005["scapula"], "YXZ", "ISB (Wu et al. 2005)"),
    "SC": JointDefinition("SC", ISB_WU2005["thorax"], ISB_WU2005["clavicle"], "YXZ", "ISB (Wu et al. 2005)"),
    "GH": JointDefinition("GH", ISB_WU2005["scapula"], ISB_WU2005["humerus"], "XZY",
                          "ISB frames, Phadke et al. 2011's sequence"),
}
"""The definitions of the rhythm's angle sets: those of their columns (exubio.model.angles)."""
ANGLE_OF: dict[str, tuple[str, int]] = {
    "ST_Y_internal_rotation": ("ST", 0), "ST_X_upward_rotation": ("ST", 1), "ST_Z_posterior_tilt": ("ST", 2),
    "SC_Y_protraction": ("SC", 0), "SC_X_elevation": ("SC", 1),
    "GH_phadke_X_elevation": ("GH", 0), "GH_phadke_Z_flexion": ("GH", 1), "GH_phadke_Y_internal_rotation": ("GH", 2)}
"""Each rhythm angle's set and its place in the set's sequence."""
assert set(ANGLE_OF) == {a for a, _ in RHYTHM_ANGLES}
PLANE_TOLERANCE_DEG = 25.0
PLANE_HT_RANGE_DEG = (30.0, 120.0)


@dataclass
class Reference:
    """The corridor per rhythm angle on exubio.literature.corridor.HT_GRID_DEG (lo, hi: NaN where
    fewer than two studies cover an elevation), each study's curve, and what was left out."""

    plane: str | None
    plane_deg: float
    why: str  # how the plane was found, or why there is no corridor
    ht_grid_deg: np.ndarray = field(default_factory=lambda: HT_GRID_DEG)
    lo: dict[str, np.ndarray] = field(default_factory=dict)
    hi: dict[str, np.ndarray] = field(default_factory=dict)
    studies: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = field(default_factory=dict)  # (label, ht, deg)
    excluded: dict[str, dict[str, str]] = field(default_factory=dict)  # set -> study -> reason

    def at(self, name: str, ht_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of angle ``name`` at ``ht_deg`` (NaN where there is no corridor)."""
        if name not in self.lo:
            nan = np.full(np.shape(ht_deg), np.nan)
            return nan, nan.copy()
        return (np.interp(ht_deg, self.ht_grid_deg, self.lo[name], left=np.nan, right=np.nan),
                np.interp(ht_deg, self.ht_grid_deg, self.hi[name], left=np.nan, right=np.nan))


def trial_plane(r: TrialRhythm, /) -> tuple[str | None, float, str]:
    """(plane, median plane of elevation deg, how it was found) of the trial's raising frames."""
    sel = (r.phase == 1) & (r.ht_deg >= PLANE_HT_RANGE_DEG[0]) & (r.ht_deg <= PLANE_HT_RANGE_DEG[1])
    sel &= np.isfinite(r.plane_deg)
    if not sel.any():
        return None, float("nan"), "no raising of the arm through HT elevation 30-120 deg: no plane, no corridor"
    p = float(np.median(r.plane_deg[sel]))
    name, nominal = min(PLANE_OF_ELEVATION_DEG.items(), key=lambda kv: abs(kv[1] - p))
    if abs(nominal - p) > PLANE_TOLERANCE_DEG:
        return None, p, (f"median HT plane of elevation {p:.0f} deg while raising: more than {PLANE_TOLERANCE_DEG:.0f} "
                         f"deg from every studied plane ({', '.join(f'{k} {v:.0f}' for k, v in PLANE_OF_ELEVATION_DEG.items())}): "
                         f"no corridor")
    return name, p, f"{name} plane: median HT plane of elevation {p:.0f} deg while raising (the studies' {nominal:.0f})"


def reference(model: Model, plane: str | None, /, *, plane_deg: float = float("nan"), why: str = "") -> Reference:
    """The corridor of every rhythm angle for arm raising in ``plane`` on ``model``'s bones."""
    out = Reference(plane, plane_deg, why)
    if plane is None:
        return out
    for joint, d in ISB_DEFINITIONS.items():
        cor = build_corridor(model, joint, plane, d)
        lo, hi, _ = cor.envelope()
        out.excluded[joint] = dict(cor.excluded)
        for name, (j, i) in ANGLE_OF.items():
            if j != joint:
                continue
            out.lo[name], out.hi[name] = lo[:, i], hi[:, i]
            out.studies[name] = [(m.study.label, m.ht_deg, m.angles_deg[:, i]) for m in cor.members
                                 if np.isfinite(m.angles_deg[:, i]).any()]
    return out
