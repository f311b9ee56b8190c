"""Like-for-like comparison of a reconstructed arm elevation with published in vivo kinematics.

exubio's joint angles are computed in the reference study's own definitions (Ludewig et al. 2009:
frames from its landmarks, its scapula built on AC, its sequences; ``exubio.literature.corridor.target_definition``),
compared with its means at humerothoracic (HT) elevations 30/60/90/120 deg, and placed in the
corridor of every comparable study of the Spartacus corpus converted to the same definition
(``exubio.literature.corridor``). The ISB-frame deviation (scapula on AA) is kept beside it, to show what the
frame definition alone changes.

Only frames where the arm is being raised count (``raising``). Angles the markers cannot give are
flagged, never hidden: ``undetermined`` (the constrained marker Jacobian does not see them) and
``inferred`` (a segment of the joint carries no marker of its own, e.g. the clavicle of a marker set
without clavicle markers: its angles then follow the model's geometry, not a measurement).
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping

import numpy as np

from exubio.model.angles import humerothoracic_elevation, isb_angles, joint_angles
from exubio.literature.corridor import HT_GRID_DEG, Corridor, build_corridor, share_inside, target_definition
from exubio.model.frame_definitions import JOINT_SEGMENTS
from exubio.model.kinematics import Kinematics
from exubio.literature.reference import LUDEWIG_ID, load_corpus
from exubio.types import Model, Protocol

__all__ = ["COMPARED_JOINTS", "ANGLE_KEYS", "HT_CHECK_DEG", "compare_elevation", "inferred_joints", "raising",
           "at_ht", "slope", "reference_curves"]

COMPARED_JOINTS = ("SC", "AC", "ST", "GH")
ANGLE_KEYS = {
    "SC": ("SC_protraction_Y", "SC_elevation_X", "SC_rotation_Z"),
    "AC": ("AC_protraction_Y", "AC_medRotation_X", "AC_antRotation_Z"),
    "ST": ("ST_protraction_Y", "ST_medRotation_X", "ST_tilt_Z"),
    "GH": ("GH_abduction_X", "GH_flexion_Z", "GH_rotation_Y"),
}
"""Name of each of a joint's three angles (sequence order): Ludewig's file name and the axis."""
HT_CHECK_DEG = (30.0, 60.0, 90.0, 120.0)
HT_BIN_HALF_WIDTH_DEG = 2.5
RAISING_MIN_RATE_DEG_S = 5.0  # humerothoracic elevation rate that counts as "raising the arm"
RAISING_MIN_SPAN_DEG = 20.0  # a raising phase must cover at least this much HT elevation
CORRIDOR_RANGE_DEG = (30.0, 120.0)
PLANE_OF_ELEVATION_DEG = {"frontal": 0.0, "scapular": 40.0, "sagittal": 90.0}
"""Nominal humerothoracic plane of elevation (ISB HT first angle: 0 = abduction in the coronal
plane, 90 = forward flexion) of each reference motion; Ludewig's scapular plane is 40 deg anterior
to the coronal plane."""
PLANE_TOLERANCE_DEG = 15.0
"""A frame of a free movement counts as elevation in a reference plane when its plane of
elevation is within this of the nominal one (about the spread of the planes within one studied
motion: the elevation planes of Ludewig's three motions are 40-50 deg apart)."""


def raising(ht_deg: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """Frames where the arm is being raised: HT elevation rising faster than
    RAISING_MIN_RATE_DEG_S, in runs that cover at least RAISING_MIN_SPAN_DEG."""
    if ht_deg.size < 3:
        return np.zeros(ht_deg.shape, dtype=bool)
    rate = np.gradient(ht_deg, time_s)
    mask = rate > RAISING_MIN_RATE_DEG_S
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        if np.ptp(ht_deg[start:stop]) < RAISING_MIN_SPAN_DEG:
            mask[start:stop] = False
    return mask


def at_ht(values: np.ndarray, ht_deg: np.ndarray, mask: np.ndarray, target: float) -> float:
    """Mean of values over masked frames with HT within HT_BIN_HALF_WIDTH_DEG of target (nan if none)."""
    sel = mask & (np.abs(ht_deg - target) <= HT_BIN_HALF_WIDTH_DEG)
    return float(np.mean(values[sel])) if sel.any() else float("nan")


def slope(values: np.ndarray, ht_deg: np.ndarray, mask: np.ndarray) -> float:
    """Least-squares slope (deg per deg of HT elevation) over masked frames with HT in 30-120."""
    sel = mask & (ht_deg >= 30.0) & (ht_deg <= 120.0)
    if sel.sum() < 3 or np.ptp(ht_deg[sel]) < 10.0:
        return float("nan")
    return float(np.polyfit(ht_deg[sel], values[sel], 1)[0])


def reference_curves(joint: str, plane: str, study_id: str = LUDEWIG_ID) -> tuple[np.ndarray, np.ndarray]:
    """(ht_deg (k,), angles_deg (k, 3)) of a study's mean ``joint`` curve in ``plane``, raw Euler
    angles of its own definition (NaN for an angle it does not publish)."""
    _, curves = load_corpus()
    c = next((c for c in curves if c.study.id == study_id and c.joint == joint and c.motion == plane and c.is_mean),
             None)
    if c is None:
        raise KeyError(f"no {joint} curve in the {plane} plane for study {study_id}")
    ht = np.unique(np.concatenate([d[0] for d in c.dofs if d is not None]))
    return ht, np.column_stack([np.interp(ht, *d) if d is not None else np.full(ht.size, np.nan) for d in c.dofs])


def inferred_joints(model: Model, protocol: Protocol, /) -> dict[str, str]:
    """Joint-angle sets with a segment (other than the thorax) that carries no tracked marker of
    its own: {joint: why}."""
    carried = {m.segment for m in protocol.markers}
    root = model.segments[0].name
    out = {}
    for joint, segs in JOINT_SEGMENTS.items():
        bare = [s for s in segs if s != root and s not in carried]
        if bare:
            out[joint] = (f"the {' and '.join(bare)} carr{'ies' if len(bare) == 1 else 'y'} no marker of this "
                          f"protocol: these angles follow the model's geometry, not a measurement")
    return out


def compare_elevation(model: Model, q_by_source: Mapping[str, np.ndarray], time_s: np.ndarray, plane: str, /, *,
                      undetermined: Iterable[str] = (), inferred: Mapping[str, str] | None = None,
                      stride: int = 1, corridors: Mapping[str, Corridor] | None = None,
                      plane_tolerance_deg: float | None = None,
                      ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Compare every source's (e.g. "pf", "ls", "truth") arm raising in ``plane`` with Ludewig et
    al. 2009 in its own definitions and with the corridor of comparable studies.

    Returns (result, arrays): result is JSON-ready (per source and angle key: value, Ludewig's
    value and deviation at HT_CHECK_DEG, the change from 30 deg minus Ludewig's, slopes, the share
    of HT 30-120 inside the corridor, the ISB-frame deviation for ST and GH); arrays hold the
    decimated curves (``<source>__ht_deg``, ``<source>__raising``, ``<source>__<joint>_deg``) and the
    corridors (``corridor__<joint>__lo|hi|n`` on ``corridor__ht_deg``, members' curves).
    ``plane_tolerance_deg``: for a free movement, count only raising frames whose plane of
    elevation is within this of ``plane``'s (PLANE_OF_ELEVATION_DEG); None: the trial is a planar
    elevation in ``plane`` (as the TRC abduction and flexion trials)."""
    kin = Kinematics(model)
    defs = {j: target_definition(j) for j in COMPARED_JOINTS}
    cors = dict(corridors) if corridors else {j: build_corridor(model, j, plane, defs[j]) for j in COMPARED_JOINTS}
    refs = {j: reference_curves(j, plane) for j in COMPARED_JOINTS}
    undetermined = set(undetermined)
    inferred = dict(inferred or {})
    arrays: dict[str, np.ndarray] = {"corridor__ht_deg": HT_GRID_DEG}
    result: dict[str, Any] = {
        "plane": plane, "ht_check_deg": list(HT_CHECK_DEG),
        "definitions": {j: d.describe() for j, d in defs.items()},
        "undetermined_angles": sorted(undetermined), "inferred_joints": inferred,
        "corridor": {}}
    envelopes = {j: cor.envelope() for j, cor in cors.items()}  # (lo, hi, n), once per joint
    in_range = (HT_GRID_DEG >= CORRIDOR_RANGE_DEG[0]) & (HT_GRID_DEG <= CORRIDOR_RANGE_DEG[1])
    for j, cor in cors.items():
        lo, hi, n = envelopes[j]
        arrays[f"corridor__{j}__lo"], arrays[f"corridor__{j}__hi"], arrays[f"corridor__{j}__n"] = lo, hi, n
        result["corridor"][j] = {"members": [{"study": m.study.label, "citation": m.study.citation,
                                              "converted": m.converted} for m in cor.members],
                                 "excluded": cor.excluded}
        for k, m in enumerate(cor.members):
            arrays[f"corridor__{j}__member{k}__ht_deg"] = m.ht_deg
            arrays[f"corridor__{j}__member{k}__deg"] = m.angles_deg
    for src, q in q_by_source.items():
        if q is None:
            continue
        ht = np.degrees(humerothoracic_elevation(model, q, kinematics=kin))
        rising = raising(ht, time_s)
        isb = {j: np.degrees(a) for j, a in isb_angles(model, q, kinematics=kin).items()}
        if plane_tolerance_deg is not None:
            off = np.abs((isb["HT"][:, 0] - PLANE_OF_ELEVATION_DEG[plane] + 180.0) % 360.0 - 180.0)
            rising = rising & (off <= plane_tolerance_deg)
        arrays[f"{src}__ht_deg"] = ht[::stride]
        arrays[f"{src}__raising"] = rising[::stride]
        per: dict[str, Any] = {"ht_range_deg": [float(ht.min()), float(ht.max())],
                               "raising_frames": int(rising.sum()),
                               "raising_ht_range_deg": [float(ht[rising].min()), float(ht[rising].max())]
                               if rising.any() else None}
        for j in COMPARED_JOINTS:
            ang = np.degrees(joint_angles(model, q, defs[j], kinematics=kin))
            arrays[f"{src}__{j}_deg"] = ang[::stride]
            ref_ht, ref = refs[j]
            sel = rising & (ht >= CORRIDOR_RANGE_DEG[0] - 1) & (ht <= CORRIDOR_RANGE_DEG[1] + 1)
            for i, key in enumerate(ANGLE_KEYS[j]):
                vals = [at_ht(ang[:, i], ht, rising, h) for h in HT_CHECK_DEG]
                lud = [float(np.interp(h, ref_ht, ref[:, i])) for h in HT_CHECK_DEG]
                dev = [a - b for a, b in zip(vals, lud)]
                share, span = share_inside(cors[j], ht[sel], ang[sel, i], i, ht_range=CORRIDOR_RANGE_DEG,
                                           envelope=envelopes[j])
                n_studies = int(envelopes[j][2][in_range, i].max(initial=0))
                entry = {
                    "value_deg": vals, "ludewig_deg": lud, "deviation_deg": dev,
                    "max_abs_deviation_deg": float(np.nanmax(np.abs(dev))) if np.isfinite(dev).any() else float("nan"),
                    "trend_deviation_deg": [(a - vals[0]) - (b - lud[0]) for a, b in zip(vals, lud)],
                    "slope_deg_per_deg": slope(ang[:, i], ht, rising),
                    "ludewig_slope_deg_per_deg": float(np.polyfit(ref_ht[ref_ht >= 30], ref[ref_ht >= 30, i], 1)[0]),
                    "share_inside_corridor": share, "corridor_span_deg": span, "corridor_studies": n_studies,
                    "undetermined": f"{j}_{key[-1]}" in undetermined,
                    "inferred": j in inferred,
                }
                if j in ("ST", "GH"):
                    isb_vals = [at_ht(isb[j][:, i], ht, rising, h) for h in HT_CHECK_DEG]
                    entry["isb_frame_deviation_deg"] = [a - b for a, b in zip(isb_vals, lud)]
                per[key] = entry
        result[src] = per
    return result, arrays
