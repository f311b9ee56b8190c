"""A soft-tissue-artefact (STA) model fitted on bone-referenced trials, and its application.

Data: trials of the ISB data-sharing format (``exubio.truth.sta_format``; Cereatti et al. 2017,
J Biomech 62:5-13, doi 10.1016/j.jbiomech.2017.02.004): each segment's skin markers in its bone's
ISB anatomical frame, and the bone's pose in the lab.

Split (``rigid_split``). For one segment, the markers' reference positions are their mean over the
calibration window (the first ``CALIBRATION_S`` s: the start posture). In every frame, the
least-squares rigid transform (Kabsch) of that reference set onto the current markers, both in the
bone frame, gives the cluster's rigid motion over the bone: a rotation vector ``rotation`` (3, rad)
about the reference centroid and the centroid's translation ``translation`` (3, m); what the rigid
transform leaves is each marker's non-rigid rest (n, k, 3).

Drivers (``trial_drivers``). Angles of the bones, all in the right-arm convention (a left arm's
mirrored ISB frames are mirrored back: positions Z -> -Z, relative rotations M R M with
M = diag(1, 1, -1)):

* ``ht_elevation``: the angle between the humerus's long axis (ISB Y) and the vertical (the lab's
  Z in the data files, the thorax's Y in a simulation). The files hold no thorax: the thorax is
  ASSUMED upright and fixed in the lab.
* ``scapula_rotation_x|y|z``: the scapula's rotation from its start posture (rotation vector, rad,
  in the scapula's start frame): with the thorax fixed in the lab, its rotation on the thorax.
* ``gh_x|gh_z|gh_y``: the glenohumeral angles scapula -> humerus, X-Z'-Y'' (Phadke et al. 2011,
  exubio's GH sequence), rad, absolute.

Model (``BoneStaModel``). Per segment: its drivers; features = each driver and each product of two
(linear + quadratic), minus their value at the start posture (so the artefact is zero there); the
six rigid parameters (rotation vector, centroid translation, in the bone frame) = ridge regression
on the features (columns scaled to unit RMS, penalty ``RIDGE``); the non-rigid rest kept as its
RMS amplitude (``nonrigid_sd_m``) and as each data marker's own regression on the same features
(``nonrigid_coef``), from which a simulation draws its markers' non-rigid motion.

Application (``segment_displacements``): for markers at bone-frame positions m_k with centroid c,
d_k(t) = T(t) + (Q(t) - I)(m_k - c) + e_k(t), Q = exp(rotation), in the bone frame; the rigid
parameters are the regression's mean course plus, in a simulation, a draw of what the regression
leaves on held-out tasks (``residual``, ``exubio.synth.sta_residual``).
"""
from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from exubio.errors import InputError
from exubio.synth.sta_residual import ResidualProcess, measure_residual

__all__ = [
    "CALIBRATION_S", "DEFAULT_DRIVERS", "ROTATION_COURSE", "BoneStaModel", "SegmentSta", "RigidSplit", "fit_sta_model", "load_sta_model",
    "rigid_split", "trial_drivers", "features", "segment_targets", "predict_rigid", "segment_displacements",
    "rigid_parameters", "held_out_residual",
]

CALIBRATION_S = 0.3
RIDGE = 0.01
MIRROR = np.diag([1.0, 1.0, -1.0])
SCHEMA_VERSION = 1
SHIPPED = {"bone": "sta_bone_s2m.json", "s2m": "sta_bone_s2m.json"}
# Chosen by leave-one-task-out on the S2M trials among 16 candidate driver sets and penalties
# (studies/README.md): the scapula on HT elevation (with its square) and, linearly, the scapula's
# rotation from the start; the humerus linearly on the three GH angles (quadratic terms in them
# extrapolated badly to a held-out task).
DEFAULT_DRIVERS: dict[str, tuple[str, ...]] = {
    "scapula": ("ht_elevation", "linear:scapula_rotation_x", "linear:scapula_rotation_y", "linear:scapula_rotation_z"),
    "humerus": ("linear:gh_x", "linear:gh_z", "linear:gh_y"),
}
DEFAULT_RIDGE: dict[str, float] = {"scapula": 0.01, "humerus": 0.1}
# The humerus cluster's rotation gets no mean course: the GH angles do not predict it on a held-out
# task (pooled held-out R^2 -0.04, studies/README.md), so it is the held-out residual alone, a draw.
ROTATION_COURSE: dict[str, bool] = {"scapula": True, "humerus": False}
DRIVER_DEFINITIONS = {
    "ht_elevation": "angle (rad) between the humerus ISB Y axis (elbow centre -> GH) and the vertical: the lab Z "
                    "axis in the bone-referenced data (thorax assumed upright and fixed in the lab), the thorax Y "
                    "axis in a simulation",
    "scapula_rotation_x": "rotation vector (rad) of the scapula ISB frame from its start posture (the "
                          "calibration window), expressed in the start frame, right-arm convention: X component",
    "scapula_rotation_y": "the same, Y component", "scapula_rotation_z": "the same, Z component",
    "gh_x": "glenohumeral angle scapula -> humerus, X-Z'-Y'' (Phadke 2011), first angle (rad), right-arm convention",
    "gh_z": "the same, second angle (Z')", "gh_y": "the same, third angle (Y'', axial rotation)",
    "humerus_rotation": "the humerus's rotation angle (rad) from its start orientation (the calibration window): "
                        "in the lab for the bone-referenced data (thorax assumed fixed), in the thorax in a "
                        "simulation; it scales the held-out residual (exubio.synth.sta_residual)",
}


@dataclass(frozen=True)
class RigidSplit:
    """A segment's skin-marker motion over its bone: ``rotation`` (n, 3) rad (rotation vector about
    ``centroid``), ``translation`` (n, 3) m of the centroid, ``nonrigid`` (n, k, 3) m, all in the
    bone frame; ``reference`` (k, 3) m the markers at the start; NaN in frames with a marker missing."""

    rotation: np.ndarray
    translation: np.ndarray
    nonrigid: np.ndarray
    reference: np.ndarray
    centroid: np.ndarray


def _kabsch(ref: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Rotations Q (n, 3, 3) with cur - mean(cur) ~ Q (ref - mean(ref)) in least squares (the
    cluster fit of exubio.calibration.cluster)."""
    from exubio.calibration.cluster import cluster_poses

    return cluster_poses(ref - ref.mean(axis=0), cur)[0]


def rigid_split(markers: np.ndarray, n_reference: int, /) -> RigidSplit:
    """Split markers (n, k, 3) m in the bone frame into the cluster's rigid motion from its mean over
    the first ``n_reference`` frames and the non-rigid rest (see the module)."""
    markers = np.asarray(markers, dtype=float)
    if markers.ndim != 3 or markers.shape[2] != 3 or markers.shape[1] < 3:
        raise InputError(f"markers must be (n_frames, n_markers >= 3, 3), got shape {markers.shape}")
    if not 1 <= n_reference <= markers.shape[0]:
        raise InputError(f"the reference window ({n_reference} frames) must lie within the {markers.shape[0]} frames")
    window = markers[:n_reference]
    seen = np.isfinite(window).all(axis=2).any(axis=0)
    ref = np.full((markers.shape[1], 3), np.nan)
    ref[seen] = np.nanmean(window[:, seen], axis=0)
    if not seen.all():
        bad = int(np.where(~np.isfinite(ref).all(axis=1))[0][0])
        raise InputError(f"marker {bad} is missing throughout the reference window (first {n_reference} frames)")
    n = markers.shape[0]
    ok = np.isfinite(markers).all(axis=(1, 2))
    rot, trans = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    nonrigid = np.full_like(markers, np.nan)
    c = ref.mean(axis=0)
    if ok.any():
        cur = markers[ok]
        Q = _kabsch(ref, cur)
        cc = cur.mean(axis=1)
        rot[ok] = Rotation.from_matrix(Q).as_rotvec()
        trans[ok] = cc - c
        nonrigid[ok] = cur - (cc[:, None, :] + np.einsum("nij,kj->nki", Q, ref - c))
    return RigidSplit(rot, trans, nonrigid, ref, c)


def trial_drivers(trial, /, *, n_reference: int) -> dict[str, np.ndarray]:
    """The drivers (module docstring) of a bone-referenced trial (``exubio.truth.sta_format.BoneTrial``
    with scapula and humerus), each (n,) rad, right-arm convention."""
    from exubio.model.angles import euler_angles

    missing = [b for b in ("scapula", "humerus") if b not in trial.segments]
    if missing:
        raise InputError(f"{trial.path}: no {' and no '.join(missing)} in the trial; the STA model's drivers need both bones")
    Rs, Rh = trial.segments["scapula"].rotation, trial.segments["humerus"].rotation
    M = MIRROR if trial.side == "left" else np.eye(3)
    return _drivers(Rs, Rh, M, vertical=np.array([0.0, 0.0, 1.0]), n_reference=n_reference,
                    euler=euler_angles)


def _drivers(Rs: np.ndarray, Rh: np.ndarray, M: np.ndarray, *, vertical: np.ndarray, n_reference: int,
             euler) -> dict[str, np.ndarray]:
    out = {"ht_elevation": np.arccos(np.clip(Rh[:, :, 1] @ vertical, -1.0, 1.0))}
    h0 = Rotation.from_matrix(Rh[:n_reference]).mean().as_matrix()
    out["humerus_rotation"] = np.arccos(np.clip((np.einsum("ij,nij->n", h0, Rh) - 1.0) / 2.0, -1.0, 1.0))
    start = Rotation.from_matrix(Rs[:n_reference]).mean().as_matrix()
    rel = M @ start.T @ Rs @ M
    rv = Rotation.from_matrix(rel).as_rotvec()
    for i, ax in enumerate("xyz"):
        out[f"scapula_rotation_{ax}"] = rv[:, i]
    gh = euler(M @ np.swapaxes(Rs, 1, 2) @ Rh @ M, "XZY")
    for i, ax in enumerate(("gh_x", "gh_z", "gh_y")):
        out[ax] = np.unwrap(gh[:, i])
    return out


def simulation_drivers(R_scapula: np.ndarray, R_humerus: np.ndarray, /) -> dict[str, np.ndarray]:
    """The drivers of a simulated motion from the ISB anatomical rotations (n, 3, 3) of the scapula
    and the humerus in the thorax frame (right arm; the start posture is the first frame)."""
    from exubio.model.angles import euler_angles

    return _drivers(R_scapula, R_humerus, np.eye(3), vertical=np.array([0.0, 1.0, 0.0]), n_reference=1,
                    euler=euler_angles)


def _base(name: str) -> str:
    return name.split(":", 1)[1] if name.startswith("linear:") else name


def feature_names(drivers: Sequence[str], /) -> tuple[str, ...]:
    """Each driver, then the product of every pair of drivers not marked ``linear:NAME``."""
    lin = tuple(_base(d) for d in drivers)
    q = [d for d in drivers if not d.startswith("linear:")]
    quad = tuple(f"{a}*{b}" for i, a in enumerate(q) for b in q[i:])
    return lin + quad


def features(drivers: Mapping[str, np.ndarray], names: Sequence[str], /, *, n_reference: int) -> np.ndarray:
    """Features (n, f): each driver and each product of two, minus their mean over the first
    ``n_reference`` frames (the start posture)."""
    missing = [_base(d) for d in names if _base(d) not in drivers]
    if missing:
        raise InputError(f"drivers {missing} are not available; available: {sorted(drivers)}")
    a = np.stack([np.asarray(drivers[_base(d)], dtype=float) for d in names], axis=1)
    b = a[:, [i for i, d in enumerate(names) if not d.startswith("linear:")]]
    cols = [a] + [b[:, i:i + 1] * b[:, i:] for i in range(b.shape[1])]
    X = np.concatenate(cols, axis=1)
    return X - X[:n_reference].mean(axis=0)


def segment_targets(split: RigidSplit, /) -> np.ndarray:
    """The six rigid parameters (n, 6): rotation vector (rad), centroid translation (m)."""
    return np.concatenate([split.rotation, split.translation], axis=1)


def _ridge(X: np.ndarray, Y: np.ndarray, ridge: float) -> np.ndarray:
    """B (f, p) minimising |Y - X B|^2 + ridge n |B'|^2 with X's columns scaled to unit RMS."""
    scale = np.sqrt(np.mean(X * X, axis=0))
    scale[scale < 1e-12] = 1.0
    Xs = X / scale
    n, f = Xs.shape
    B = np.linalg.solve(Xs.T @ Xs + ridge * n * np.eye(f), Xs.T @ Y)
    return B / scale[:, None]


@dataclass(frozen=True)
class SegmentSta:
    """One segment's fitted artefact: ``drivers``; ``rigid_coef`` (f, 6): features -> rotation
    vector (rad) and centroid translation (m) in the bone frame (right-arm convention);
    ``nonrigid_sd_m`` the RMS per coordinate of the non-rigid rest; ``nonrigid_coef`` (k, f, 3):
    each data marker's non-rigid rest regressed on the features (m per feature unit; a marker of the
    same name in several trials pooled); ``residual``: what the rigid regression leaves on held-out
    tasks, drawn as a smooth random process in a simulation (``exubio.synth.sta_residual``; None:
    the regression's mean course alone, as a model fitted on one trial or written before it)."""

    drivers: tuple[str, ...]
    rigid_coef: np.ndarray
    nonrigid_sd_m: float
    nonrigid_coef: np.ndarray
    fit: Mapping[str, object] = field(default_factory=dict)
    residual: ResidualProcess | None = None

    @property
    def feature_names(self) -> tuple[str, ...]:
        return feature_names(self.drivers)


@dataclass(frozen=True)
class BoneStaModel:
    segments: Mapping[str, SegmentSta]
    meta: Mapping[str, object] = field(default_factory=dict)
    name: str = ""

    def to_json(self) -> dict:
        segs = {}
        for s, m in self.segments.items():
            segs[s] = {
                "drivers": list(m.drivers), "features": list(m.feature_names),
                "rigid_outputs": ["rotation_x_rad", "rotation_y_rad", "rotation_z_rad",
                                  "translation_x_m", "translation_y_m", "translation_z_m"],
                "rigid_coef": np.round(m.rigid_coef, 9).tolist(),
                "nonrigid_sd_m": round(float(m.nonrigid_sd_m), 6),
                "nonrigid_coef_m": np.round(m.nonrigid_coef, 7).tolist(),
                "fit": dict(m.fit),
            }
            if m.residual is not None:
                segs[s]["residual"] = m.residual.to_json()
        return {"schema_version": SCHEMA_VERSION, **dict(self.meta), "driver_definitions":
                {_base(d): DRIVER_DEFINITIONS[_base(d)] for m in self.segments.values() for d in m.drivers}, "segments": segs}

    def write(self, path: str | Path, /) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        return path

    @classmethod
    def from_json(cls, data: Mapping, /, *, where: str = "STA model") -> "BoneStaModel":
        if not isinstance(data, Mapping) or data.get("schema_version") != SCHEMA_VERSION:
            got = data.get("schema_version") if isinstance(data, Mapping) else type(data).__name__
            raise InputError(f"{where}: expected a bone STA model with schema_version {SCHEMA_VERSION}, got {got}")
        segs = {}
        raw_segs = data.get("segments")
        if not isinstance(raw_segs, Mapping) or not raw_segs:
            raise InputError(f"{where}: key 'segments' must map segment names to their models")
        for s, m in raw_segs.items():
            try:
                drivers = tuple(m["drivers"])
                coef = np.asarray(m["rigid_coef"], dtype=float)
                sd = float(m["nonrigid_sd_m"])
                nr = np.asarray(m.get("nonrigid_coef_m", []), dtype=float)
            except (KeyError, TypeError, ValueError) as exc:
                raise InputError(f"{where}: segment '{s}': missing or bad key {exc}; expected drivers, rigid_coef, "
                                 "nonrigid_sd_m, nonrigid_coef_m") from None
            unknown = [d for d in drivers if _base(d) not in DRIVER_DEFINITIONS]
            if unknown:
                raise InputError(f"{where}: segment '{s}': unknown drivers {unknown}; known: {sorted(DRIVER_DEFINITIONS)}")
            f = len(feature_names(drivers))
            if coef.shape != (f, 6) or (nr.size and nr.shape[1:] != (f, 3)):
                raise InputError(f"{where}: segment '{s}': rigid_coef has shape {coef.shape}, expected ({f}, 6); "
                                 f"nonrigid_coef_m {nr.shape}, expected (k, {f}, 3)")
            res = m.get("residual")
            res = None if res is None else ResidualProcess.from_json(res, where=f"{where}: segment '{s}'")
            segs[s] = SegmentSta(drivers, coef, sd, nr.reshape(-1, f, 3), dict(m.get("fit", {})), res)
        meta = {k: v for k, v in data.items() if k not in ("schema_version", "segments", "driver_definitions")}
        return cls(segs, meta, str(data.get("name", where)))


def load_sta_model(name_or_path: str | Path, /) -> BoneStaModel:
    """A shipped model by name ('bone' = 's2m': exubio/data/sta_bone_s2m.json) or a JSON file."""
    key = str(name_or_path)
    if key.lower() in SHIPPED:
        from importlib.resources import files

        text = files("exubio.data").joinpath(SHIPPED[key.lower()]).read_text(encoding="utf-8")
        return BoneStaModel.from_json(json.loads(text), where=f"shipped STA model '{key}'")
    path = Path(key)
    if not path.is_file():
        raise InputError(f"STA model '{key}': not a shipped model ({', '.join(sorted(SHIPPED))}) nor a file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a JSON STA model ({exc})") from None
    return BoneStaModel.from_json(data, where=str(path))


# --------------------------------------------------------------------------------------------
# Fit
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SegmentData:
    """One trial's segment, ready to fit: features X (n, f), rigid targets Y (n, 6), the non-rigid
    rest (n, k, 3) with the marker names, the split; right-arm convention."""

    task: str
    X: np.ndarray
    Y: np.ndarray
    nonrigid: np.ndarray
    marker_names: tuple[str, ...]
    split: RigidSplit
    theta: np.ndarray | None = None  # (n,) rad: the humerus's rotation from the start (the residual's driver)
    rate_hz: float = 0.0


def segment_data(trial, segment: str, drivers: Sequence[str], *, rate_hz: float,
                 n_reference: int | None = None) -> SegmentData:
    """The fitting data of one segment of a bone-referenced trial; the start posture is the first
    ``CALIBRATION_S`` s, or the first ``n_reference`` frames where given."""
    if segment not in trial.segments:
        raise InputError(f"{trial.path}: no {segment} in the trial (has {', '.join(trial.segments)})")
    n_ref = max(1, int(round(CALIBRATION_S * rate_hz))) if n_reference is None else int(n_reference)
    if n_ref >= trial.n_frames:
        raise InputError(f"{trial.path}: {trial.n_frames} frames at {rate_hz:g} Hz do not outlast the "
                         f"{CALIBRATION_S:g} s calibration window")
    seg = trial.segments[segment]
    M = MIRROR if trial.side == "left" else np.eye(3)
    split = rigid_split(seg.markers_bone @ M, n_ref)  # mirrored positions: the split comes out right-armed
    drv = trial_drivers(trial, n_reference=n_ref)
    X = features(drv, drivers, n_reference=n_ref)
    return SegmentData(trial.task, X, segment_targets(split), split.nonrigid, seg.marker_names, split,
                       drv["humerus_rotation"], float(rate_hz))


def fit_segment(data: Sequence[SegmentData], drivers: Sequence[str], *, ridge: float = RIDGE,
                rotation_course: bool = True) -> SegmentSta:
    """Fit one segment's model on the pooled frames of ``data`` (frames with a marker missing left out);
    without ``rotation_course`` the cluster's rotation has no mean course (zero coefficients)."""
    X = np.concatenate([d.X for d in data])
    Y = np.concatenate([d.Y for d in data])
    ok = np.isfinite(Y).all(axis=1) & np.isfinite(X).all(axis=1)
    if ok.sum() < 10 * X.shape[1]:
        raise InputError(f"{ok.sum()} usable frames cannot fit {X.shape[1]} features per rigid parameter")
    B = _ridge(X[ok], Y[ok], ridge)
    if not rotation_course:
        B[:, :3] = 0.0
    sq, cnt = 0.0, 0
    pooled: dict[str, tuple[list, list]] = {}  # a marker's frames over every trial it is in, by name
    for d in data:
        good = np.isfinite(d.nonrigid).all(axis=(1, 2)) & np.isfinite(d.X).all(axis=1)
        e = d.nonrigid[good]
        sq += float(np.sum(e * e))
        cnt += e.size
        for k, name in enumerate(d.marker_names):
            xs, es = pooled.setdefault(name, ([], []))
            xs.append(d.X[good])
            es.append(e[:, k, :])
    sd = float(np.sqrt(sq / max(cnt, 1)))
    nr_coef = [_ridge(np.concatenate(xs), np.concatenate(es), ridge) for xs, es in pooled.values()]
    fit = {"tasks": [d.task for d in data], "frames": int(ok.sum()), "ridge": ridge, "rotation_course": rotation_course,
           "rms_rotation_deg": round(float(np.degrees(np.sqrt(np.mean(np.sum(Y[ok, :3] ** 2, axis=1))))), 3),
           "rms_translation_mm": round(float(1e3 * np.sqrt(np.mean(np.sum(Y[ok, 3:] ** 2, axis=1)))), 3)}
    return SegmentSta(tuple(drivers), B, sd, np.stack(nr_coef), fit)


def held_out_residual(data: Sequence[SegmentData], drivers: Sequence[str], *, ridge: float = RIDGE,
                      rotation_course: bool = True) -> ResidualProcess:
    """What the rigid regression leaves on a task it was not fitted to (``exubio.synth.sta_residual``):
    for each trial of ``data`` (at least 2, one sampling rate), the regression fitted on the others,
    its residual on it."""
    if len(data) < 2:
        raise InputError("a held-out residual needs at least two trials (one fitted on the other)")
    rates = {d.rate_hz for d in data}
    if len(rates) != 1 or any(d.theta is None for d in data):
        raise InputError(f"held-out residual: the trials need one sampling rate and their drivers, got rates {sorted(rates)}")
    res = []
    for i, held in enumerate(data):
        seg = fit_segment([d for j, d in enumerate(data) if j != i], drivers, ridge=ridge, rotation_course=rotation_course)
        res.append(held.Y - held.X @ seg.rigid_coef)
    return measure_residual(res, [d.theta for d in data], rates.pop(), tasks=[d.task for d in data])


def fit_sta_model(paths: Sequence[str | Path], /, *, rate_hz: float,
                  drivers: Mapping[str, Sequence[str]] | None = None, ridge: float | Mapping[str, float] | None = None,
                  citation: str = "", name: str = "") -> BoneStaModel:
    """Fit a model on bone-referenced trials (.mat files of the data-sharing format, all sampled at
    ``rate_hz``): each segment of ``drivers`` (default DEFAULT_DRIVERS; ``linear:NAME`` = no
    quadratic terms in NAME) on the pooled frames of every trial, with the ridge penalty ``ridge``
    (one for all, or per segment; default DEFAULT_RIDGE). Returns the model; ``.write(path)``
    saves its JSON."""
    from exubio.truth.sta_format import read_sta_trial

    if not paths:
        raise InputError("no bone-referenced trial given to fit an STA model on")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"sampling rate must be > 0 Hz, got {rate_hz}")
    drivers = dict(DEFAULT_DRIVERS if drivers is None else drivers)
    trials = [read_sta_trial(p) for p in paths]
    ridges = ridge if isinstance(ridge, Mapping) else {s: (DEFAULT_RIDGE.get(s, RIDGE) if ridge is None else ridge)
                                                        for s in drivers}
    segs = {}
    for s, d in drivers.items():
        data = [segment_data(t, s, d, rate_hz=rate_hz) for t in trials]
        kw = dict(ridge=ridges.get(s, RIDGE), rotation_course=ROTATION_COURSE.get(s, True))
        seg = fit_segment(data, d, **kw)
        segs[s] = seg if len(data) < 2 else replace(seg, residual=held_out_residual(data, d, **kw))
    meta = {
        "name": name or "bone STA model: " + ", ".join(f"{t.lab} {t.task}".strip() for t in trials),
        "fitted": _dt.date.today().isoformat(),
        "data": [f"{Path(t.path).name} ({t.lab} {t.task}, {t.side} arm, {t.n_frames} frames)" for t in trials],
        "sampling_rate_hz": rate_hz, "calibration_window_s": CALIBRATION_S,
        "citation": citation or "Cereatti A, Bonci T, Akbarshahi M, et al. (2017) Standardization proposal of soft "
                                "tissue artefact description for data sharing in human motion measurements. "
                                "J Biomech 62:5-13, doi 10.1016/j.jbiomech.2017.02.004",
        "convention": "right arm (a left arm's mirrored ISB frames mirrored back: Z -> -Z); bone-frame "
                      "quantities in the segment's ISB anatomical frame (Wu et al. 2005); the thorax is assumed "
                      "upright and fixed in the lab (the files hold no thorax)",
        "units": "rotation vectors rad, translations m, drivers rad; features = drivers and their pairwise "
                 "products minus their start values",
        "model": "rigid: rotation vector (about the markers' centroid) and centroid translation of the segment's "
                 "skin-marker cluster in the bone frame = features @ rigid_coef, plus (in a simulation) the held-out "
                 "residual drawn as a smooth random process (segment key 'residual', with how it was measured); "
                 "non-rigid: per data marker, features @ nonrigid_coef_m[k], RMS nonrigid_sd_m; a segment fitted "
                 "with rotation_course false (the humerus) has no mean course of its rotation, only the draw",
    }
    return BoneStaModel(segs, meta, meta["name"])


# --------------------------------------------------------------------------------------------
# Apply
# --------------------------------------------------------------------------------------------
def predict_rigid(seg: SegmentSta, drivers: Mapping[str, np.ndarray], /, *, n_reference: int = 1) -> np.ndarray:
    """The rigid parameters (n, 6) the model predicts for a motion's drivers."""
    return features(drivers, seg.drivers, n_reference=n_reference) @ seg.rigid_coef


def rigid_parameters(seg: SegmentSta, X: np.ndarray, drivers: Mapping[str, np.ndarray], /, *,
                     residual_rng: np.random.Generator | None = None, rate_hz: float | None = None) -> np.ndarray:
    """The cluster's rigid parameters (n, 6) for features X (n, f): the regression's mean course,
    plus one draw of the held-out residual process where the model has one and ``residual_rng``
    and ``rate_hz`` are given (scaled by the drivers' ``humerus_rotation``)."""
    params = X @ seg.rigid_coef
    if seg.residual is not None and residual_rng is not None:
        if rate_hz is None or not rate_hz > 0:
            raise InputError(f"the STA residual process needs the sampling rate, got {rate_hz}")
        if "humerus_rotation" not in drivers:
            raise InputError("the STA residual process needs the driver 'humerus_rotation'")
        params = params + seg.residual.draw(np.asarray(drivers["humerus_rotation"], dtype=float), rate_hz,
                                            residual_rng)
    return params


def rigid_displacements(params: np.ndarray, points: np.ndarray, /) -> np.ndarray:
    """Displacements (n, k, 3) of points (k, 3) in the bone frame under the rigid cluster motion
    ``params`` (n, 6) about the points' centroid."""
    c = points.mean(axis=0)
    Q = Rotation.from_rotvec(params[:, :3]).as_matrix()
    rel = points - c
    return params[:, None, 3:] + np.einsum("nij,kj->nki", Q, rel) - rel[None]


def segment_displacements(seg: SegmentSta, drivers: Mapping[str, np.ndarray], points: np.ndarray,
                          rng: np.random.Generator, /, *, n_reference: int = 1,
                          residual_rng: np.random.Generator | None = None,
                          rate_hz: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rigid, non-rigid) displacements (n, k, 3) m in the bone frame of markers at ``points``
    (k, 3) m in the bone frame: the predicted rigid cluster motion about their centroid (with
    ``residual_rng`` and ``rate_hz``, and a model that has one, plus a draw of the held-out
    residual, ``rigid_parameters``), and for each marker the non-rigid regression of a data marker
    drawn at random (``rng``); both zero at the start posture."""
    X = features(drivers, seg.drivers, n_reference=n_reference)
    rigid = rigid_displacements(rigid_parameters(seg, X, drivers, residual_rng=residual_rng, rate_hz=rate_hz), points)
    nonrigid = np.zeros_like(rigid)
    if seg.nonrigid_coef.size:
        pick = rng.integers(0, seg.nonrigid_coef.shape[0], size=points.shape[0])
        nonrigid = np.einsum("nf,kfc->nkc", X, seg.nonrigid_coef[pick])
    return rigid, nonrigid
