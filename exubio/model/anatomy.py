"""The ISB anatomical frames of the shoulder's bones from their landmarks (Wu et al. 2005, J Biomech
38:981-992), as pure numpy on positions, so the model loader (which sets the joint axes on them)
and the angle computation (``exubio.model.angles``) build them the same way.

Positions are those of one posture, in any frame whose axes are the ISB thorax frame's (X anterior,
Y superior, Z right): the model's reference posture, where every segment frame is parallel to the
thorax. A frame is returned as a rotation (3, 3) whose columns are its X, Y, Z axes.

* clavicle: Z from SC to AC; X = Y_thorax x Z (anterior); Y = Z x X;
* scapula: Z from TS to AA; X normal to the plane AI-AA-TS, anterior; Y = Z x X;
* humerus (Wu option 1): Y from the elbow centre to GH; X normal to the plane of GH, the elbow
  centre and EL (= the plane EL-EM-GH when the centre is their midpoint), anterior; Z = X x Y. The
  elbow centre is EJC where given, else the midpoint of EL and EM.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

__all__ = ["ISB_FRAME_SEGMENTS", "isb_frame"]

Y_THORAX = np.array([0.0, 1.0, 0.0])


def _unit(v: np.ndarray, what: str, fail: Callable[[str], Exception]) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n < 1e-9:
        raise fail(f"{what} has zero length")
    return v / n


def _clavicle(p: Mapping[str, np.ndarray], fail) -> np.ndarray:
    z = _unit(p["AC"] - p["SC"], "SC->AC", fail)
    x = _unit(np.cross(Y_THORAX, z), "thorax Y x clavicle Z", fail)
    return np.column_stack([x, np.cross(z, x), z])


def _scapula(p: Mapping[str, np.ndarray], fail) -> np.ndarray:
    aa, ts, ai = p["AA"], p["TS"], p["AI"]
    z = _unit(aa - ts, "TS->AA", fail)
    x = _unit(np.cross(ts - ai, aa - ai), "normal of plane AI-AA-TS", fail)
    x = _unit(x - (x @ z) * z, "scapula X", fail)
    return np.column_stack([x, np.cross(z, x), z])


def _humerus(p: Mapping[str, np.ndarray], fail) -> np.ndarray:
    if "EJC" in p:
        elbow = p["EJC"]
    elif "EL" in p and "EM" in p:
        elbow = 0.5 * (p["EL"] + p["EM"])
    else:
        raise fail(f"needs EJC, or EL and EM; has {sorted(p)}")
    if "EL" in p:
        lateral = p["EL"] - elbow  # = (EL - EM) / 2 when EJC is their midpoint
    elif "EM" in p:
        lateral = elbow - p["EM"]
    else:
        raise fail(f"needs EL or EM; has {sorted(p)}")
    y = _unit(p["GH"] - elbow, "elbow centre->GH", fail)
    x = _unit(np.cross(y, lateral), "normal of plane EL-EM-GH", fail)  # anterior for a right arm
    x = _unit(x - (x @ y) * y, "humerus X", fail)
    return np.column_stack([x, y, np.cross(x, y)])


_BUILDERS = {"clavicle": (_clavicle, ("SC", "AC")), "scapula": (_scapula, ("AA", "TS", "AI")),
             "humerus": (_humerus, ("GH",))}

ISB_FRAME_SEGMENTS: tuple[str, ...] = ("thorax", *_BUILDERS)
"""The segments with an ISB frame here (the thorax's is the model's global frame)."""


def isb_frame(segment: str, points: Mapping[str, np.ndarray], /, *,
              fail: Callable[[str], Exception] = ValueError) -> np.ndarray:
    """The ISB frame (3, 3) of ``segment`` from its landmark positions ``points`` (name -> (3,),
    one posture, thorax-parallel axes). ``fail(message)`` makes the exception raised when a
    landmark is missing or the frame degenerate (the message names the landmark or vector)."""
    if segment == "thorax":
        return np.eye(3)
    if segment not in _BUILDERS:
        raise fail(f"no ISB frame is defined for segment '{segment}' (defined for {list(ISB_FRAME_SEGMENTS)})")
    build, needed = _BUILDERS[segment]
    missing = [n for n in needed if n not in points]
    if missing:
        raise fail(f"the ISB {segment} frame needs landmark(s) {missing}; the segment has {sorted(points)}")
    return build({k: np.asarray(v, dtype=float) for k, v in points.items()}, fail)
