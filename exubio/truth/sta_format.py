"""Reader of bone-referenced trials in the ISB soft-tissue-artefact data-sharing format.

The format is that of Cereatti A, Bonci T, Akbarshahi M, et al. (2017) "Standardization proposal of
soft tissue artefact description for data sharing in human motion measurements", J Biomech 62:5-13
(doi 10.1016/j.jbiomech.2017.02.004): a MATLAB v5 file with one variable ``dataSample_<LAB>_<task>``
whose ``subjNN.trialNN.<side>_<bone>`` structs hold, for each bone tracked by pins or fluoroscopy:

* ``mrk.Mxx`` (N x 3, mm): skin-marker trajectories in the bone's anatomical frame (Wu et al. 2005,
  mirrored for a left side); ``mrk_raw`` the same before gap filling, where given;
* ``gRa`` (N x 9): the rotation anatomical frame -> lab, stored row-major;
* ``gta`` (N x 3, mm): the lab position of the anatomical frame's origin;
* ``ALs.<name>`` (3, mm): anatomical landmarks in the anatomical frame.

A skin marker in the lab is ``R @ m + t``; the bone's truth is the (R, t) series. Everything here is
returned in SI (m). The files carry no sampling rate: it is given by the caller.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import InputError

__all__ = ["BoneSegment", "BoneTrial", "read_sta_trial"]

_MM = 1e-3
_BONES = ("scapula", "humerus", "thorax", "clavicle", "ulna", "radius", "hand", "forearm", "femur", "tibia", "pelvis")


@dataclass(frozen=True, eq=False)
class BoneSegment:
    """One bone of a bone-referenced trial: its skin markers in the bone frame and the bone's pose.

    ``markers_bone`` (n_frames, n_markers, 3) m in the bone's anatomical frame, NaN where missing;
    ``rotation`` (n_frames, 3, 3) anatomical frame -> lab; ``origin`` (n_frames, 3) m, lab;
    ``landmarks`` name -> (3,) m in the anatomical frame."""

    name: str
    side: str
    marker_names: tuple[str, ...]
    markers_bone: np.ndarray
    rotation: np.ndarray
    origin: np.ndarray
    landmarks: Mapping[str, np.ndarray]
    note: str = ""
    markers_bone_raw: np.ndarray | None = None
    """``mrk_raw`` where the file gives it: the markers before the file's gap filling (NaN in gaps),
    on the same ``marker_names`` (a marker only in the raw set, which the file removed, is left out)."""

    @property
    def n_frames(self) -> int:
        return int(self.rotation.shape[0])

    def markers_lab(self, *, raw: bool = False) -> np.ndarray:
        """Skin markers in the lab (n_frames, n_markers, 3) m; ``raw``: before the file's gap filling."""
        m = self.markers_bone_raw if raw and self.markers_bone_raw is not None else self.markers_bone
        return np.einsum("nij,nkj->nki", self.rotation, m) + self.origin[:, None, :]

    def landmarks_lab(self) -> dict[str, np.ndarray]:
        """Each anatomical landmark carried by the bone's pose into the lab, (n_frames, 3) m."""
        return {k: self.rotation @ v + self.origin for k, v in self.landmarks.items()}

    def landmark_lab(self, name: str) -> np.ndarray:
        return self.rotation @ self.landmarks[name] + self.origin


@dataclass(frozen=True, eq=False)
class BoneTrial:
    """A bone-referenced trial: its bones (``segments`` by bone name: "scapula", "humerus"), the
    side of the limb, the subject's info as written, the variable's name and its source file."""

    path: Path
    variable: str
    side: str
    segments: Mapping[str, BoneSegment]
    subject: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return next(iter(self.segments.values())).n_frames

    @property
    def lab(self) -> str:
        parts = self.variable.split("_")
        return parts[1] if len(parts) > 2 else ""

    @property
    def task(self) -> str:
        parts = self.variable.split("_")
        return "_".join(parts[2:]) if len(parts) > 2 else self.variable


def _fields(obj: Any) -> list[str]:
    return list(getattr(obj, "_fieldnames", []) or [])


def _array(value: Any, where: str, shape_tail: tuple[int, ...], path: Path) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{path}: {where} is not numeric ({exc})") from None
    if a.ndim == 1 and shape_tail and a.shape[0] == shape_tail[-1] and len(shape_tail) == 1:
        a = a[None, :]
    if a.ndim != 1 + len(shape_tail) or a.shape[1:] != shape_tail:
        raise InputError(f"{path}: {where} has shape {a.shape}; expected (n_frames, {', '.join(map(str, shape_tail))})")
    return a


def _segment(path: Path, key: str, raw: Any) -> BoneSegment:
    side_tag, _, bone = key.partition("_")
    side = {"L": "left", "R": "right"}.get(side_tag.upper())
    if side is None or not bone:
        raise InputError(f"{path}: segment '{key}' is not named <L|R>_<bone> as the data-sharing format asks")
    names = _fields(raw)
    for need in ("mrk", "gRa", "gta"):
        if need not in names:
            raise InputError(f"{path}: segment '{key}' has no '{need}' (has {', '.join(names)}); the data-sharing "
                             "format needs mrk (markers in the bone frame), gRa (bone rotation) and gta (bone origin)")
    rot = _array(raw.gRa, f"{key}.gRa", (9,), path)
    n = rot.shape[0]
    rotation = rot.reshape(n, 3, 3)  # stored row-major
    dets = np.linalg.det(rotation)
    orth = np.abs(np.einsum("nij,nik->njk", rotation, rotation) - np.eye(3)).max(axis=(1, 2))
    finite = np.isfinite(dets)
    if finite.any() and (np.abs(dets[finite] - 1.0).max() > 1e-3 or orth[finite].max() > 1e-3):
        worst = int(np.nanargmax(np.abs(dets - 1.0) + orth))
        raise InputError(f"{path}: {key}.gRa is not a rotation at frame {worst} (det {dets[worst]:.4f}); expected "
                         "an orthonormal 3x3 matrix per frame stored row-major")
    origin = _array(raw.gta, f"{key}.gta", (3,), path) * _MM
    if origin.shape[0] != n:
        raise InputError(f"{path}: {key}.gta has {origin.shape[0]} frames, {key}.gRa {n}")
    mrk = raw.mrk
    mrk_raw = raw.mrk_raw if "mrk_raw" in names else None
    marker_names = tuple(_fields(mrk))  # a marker the file removed from mrk (long gaps) is left out of both
    if not marker_names:
        raise InputError(f"{path}: {key}.mrk holds no marker")

    def read_set(struct: Any, field_name: str) -> np.ndarray:
        out = np.full((n, len(marker_names), 3), np.nan)
        for j, m in enumerate(marker_names):
            if m not in _fields(struct):
                continue
            a = _array(getattr(struct, m), f"{key}.{field_name}.{m}", (3,), path)
            if a.shape[0] != n:
                raise InputError(f"{path}: {key}.{field_name}.{m} has {a.shape[0]} frames, {key}.gRa {n}")
            out[:, j] = a * _MM
        return out

    markers = read_set(mrk, "mrk")
    markers_raw = read_set(mrk_raw, "mrk_raw") if mrk_raw is not None else None
    landmarks: dict[str, np.ndarray] = {}
    if "ALs" in names:
        for lm in _fields(raw.ALs):
            v = np.asarray(getattr(raw.ALs, lm), dtype=float).reshape(-1)
            if v.shape != (3,):
                raise InputError(f"{path}: {key}.ALs.{lm} has {v.size} values; expected 3 (mm)")
            landmarks[lm] = v * _MM
    note = str(raw.warning) if "warning" in names else ""
    return BoneSegment(bone.lower(), side, marker_names, markers, rotation, origin, landmarks, note, markers_raw)


def read_sta_trial(path: str | Path, /) -> BoneTrial:
    """Read one trial of a data-sharing .mat file (the first subject, the first trial); see the module."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        import scipy.io
        from scipy.io.matlab import MatReadError
        data = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except (ValueError, OSError, NotImplementedError, TypeError, MatReadError) as exc:
        raise InputError(f"{path}: not a readable MATLAB v5 file ({exc}); expected the ISB STA data-sharing format") from None
    variables = [k for k in data if not k.startswith("__")]
    if len(variables) != 1:
        raise InputError(f"{path}: holds {len(variables)} variables ({', '.join(variables) or 'none'}); the data-sharing "
                         "format has one, dataSample_<LAB>_<task>")
    var = variables[0]
    top = data[var]
    subjects = [f for f in _fields(top) if f.lower().startswith("subj")]
    if not subjects:
        raise InputError(f"{path}: {var} has no subjNN field (has {', '.join(_fields(top))})")
    subj = getattr(top, sorted(subjects)[0])
    trials = [f for f in _fields(subj) if f.lower().startswith("trial")]
    if not trials:
        raise InputError(f"{path}: {var}.{subjects[0]} has no trialNN field")
    trial = getattr(subj, sorted(trials)[0])
    segs: dict[str, BoneSegment] = {}
    for key in _fields(trial):
        seg = _segment(path, key, getattr(trial, key))
        if seg.name not in _BONES:
            raise InputError(f"{path}: segment '{key}': unknown bone '{seg.name}'")
        segs[seg.name] = seg
    if not segs:
        raise InputError(f"{path}: the trial holds no bone")
    sides = {s.side for s in segs.values()}
    if len(sides) != 1:
        raise InputError(f"{path}: bones of both sides ({', '.join(sorted(sides))}); one limb per trial expected")
    frames = {s.n_frames for s in segs.values()}
    if len(frames) != 1:
        raise InputError(f"{path}: the bones have different frame counts ({sorted(frames)})")
    info: dict[str, Any] = {}
    if "info" in _fields(subj):
        for f in _fields(subj.info):
            v = getattr(subj.info, f)
            if isinstance(v, (str, int, float)) or (isinstance(v, np.ndarray) and v.size == 1):
                info[f] = v.item() if isinstance(v, np.ndarray) else v
    return BoneTrial(path, var, sides.pop(), segs, info)
