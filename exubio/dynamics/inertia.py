"""Segment inertia for inverse dynamics: Dumas, Cheze & Verriest (2007), J Biomech 40:543-553,
"Adjustments to McConville et al. and Young et al. body segment inertial parameters", Table 2
(male adults), in the ISB segment frames of the arm, forearm and hand, scaled by the model's own
segment lengths and its body mass (``--body-mass``).

The table gives, per segment, the mass as a fraction of body mass, the centre of mass as percent
of the segment length along the segment coordinate system's X (anterior), Y (from the distal to the
proximal joint centre, i.e. superior in the anatomical posture) and Z (right) axes, from the
proximal joint centre, and the inertia tensor about the centre of mass as radii of gyration in
percent of the length: I = m L^2 [[rxx^2, rxy^2, rxz^2], [., ryy^2, ryz^2], [., ., rzz^2]], where
the paper's imaginary radii ("i", here a negative sign) give negative products.

Lengths (the paper's definitions, on this model's landmarks):
- arm: GH to the elbow joint centre EJC; frame: the humerus ISB frame (Wu et al. 2005, option 1,
  ``exubio.model.anatomy``);
- forearm: EJC to the wrist joint centre WJC; Y from WJC to EJC, X normal to Y and the styloid
  line US->RS (anterior), Z = X x Y;
- hand: WJC to the midpoint of the 2nd and 5th metacarpal heads (MCP2, MCP5); Y from that midpoint
  to WJC, X normal to Y and MCP5->MCP2 (anterior), Z = X x Y.

What the table does not hold, and the rule used here:
- the model splits the forearm into an ulna and a radius (pronation between them): the Dumas
  forearm (mass, centre of mass, tensor) is shared between them in the model's own ratio of their
  masses (Seth et al. 2019, as in the model file), each share fixed to its bone in the reference
  posture (forearm supinated), so at pronation 0 the two shares are exactly the Dumas forearm;
- clavicle and scapula (not in Dumas 2007): the model's own values (Seth et al. 2019 masses and
  principal inertias, scaled with body mass; see the model file);
- the thorax is fixed (its inertia plays no part in the joint moments of the arm);
- a mass held in the hand (``hand_load_kg``) is a point mass at the hand's centre of mass: the
  hand's mass grows by it, its centre of mass and tensor about it do not change.

The model is a right arm (a left arm is mirrored onto it before reconstruction), so the table's
right-side frames apply as they are.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from exubio.errors import ModelError
from exubio.model.anatomy import isb_frame
from exubio.model.kinematics import Kinematics
from exubio.types import Model

__all__ = ["DUMAS_2007_MALE", "INERTIA_SOURCE", "dynamics_model", "isb_segment_frames"]

INERTIA_SOURCE = ("Dumas R, Cheze L, Verriest JP (2007) J Biomech 40:543-553, Table 2 (male), scaled by the "
                  "model's segment lengths and body mass; clavicle and scapula: the model's own (Seth et al. 2019)")


@dataclasses.dataclass(frozen=True)
class DumasSegment:
    mass_fraction: float
    com_percent: tuple[float, float, float]  # X, Y, Z, % of length, from the proximal joint centre
    radii_percent: tuple[float, float, float, float, float, float]  # xx, yy, zz, xy, xz, yz (negative: "i")


DUMAS_2007_MALE = {
    "arm": DumasSegment(0.024, (1.7, -45.2, -2.6), (31, 14, 32, 6, 5, 2)),
    "forearm": DumasSegment(0.017, (1.0, -41.7, 1.4), (28, 11, 27, 3, 2, -8)),
    "hand": DumasSegment(0.006, (8.2, -83.9, 7.4), (61, 38, 56, 22, 15, -20)),
}
"""Dumas et al. 2007, Table 2, male: mass fraction, centre of mass (% of length) and radii of
gyration (%; a negative entry is the paper's imaginary radius, a negative product of inertia)."""


def _tensor(radii: tuple[float, ...]) -> np.ndarray:
    xx, yy, zz, xy, xz, yz = (math.copysign((r / 100.0) ** 2, r) for r in radii)
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def _unit(v: np.ndarray, what: str, where: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n < 1e-9:
        raise ModelError(f"{where}: {what} has zero length; cannot build the segment frame of the inertia table")
    return v / n


def _point(model: Model, ref: dict[str, np.ndarray], segment: str, name: str) -> np.ndarray:
    seg = model.segment(segment)
    if name not in seg.points:
        raise ModelError(f"{model.source or model.name}: segment '{segment}' has no point '{name}', which the "
                         f"inertia table (Dumas et al. 2007) needs; it has {sorted(seg.points)}")
    return ref[segment][0] @ seg.points[name] + ref[segment][1]


def isb_segment_frames(model: Model) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """{"humerus" | "ulna" | "hand": (origin (3,), rotation (3, 3) columns X, Y, Z, length m)} of the
    Dumas / ISB segment frames in the model's reference posture (thorax frame = every segment's
    frame there), from the model's landmarks (module docstring)."""
    kin = Kinematics(model)
    fr = kin.frames(np.zeros(model.n_coordinates))
    ref = {s.name: (fr.R[i], fr.p[i]) for i, s in enumerate(model.segments)}
    where = model.source or model.name
    p = {n: _point(model, ref, seg, n) for seg, names in (("humerus", ("GH", "EJC", "EL")), ("ulna", ("WJC",)),
                                                          ("radius", ("RS",)), ("hand", ("MCP2", "MCP5")))
         for n in names}
    p["US"] = _point(model, ref, "ulna", "US")
    hum = model.segment("humerus").points
    A = isb_frame("humerus", {k: ref["humerus"][0] @ v + ref["humerus"][1] for k, v in hum.items()},
                  fail=lambda msg: ModelError(f"{where}: cannot build the ISB humerus frame: {msg}"))
    out = {"humerus": (p["GH"], A, float(np.linalg.norm(p["GH"] - p["EJC"])))}
    for name, prox, distal, lateral in (("ulna", p["EJC"], p["WJC"], p["RS"] - p["US"]),
                                        ("hand", p["WJC"], 0.5 * (p["MCP2"] + p["MCP5"]), p["MCP2"] - p["MCP5"])):
        y = _unit(prox - distal, f"the {name} long axis", where)
        x = _unit(np.cross(y, lateral), f"the {name} X axis", where)
        out[name] = (prox, np.column_stack([x, y, np.cross(x, y)]), float(np.linalg.norm(prox - distal)))
    return out


def dynamics_model(model: Model, /, *, hand_load_kg: float = 0.0) -> Model:
    """``model`` with the segment inertia of inverse dynamics (module docstring): humerus, ulna +
    radius and hand from Dumas et al. 2007 scaled by the model's lengths and ``model.body_mass_kg``,
    clavicle and scapula as they are, ``hand_load_kg`` added at the hand's centre of mass."""
    if not (math.isfinite(hand_load_kg) and hand_load_kg >= 0):
        raise ModelError(f"--hand-load-kg must be a number >= 0 (kg), got {hand_load_kg}")
    frames = isb_segment_frames(model)
    kin = Kinematics(model)
    fr = kin.frames(np.zeros(model.n_coordinates))
    body = model.body_mass_kg
    segments = list(model.segments)
    index = {s.name: i for i, s in enumerate(segments)}

    def table(key: str, frame: str):
        origin, A, length = frames[frame]
        d = DUMAS_2007_MALE[key]
        mass = d.mass_fraction * body
        com_global = origin + A @ (np.asarray(d.com_percent) / 100.0 * length)
        inertia = A @ (mass * length ** 2 * _tensor(d.radii_percent)) @ A.T  # thorax-parallel axes
        return mass, com_global, inertia

    def put(name: str, mass: float, com_global: np.ndarray, inertia: np.ndarray) -> None:
        i = index[name]
        local_com = fr.R[i].T @ (com_global - fr.p[i])  # R = I in the reference posture
        segments[i] = dataclasses.replace(segments[i], mass_kg=float(mass), com_m=local_com,
                                          inertia_kgm2=fr.R[i].T @ inertia @ fr.R[i])

    put("humerus", *table("arm", "humerus"))
    m_fa, c_fa, i_fa = table("forearm", "ulna")
    ulna, radius = model.segment("ulna").mass_kg, model.segment("radius").mass_kg
    share = radius / (ulna + radius) if ulna + radius > 0 else 0.0
    put("ulna", (1 - share) * m_fa, c_fa, (1 - share) * i_fa)
    put("radius", share * m_fa, c_fa, share * i_fa)
    m_h, c_h, i_h = table("hand", "hand")
    put("hand", m_h + hand_load_kg, c_h, i_h)
    metadata = dict(model.metadata)
    metadata["inertia_source"] = INERTIA_SOURCE
    metadata["hand_load_kg"] = float(hand_load_kg)
    return dataclasses.replace(model, segments=tuple(segments), metadata=metadata)
