"""A bone-referenced trial set up as a lab would reconstruct it: a thorax, a subject model, a protocol
and the skin markers as a trial, with the bones' own ISB frames kept aside as the truth.

The data-sharing files carry the scapula and humerus only (their skin markers and bone poses); the
thorax and clavicle markers were not shared. What is assumed, stated in every output
(``ThoraxAssumption.text``):

* **The thorax is fixed in the lab** (the subject stands still; measured cost on simulated trials:
  ``studies/README.md``, "Bone truth"). Its ISB frame: Y = the lab's vertical, which is the lab
  axis closest to the humerus's long axis in the rest posture (the arm hangs); X (anterior) turned
  about Y so that the scapula's TS->AA direction, seen from above, makes the generic model's rest
  angle with the thorax's Z axis (the scapula's rest protraction is the generic model's); the origin
  placed so that the subject's AA at rest is the generic model's AA.
* **A left arm** is mirrored through the thorax's sagittal plane (Z -> -Z) onto the right-arm model,
  as exubio's ``side: left`` does, and its truth with it, so the angles carry the right arm's signs.
* **A perfect static calibration at the trial's first frames** (the rest window): the subject
  model's scapula (AA, TS, AI) and humerus (GH, EL, EM) are the subject's bone landmarks at rest,
  its other points follow the generic model rigidly with each bone's ISB frame, the thorax ellipsoid
  is moved least so that TS and AI at rest lie on it, and each skin marker is a model point where it
  sits on its bone at rest. The skin markers carry no palpation error and no STA at rest by
  construction: the errors measured are the soft-tissue artefact's during the motion, through the
  model, not a calibration's.
* **No clavicle marker**: the clavicle's axial rotation is held (it moves no marker), as the
  shipped thoracoscapular protocol does; the SC and AC angles are therefore not compared.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..errors import InputError
from ..model.anatomy import isb_frame
from ..types import Trajectories
from .sta_format import BoneTrial

__all__ = ["ThoraxAssumption", "BoneLabRun", "REST_WINDOW_S", "REST_MAX_DEG", "clavicle_gap_m", "setup_lab_run", "truth_frames"]

REST_WINDOW_S = 0.3
"""The rest window: at most the first 0.3 s of the trial ..."""
REST_MAX_DEG = 2.0
"""... and only its frames where the humerus has turned less than 2 deg from the first frame."""

_MM = 1e-3
_SCAPULA_LANDMARKS = ("AA", "TS", "AI")
_HUMERUS_LANDMARKS = {"GH": ("GHC", "GH"), "EL": ("EL",), "EM": ("EM",)}
_AXIS_NAMES = ("X", "Y", "Z")


@dataclass(frozen=True, eq=False)
class ThoraxAssumption:
    """The thorax assumed fixed in the lab: ``rotation`` thorax -> lab (columns: the thorax's X, Y, Z
    in the lab), ``origin_m`` (lab), ``mirrored`` (a left arm, Z -> -Z), ``vertical`` (the lab axis
    taken as up, e.g. "+Z"), ``text``: the assumption in words, for every output."""

    rotation: np.ndarray
    origin_m: np.ndarray
    mirrored: bool
    vertical: str
    text: str

    def to_thorax(self, points_lab: np.ndarray) -> np.ndarray:
        """Lab positions (..., 3) m -> thorax-frame positions (mirrored for a left arm)."""
        p = (np.asarray(points_lab, dtype=float) - self.origin_m) @ self.rotation
        if self.mirrored:
            p = p * np.array([1.0, 1.0, -1.0])
        return p


@dataclass(frozen=True, eq=False)
class BoneLabRun:
    """Everything a reconstruction of a bone-referenced trial needs, and its truth.

    ``model_mapping`` and ``protocol_mapping``: the subject model's and the protocol's YAML
    mappings (written beside the results so a lab sees what was assumed); ``trajectories``: the
    skin markers in the thorax frame (``thorax_frame: identity``); ``truth``: each bone's ISB frame
    (n, 3, 3) in the thorax frame (``truth_frames``); ``rest_frames``: the calibration window."""

    trial: BoneTrial
    assumption: ThoraxAssumption
    model_mapping: Mapping[str, Any]
    protocol_mapping: Mapping[str, Any]
    trajectories: Trajectories
    truth: Mapping[str, np.ndarray]
    rest_frames: np.ndarray
    raw_markers: bool


def _rotation_angle_deg(R0: np.ndarray, R: np.ndarray) -> np.ndarray:
    c = (np.einsum("ij,nij->n", R0, R) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def _rest_frames(trial: BoneTrial, rate_hz: float) -> np.ndarray:
    hum = trial.segments["humerus"]
    n = max(1, min(trial.n_frames, int(round(REST_WINDOW_S * rate_hz)) + 1))
    turned = _rotation_angle_deg(hum.rotation[0], hum.rotation[:n])
    still = np.flatnonzero(turned < REST_MAX_DEG)
    return still[: np.argmax(np.diff(np.r_[still, n + 1]) > 1) + 1] if still.size else np.array([0])


def _landmark(seg, names: tuple[str, ...], path) -> str:
    for n in names:
        if n in seg.landmarks:
            return n
    raise InputError(f"{path}: the {seg.side} {seg.name} has no landmark {' or '.join(names)} (has "
                     f"{', '.join(seg.landmarks) or 'none'}); the bone-truth comparison needs its ISB frame")


def _mean_lab(points: np.ndarray, frames: np.ndarray) -> np.ndarray:
    return np.nanmean(points[frames], axis=0)


def _scapula_points(trial: BoneTrial) -> dict[str, np.ndarray]:
    seg = trial.segments["scapula"]
    return {k: seg.landmark_lab(_landmark(seg, (k,), trial.path)) for k in _SCAPULA_LANDMARKS}


def _humerus_points(trial: BoneTrial) -> dict[str, np.ndarray]:
    seg = trial.segments["humerus"]
    return {k: seg.landmark_lab(_landmark(seg, names, trial.path)) for k, names in _HUMERUS_LANDMARKS.items()}


def thorax_assumption(trial: BoneTrial, generic_points_mm: Mapping[str, Mapping[str, list]], rest: np.ndarray
                      ) -> ThoraxAssumption:
    """The thorax fixed in the lab (module docstring), from the rest window's landmarks."""
    hum = {k: _mean_lab(v, rest) for k, v in _humerus_points(trial).items()}
    scap = {k: _mean_lab(v, rest) for k, v in _scapula_points(trial).items()}
    long_axis = hum["GH"] - 0.5 * (hum["EL"] + hum["EM"])
    k = int(np.argmax(np.abs(long_axis)))
    up = np.zeros(3)
    up[k] = np.sign(long_axis[k])
    vertical = ("+" if up[k] > 0 else "-") + _AXIS_NAMES[k]
    mirrored = trial.side == "left"
    s = -1.0 if mirrored else 1.0
    gs = {n: np.asarray(generic_points_mm["scapula"][n], dtype=float) * _MM for n in ("AA", "TS")}
    d_model = gs["AA"] - gs["TS"]
    a, b = d_model[0], s * d_model[2]  # the generic rest direction, horizontal part, in the unmirrored thorax
    d_lab = scap["AA"] - scap["TS"]
    d_lab = d_lab - (d_lab @ up) * up
    if np.linalg.norm(d_lab) < 1e-6 or np.hypot(a, b) < 1e-9:
        raise InputError(f"{trial.path}: the scapula's TS->AA direction at rest is vertical; cannot orient the thorax")
    e = d_lab / np.linalg.norm(d_lab)
    g = np.cross(up, e)
    beta = np.arctan2(b, a)
    x = np.cos(beta) * e + np.sin(beta) * g
    z = np.cross(x, up)
    rotation = np.column_stack([x, up, z])
    aa_model = gs["AA"] * np.array([1.0, 1.0, s])
    origin = scap["AA"] - rotation @ aa_model
    text = (f"thorax fixed in the lab (the files carry no thorax marker): Y = lab {vertical} (the lab axis nearest the "
            f"humerus's long axis at rest), X turned about Y so that the scapula's TS->AA at rest makes the generic "
            f"model's angle with the thorax, origin placed so that AA at rest is the generic model's"
            + ("; left arm mirrored onto the right-arm model (Z -> -Z)" if mirrored else ""))
    return ThoraxAssumption(rotation, origin, mirrored, vertical, text)


def _frame_series(segment: str, points: Mapping[str, np.ndarray], path) -> np.ndarray:
    n = next(iter(points.values())).shape[0]
    out = np.full((n, 3, 3), np.nan)
    for i in range(n):
        p = {k: v[i] for k, v in points.items()}
        if all(np.isfinite(v).all() for v in p.values()):
            out[i] = isb_frame(segment, p, fail=lambda msg, i=i: InputError(f"{path}: frame {i}: the {segment}'s ISB frame: {msg}"))
    return out


def truth_frames(trial: BoneTrial, assumption: ThoraxAssumption) -> dict[str, np.ndarray]:
    """Each bone's ISB frame (n, 3, 3) in the (assumed, mirrored) thorax frame, from its landmarks
    carried by the bone's pose: the same construction (``exubio.model.anatomy.isb_frame``) the
    model's frames use."""
    scap = {k: assumption.to_thorax(v) for k, v in _scapula_points(trial).items()}
    hum = {k: assumption.to_thorax(v) for k, v in _humerus_points(trial).items()}
    return {"scapula": _frame_series("scapula", scap, trial.path), "humerus": _frame_series("humerus", hum, trial.path)}


def clavicle_gap_m(run: "BoneLabRun", /) -> np.ndarray:
    """(n,) m: how far the bone's AC, carried by the pinned scapula (the subject model's AC moved with the
    bone's ISB frame from its rest pose), lies off the sphere about the model's SC on which the model's
    rigid clavicle keeps it, with the thorax still as assumed (NaN where the scapula is not seen). Zero at
    rest by construction; what it grows to is what no reconstruction under the assumption can follow (a
    trunk that moved in the lab, a girdle that is not the model's): the comparison's error there is the
    assumption's as much as exubio's."""
    segs = {s["name"]: s for s in run.model_mapping["segments"]}
    pts = {k: np.asarray(v, dtype=float) * _MM for k, v in segs["scapula"]["points_mm"].items()}
    sc = np.asarray(segs["clavicle"]["points_mm"]["SC"], dtype=float) * _MM
    rest = isb_frame("scapula", {k: pts[k] for k in _SCAPULA_LANDMARKS}, fail=InputError)
    aa = run.assumption.to_thorax(_scapula_points(run.trial)["AA"])
    ac = aa + np.einsum("nij,j->ni", run.truth["scapula"], rest.T @ (pts["AC"] - pts["AA"]))
    return np.abs(np.linalg.norm(ac - sc, axis=1) - np.linalg.norm(pts["AC"] - sc))


def _rigid_map(F_from: np.ndarray, o_from: np.ndarray, F_to: np.ndarray, o_to: np.ndarray):
    R = F_to @ F_from.T
    return lambda p: R @ (np.asarray(p, dtype=float) - o_from) + o_to


def _subject_model(generic: Mapping[str, Any], scap: Mapping[str, np.ndarray], hum: Mapping[str, np.ndarray],
                   markers: Mapping[str, Mapping[str, np.ndarray]], name: str) -> dict[str, Any]:
    """The generic model's mapping with the subject's scapula and humerus at rest (module docstring)."""
    from ..calibration.ellipsoid import fit_ellipsoid
    from ..types import Ellipsoid

    data = copy.deepcopy(dict(generic))
    segs = {s["name"]: s for s in data["segments"]}
    pts = {n: {k: np.asarray(v, dtype=float) * _MM for k, v in s.get("points_mm", {}).items()} for n, s in segs.items()}
    gen_scap = isb_frame("scapula", pts["scapula"], fail=InputError)
    sub_scap = isb_frame("scapula", scap, fail=InputError)
    to_scap = _rigid_map(gen_scap, pts["scapula"]["AA"], sub_scap, scap["AA"])
    gen_hum = isb_frame("humerus", {k: pts["humerus"][k] for k in ("GH", "EL", "EM")}, fail=InputError)
    sub_hum = isb_frame("humerus", hum, fail=InputError)
    to_hum = _rigid_map(gen_hum, pts["humerus"]["GH"], sub_hum, hum["GH"])
    new = {n: dict(p) for n, p in pts.items()}
    new["scapula"] = {k: to_scap(v) for k, v in pts["scapula"].items() if not k.startswith("SCAP_")}
    new["scapula"].update({k: scap[k] for k in _SCAPULA_LANDMARKS})
    new["clavicle"] = {"SC": pts["clavicle"]["SC"], "AC": new["scapula"]["AC"]}
    new["humerus"] = {k: to_hum(v) for k, v in pts["humerus"].items() if k in ("GH", "EJC", "EL", "EM")}
    new["humerus"].update({"GH": hum["GH"], "EL": hum["EL"], "EM": hum["EM"], "EJC": 0.5 * (hum["EL"] + hum["EM"])})
    for distal in ("ulna", "radius", "hand"):
        new[distal] = {k: to_hum(v) for k, v in pts[distal].items()}
    for seg, m in markers.items():
        new[seg].update(m)
    for n, s in segs.items():
        s["points_mm"] = {k: [round(float(c) / _MM, 3) for c in v] for k, v in new[n].items()}
    ell = data["ellipsoid"]
    generic_ell = Ellipsoid(np.asarray(ell["centre_mm"], float) * _MM, np.asarray(ell["radii_mm"], float) * _MM,
                            tuple(tuple(c) for c in ell["contact_points"]))
    fitted, _ = fit_ellipsoid(generic_ell, np.array([scap["TS"], scap["AI"]]))
    ell["centre_mm"] = [round(float(c) / _MM, 4) for c in fitted.centre_m]
    ell["radii_mm"] = [round(float(c) / _MM, 4) for c in fitted.radii_m]
    data["name"] = name
    data.pop("calibration", None)
    return data


def setup_lab_run(trial: BoneTrial, generic_model: Mapping[str, Any], /, *, rate_hz: float,
                  raw_markers: bool = True, without_sta: bool = False) -> BoneLabRun:
    """The trial as a lab would reconstruct it (module docstring). ``generic_model``: the generic
    model YAML's mapping; ``raw_markers``: the markers before the file's gap filling (exubio fills
    nothing: a gap switches the marker off), else the file's filled ones. ``without_sta``: each
    marker carried rigidly by its bone from where it sits at rest (no soft-tissue artefact at all):
    what is left of the error is the model's and the thorax assumption's."""
    for bone in ("scapula", "humerus"):
        if bone not in trial.segments:
            raise InputError(f"{trial.path}: no {bone} in the trial (has {', '.join(trial.segments)}); the bone-truth "
                             "comparison needs the scapula and the humerus")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"{trial.path}: sampling rate {rate_hz!r} Hz; expected a positive number")
    rest = _rest_frames(trial, rate_hz)
    generic_points = {s["name"]: s.get("points_mm", {}) for s in generic_model["segments"]}
    assumption = thorax_assumption(trial, generic_points, rest)
    scap = {k: _mean_lab(assumption.to_thorax(v), rest) for k, v in _scapula_points(trial).items()}
    hum = {k: _mean_lab(assumption.to_thorax(v), rest) for k, v in _humerus_points(trial).items()}
    labels: list[str] = []
    columns: list[np.ndarray] = []
    model_markers: dict[str, dict[str, np.ndarray]] = {}
    for bone, prefix in (("scapula", "S_"), ("humerus", "H_")):
        seg = trial.segments[bone]
        lab = assumption.to_thorax(seg.markers_lab(raw=raw_markers))
        at_rest = assumption.to_thorax(seg.markers_lab(raw=False))[rest]
        if without_sta:
            fixed = np.nanmean(seg.markers_bone[rest], axis=0)
            lab = assumption.to_thorax(np.einsum("nij,kj->nki", seg.rotation, fixed) + seg.origin[:, None, :])
        for j, m in enumerate(seg.marker_names):
            label = prefix + m
            seen = np.isfinite(at_rest[:, j]).all(axis=1)
            pos = at_rest[seen, j].mean(axis=0) if seen.any() else np.full(3, np.nan)
            if not seen.any() or np.isnan(lab[:, j]).all():
                continue  # a marker the file removed (never filled): not a marker of this trial
            model_markers.setdefault(bone, {})[label] = pos
            labels.append(label)
            columns.append(lab[:, j])
    model = _subject_model(generic_model, scap, hum, model_markers, f"bone_truth_{trial.lab}_{trial.task}")
    protocol = {
        "schema_version": 1,
        "name": f"bone_truth_{trial.lab}_{trial.task}",
        "description": (f"skin markers of {trial.path.name} (scapula and humerus; no thorax or clavicle marker in the "
                        f"file): {assumption.text}"),
        "thorax_frame": "identity",
        "filter": {"cutoff_hz": "auto", "order": 2},
        "hold": ["sc_posterior_rotation"],
        "markers": {label: {"segment": bone, "point": label} for bone, ms in model_markers.items() for label in ms},
    }
    n = trial.n_frames
    traj = Trajectories(tuple(labels), np.stack(columns, axis=1), float(rate_hz), np.arange(n) / float(rate_hz),
                        source=str(trial.path))
    return BoneLabRun(trial, assumption, model, protocol, traj, truth_frames(trial, assumption), rest, raw_markers)
