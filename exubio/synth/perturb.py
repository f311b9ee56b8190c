"""A model perturbation: the model a simulated trial is generated with differs from the one it is
reconstructed with (``exubio simulate --perturb``), by given amounts.

What can be perturbed (millimetres and scale factors at the edge, metres inside):

* ``ellipsoid_centre_mm``: the thorax ellipsoid's centre moved by (dx, dy, dz) mm in the ISB thorax
  frame (X anterior, Y superior, Z right): ``(-10, 0, 0)`` is 10 mm more posterior;
* ``ellipsoid_radii_scale``: its radii multiplied by (sx, sy, sz) (one number: all three);
* ``segment_length_scale``: per segment, its size scaled about its origin (its points, its centre
  of mass and its children's joint centres: the segment's length; ``exubio.calibration.scaling.
  scale_model``, the calibration's own scaling);
* ``joint_centre_mm``: per segment, its joint centre (the segment's origin) moved by (dx, dy, dz) mm
  in the reference posture while its points, and its children, stay where they are: only the
  rotation centre moves (e.g. ``humerus``: the glenohumeral centre);
* ``marker_offset_mm``: per model point (a marker's point, e.g. ``SCAP_IA``), moved by (dx, dy, dz)
  mm in the reference posture (thorax-frame axes = the segment's axes there).

``ModelPerturbation.parse(["ellipsoid_centre_mm=-10,0,0", "ellipsoid_radii_scale=1.08",
"length.humerus=1.05", "joint.humerus=0,0,8", "marker.SCAP_IA=0,0,10"])`` reads the CLI's
``KEY=VALUE`` words; ``header_lines`` writes it back in the same words (the truth file's header), so
a header line read by ``parse`` gives the same perturbation.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.io.records import to_json
from exubio.types import Model

__all__ = ["HEADER_PREFIX", "ModelPerturbation"]

HEADER_PREFIX = "model perturbation:"
_VECTOR_KEYS = ("ellipsoid_centre_mm",)
_PREFIXED = {"length": "segment_length_scale", "joint": "joint_centre_mm", "marker": "marker_offset_mm"}
VALID_KEYS = ("ellipsoid_centre_mm=DX,DY,DZ", "ellipsoid_radii_scale=S|SX,SY,SZ", "length.SEGMENT=S",
              "joint.SEGMENT=DX,DY,DZ", "marker.POINT=DX,DY,DZ")


def _floats(key: str, text: str, n: tuple[int, ...]) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        vals = ()
    if len(vals) not in n or not all(np.isfinite(vals)):
        want = " or ".join(str(k) for k in n)
        raise InputError(f"--perturb {key}: expected {want} finite comma-separated number(s), got '{text}'")
    return vals


def _vec(key: str, value) -> tuple[float, float, float]:
    v = np.asarray(value, dtype=float).ravel()
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"perturbation {key}: expected three finite numbers (mm), got {value!r}")
    return tuple(float(x) for x in v)  # type: ignore[return-value]


def _fmt(v: Sequence[float]) -> str:
    return ",".join(f"{x:g}" for x in v)


@dataclass(frozen=True)
class ModelPerturbation:
    """How the generating model differs from the reconstructing one (see the module docstring).
    Empty (the default): no perturbation. Values are checked on construction (InputError naming the
    key); segment and point names against a model in ``apply``."""

    ellipsoid_centre_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ellipsoid_radii_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    segment_length_scale: Mapping[str, float] = field(default_factory=dict)
    joint_centre_mm: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)
    marker_offset_mm: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "ellipsoid_centre_mm", _vec("ellipsoid_centre_mm", self.ellipsoid_centre_mm))
        radii = np.broadcast_to(np.asarray(self.ellipsoid_radii_scale, dtype=float).ravel(), (3,))
        if not np.all(np.isfinite(radii)) or np.any(radii <= 0):
            raise InputError(f"perturbation ellipsoid_radii_scale: expected factors > 0, got {self.ellipsoid_radii_scale!r}")
        object.__setattr__(self, "ellipsoid_radii_scale", tuple(float(x) for x in radii))
        scales = {}
        for seg, s in dict(self.segment_length_scale).items():
            if not (np.isfinite(s) and s > 0):
                raise InputError(f"perturbation length.{seg}: expected a factor > 0, got {s!r}")
            scales[str(seg)] = float(s)
        object.__setattr__(self, "segment_length_scale", MappingProxyType(scales))
        object.__setattr__(self, "joint_centre_mm", MappingProxyType(
            {str(k): _vec(f"joint.{k}", v) for k, v in dict(self.joint_centre_mm).items()}))
        object.__setattr__(self, "marker_offset_mm", MappingProxyType(
            {str(k): _vec(f"marker.{k}", v) for k, v in dict(self.marker_offset_mm).items()}))

    # ---------------------------------------------------------------- words <-> perturbation
    @classmethod
    def parse(cls, words: Sequence[str], /) -> "ModelPerturbation":
        """From ``KEY=VALUE`` words (the CLI's ``--perturb``); an InputError names a bad key or value
        and lists the valid keys."""
        kw: dict = {"segment_length_scale": {}, "joint_centre_mm": {}, "marker_offset_mm": {}}
        for word in words:
            key, sep, value = str(word).partition("=")
            key = key.strip()
            if not sep or not key:
                raise InputError(f"--perturb '{word}': expected KEY=VALUE; valid keys are {list(VALID_KEYS)}")
            prefix, dot, name = key.partition(".")
            if key == "ellipsoid_centre_mm":
                kw[key] = _floats(key, value, (3,))
            elif key == "ellipsoid_radii_scale":
                v = _floats(key, value, (1, 3))
                kw[key] = v * 3 if len(v) == 1 else v
            elif dot and name and prefix in _PREFIXED:
                target = _PREFIXED[prefix]
                kw[target][name] = _floats(key, value, (1,))[0] if prefix == "length" else _floats(key, value, (3,))
            else:
                raise InputError(f"--perturb {key}: unknown key; valid keys are {list(VALID_KEYS)}")
        return cls(**kw)

    def words(self) -> tuple[str, ...]:
        """The ``KEY=VALUE`` words ``parse`` reads back to this perturbation (no-op entries left out)."""
        out = []
        if any(self.ellipsoid_centre_mm):
            out.append(f"ellipsoid_centre_mm={_fmt(self.ellipsoid_centre_mm)}")
        if self.ellipsoid_radii_scale != (1.0, 1.0, 1.0):
            out.append(f"ellipsoid_radii_scale={_fmt(self.ellipsoid_radii_scale)}")
        out += [f"length.{k}={v:g}" for k, v in sorted(self.segment_length_scale.items())]
        out += [f"joint.{k}={_fmt(v)}" for k, v in sorted(self.joint_centre_mm.items())]
        out += [f"marker.{k}={_fmt(v)}" for k, v in sorted(self.marker_offset_mm.items())]
        return tuple(out)

    @property
    def is_empty(self) -> bool:
        return not self.words()

    def header_lines(self) -> tuple[str, ...]:
        """Comment lines for a truth file: ``model perturbation: KEY=VALUE ...`` (or ``none``)."""
        return (f"{HEADER_PREFIX} {' '.join(self.words()) or 'none'} (mm in the ISB thorax frame of the reference "
                f"posture; the trial was generated with the perturbed model, reconstruct it with the unperturbed one)",)

    @classmethod
    def from_header(cls, lines: Sequence[str], /) -> "ModelPerturbation | None":
        """The perturbation a truth file's header states (None: the header states none)."""
        for line in lines:
            text = line.lstrip("#").strip()
            if text.startswith(HEADER_PREFIX):
                words = text[len(HEADER_PREFIX):].split("(")[0].split()
                return cls() if words == ["none"] else cls.parse(words)
        return None

    # ---------------------------------------------------------------- the perturbed model
    def apply(self, model: Model, /) -> Model:
        """The perturbed model (``model`` is not changed). Unknown segments or points are an
        InputError listing the model's."""
        from exubio.calibration.scaling import scale_model

        names = model.segment_names
        for seg in (*self.segment_length_scale, *self.joint_centre_mm):
            if seg not in names:
                raise InputError(f"perturbation: no segment '{seg}' in model '{model.name}'; its segments are {list(names)}")
        for seg in self.joint_centre_mm:
            if model.segment(seg).joint is None:
                raise InputError(f"perturbation joint.{seg}: segment '{seg}' has no joint; "
                                 f"segments with a joint are {[s.name for s in model.segments if s.joint]}")
        owner = {p: s.name for s in model.segments for p in s.points}
        for p in self.marker_offset_mm:
            if p not in owner:
                raise InputError(f"perturbation marker.{p}: no point '{p}' in model '{model.name}'; "
                                 f"its points are {sorted(owner)}")
        out = scale_model(model, self.segment_length_scale) if self.segment_length_scale else model
        segs = list(out.segments)
        index = {s.name: i for i, s in enumerate(segs)}
        for seg, d_mm in self.joint_centre_mm.items():  # move the rotation centre, keep the points
            d = np.asarray(d_mm) * 1e-3
            i = index[seg]
            s = segs[i]
            segs[i] = dataclasses.replace(
                s, joint=dataclasses.replace(s.joint, centre_m=np.asarray(s.joint.centre_m, dtype=float) + d),
                com_m=np.asarray(s.com_m, dtype=float) - d,
                points={k: np.asarray(v, dtype=float) - d for k, v in s.points.items()})
            for j, child in enumerate(segs):
                if child.parent == seg:
                    segs[j] = dataclasses.replace(child, joint=dataclasses.replace(
                        child.joint, centre_m=np.asarray(child.joint.centre_m, dtype=float) - d))
        for p, d_mm in self.marker_offset_mm.items():
            i = index[owner[p]]
            pts = dict(segs[i].points)
            pts[p] = np.asarray(pts[p], dtype=float) + np.asarray(d_mm) * 1e-3
            segs[i] = dataclasses.replace(segs[i], points=pts)
        ell = out.ellipsoid
        ell = dataclasses.replace(ell, centre_m=np.asarray(ell.centre_m, dtype=float) + np.asarray(self.ellipsoid_centre_mm) * 1e-3,
                                  radii_m=np.asarray(ell.radii_m, dtype=float) * np.asarray(self.ellipsoid_radii_scale))
        meta = dict(out.metadata)
        meta["perturbation"] = to_json(self)  # its fields as they are (exubio.io.records)
        return dataclasses.replace(out, segments=tuple(segs), ellipsoid=ell, metadata=meta,
                                   name=f"{model.name} (perturbed: {' '.join(self.words()) or 'none'})")
