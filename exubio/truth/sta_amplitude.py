"""How large a segment's soft-tissue artefact (STA) is, measured on bone-referenced trials: the
amplitude model behind every angle's stated uncertainty (``exubio.trust.angle_uncertainty``).

For each bone and frame, the skin markers in the bone's frame are fitted by a rigid motion of their
rest shape (Kabsch, ``exubio.calibration.cluster``): a rotation of the cluster about its centroid
(a rotation vector, in the bone's ISB axes), a translation of the centroid, and what no rigid motion
explains (non-rigid, per marker). A left arm's (mirrored) frames are turned into the right arm's
convention, which exubio's model uses. The rest shape is the markers' mean over the rest window, where a
static calibration puts the model points, so the artefact is zero there by construction.

The artefact grows with the motion away from the calibration posture: the arm's motion drags the
skin over the scapula and turns the upper arm's skin about the humerus. The driver is the humerus's
rotation angle from its rest orientation in the lab, theta (rad), as shipped: d = theta; with
``saturation_rad`` = theta_s, d = theta_s tanh(theta / theta_s), an artefact that levels off beyond
theta_s. Per bone and axis the amplitude is the RMS ratio (zero intercept: no artefact at rest)

    a = sqrt(sum_t x(t)^2 / sum_t d(t)^2)

of the rotation vector's component (rad per rad), of the translation's (m per rad), and of the
non-rigid displacement's per coordinate (m per rad); and the rigid motion's whole second moment
C = sum_t x x^T / sum_t d^2 (6 x 6: rotation and translation together, since the skin that lags
a rotation also slides: a cluster over the scapula turns about its centroid and moves up at once,
and only the two together say how the bone's pivot sees it). The STA at a posture is then modelled
as a zero-mean random rigid motion of each segment's markers with covariance C d^2 plus
independent non-rigid displacements; ``exubio.trust.angle_uncertainty`` carries it through the
reconstruction's first-order sensitivity to each angle.

Why the shipped model does not saturate: fitted on three of the four S2M tasks and judged on the
fourth, the Gaussian log-likelihood of the held-out task's cluster motions is highest at theta_s = 0.5
rad on every one of the four (``python studies/sta_driver_form.py``), but the lab's u made with it
covers the bone no better (``python studies/bone_u_driver.py --saturation 0.5 --data DIR``: 8 of 59
task-angle cells below 90 % with it and without) and far worse where the arm turns most: the
behind-the-back reach's ST upward rotation within +-2u in 33 % of its frames against 58 %, Phadke GH
elevation 64 % against 98 %. The four tasks the form is judged on do not reach that far, and a u
that falls with a larger motion is the one error the uncertainty must not make.

Coefficients fitted on the S2M pin trials (Cereatti et al. 2017, J Biomech 62:5-13; doi
10.1016/j.jbiomech.2017.02.004) ship as ``exubio/data/sta_amplitude_s2m.json``; a lab fits its own
with ``fit_sta_amplitude`` on its bone-referenced trials.
"""
from __future__ import annotations

import datetime
import json
from pathlib import Path
from typing import Sequence

import numpy as np

from ..calibration.cluster import cluster_poses
from ..errors import InputError
from ..trust.sta_amplitude import STAAmplitude, saturating
from .lab_run import REST_MAX_DEG, REST_WINDOW_S
from .sta_format import BoneTrial

__all__ = ["segment_sta", "fit_sta_amplitude", "write_sta_amplitude"]

CITATION = ("Cereatti A, Bonci T, Akbarshahi M, et al. (2017) Standardization proposal of soft tissue artefact "
            "description for data sharing in human motion measurements. J Biomech 62:5-13, "
            "doi 10.1016/j.jbiomech.2017.02.004 (ISB STA data-sharing initiative)")


def _rotvec(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    out = np.full((R.shape[0], 3), np.nan)
    ok = np.isfinite(R).all(axis=(1, 2))
    if ok.any():
        out[ok] = Rotation.from_matrix(R[ok]).as_rotvec()
    return out


def _rest(trial: BoneTrial, rate_hz: float) -> np.ndarray:
    hum = trial.segments["humerus"]
    n = max(1, min(trial.n_frames, int(round(REST_WINDOW_S * rate_hz)) + 1))
    c = (np.einsum("ij,nij->n", hum.rotation[0], hum.rotation[:n]) - 1.0) / 2.0
    turned = np.degrees(np.arccos(np.clip(c, -1, 1)))
    return np.flatnonzero(turned < REST_MAX_DEG)


def humerus_driver(trial: BoneTrial, rest: np.ndarray) -> np.ndarray:
    """theta (n,) rad: the humerus's rotation angle from its mean rest orientation, in the lab."""
    from scipy.spatial.transform import Rotation

    hum = trial.segments["humerus"]
    R0 = Rotation.from_matrix(hum.rotation[rest]).mean().as_matrix()
    c = (np.einsum("ij,nij->n", R0, hum.rotation) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def segment_sta(trial: BoneTrial, bone: str, rest: np.ndarray) -> dict[str, np.ndarray]:
    """The rigid/non-rigid split of one bone's skin markers in its frame: ``rotation`` (n, 3) rad
    (rotation vector, bone axes), ``translation`` (n, 3) m (the centroid's), ``nonrigid`` (n, k, 3) m.
    The file's gap-filled markers are used; markers NaN at rest are left out."""
    seg = trial.segments[bone]
    m = seg.markers_bone
    seen = np.isfinite(m[rest]).all(axis=2)  # (rest, k)
    keep = seen.any(axis=0)
    shape = np.array([m[rest][seen[:, j], j].mean(axis=0) if keep[j] else np.full(3, np.nan) for j in range(m.shape[1])])
    m, shape = m[:, keep], shape[keep]
    if shape.shape[0] < 3:
        raise InputError(f"{trial.path}: the {bone} has {shape.shape[0]} markers at rest; 3 are needed for its STA")
    centroid = shape.mean(axis=0)
    R, t, _ = cluster_poses(shape - centroid, m)
    fitted = np.einsum("nab,kb->nka", R, shape - centroid) + t[:, None, :]
    rot, tra, nonrigid = _rotvec(R), t - centroid, m - fitted
    if seg.side == "left":  # the format's left frames are mirrored (Z -> -Z): in the right arm's convention
        M = np.diag([1.0, 1.0, -1.0])  # positions p -> M p, rotation vectors w -> -M w (an axial vector)
        rot, tra, nonrigid = -rot @ M, tra @ M, nonrigid @ M
    return {"rotation": rot, "translation": tra, "nonrigid": nonrigid}


def _rms_ratio(x: np.ndarray, theta: np.ndarray) -> np.ndarray:
    ok = np.isfinite(x).all(axis=-1) & np.isfinite(theta)
    d = float(np.sum(theta[ok] ** 2))
    if d <= 0:
        return np.zeros(x.shape[-1])
    return np.sqrt(np.sum(x[ok] ** 2, axis=0) / d)


def fit_sta_amplitude(trials: Sequence[tuple[BoneTrial, float]], /, *, source: str = "",
                      saturation_rad: float | None = None) -> STAAmplitude:
    """The amplitude model (module docstring) of bone-referenced ``trials`` ((trial, rate Hz) pairs),
    pooled over their frames, per unit of the skin's driver with ``saturation_rad``. Bones fitted:
    those of ``exubio.trust.sta_amplitude.SEGMENTS_WITH_DATA`` present in the trials."""
    pooled: dict[str, dict[str, list]] = {}
    cross_num, cross_den = np.zeros((6, 6)), 0.0
    for trial, rate in trials:
        rest = _rest(trial, rate)
        theta = saturating(humerus_driver(trial, rest), saturation_rad)
        both = {}
        for bone in ("scapula", "humerus"):
            if bone not in trial.segments:
                continue
            s = segment_sta(trial, bone, rest)
            both[bone] = np.concatenate([s["rotation"], s["translation"]], axis=1)
            p = pooled.setdefault(bone, {"rotation": [], "translation": [], "nonrigid": [], "theta": [], "theta_k": []})
            p["rotation"].append(s["rotation"])
            p["translation"].append(s["translation"])
            k = s["nonrigid"].shape[1]
            p["nonrigid"].append(s["nonrigid"].reshape(-1, 3))
            p["theta"].append(theta)
            p["theta_k"].append(np.repeat(theta, k))
        if len(both) == 2:
            ok = np.isfinite(both["scapula"]).all(axis=1) & np.isfinite(both["humerus"]).all(axis=1) & np.isfinite(theta)
            cross_num += both["scapula"][ok].T @ both["humerus"][ok]
            cross_den += float(np.sum(theta[ok] ** 2))
    if not pooled:
        raise InputError("fit_sta_amplitude: no trial with a scapula or a humerus")
    rot, tra, nr, rigid = {}, {}, {}, {}
    for bone, p in pooled.items():
        th = np.concatenate(p["theta"])
        rot[bone] = _rms_ratio(np.concatenate(p["rotation"]), th)
        tra[bone] = _rms_ratio(np.concatenate(p["translation"]), th)
        nr[bone] = _rms_ratio(np.concatenate(p["nonrigid"]), np.concatenate(p["theta_k"]))
        x = np.concatenate([np.concatenate(p["rotation"]), np.concatenate(p["translation"])], axis=1)
        ok = np.isfinite(x).all(axis=1) & np.isfinite(th)
        rigid[bone] = x[ok].T @ x[ok] / max(float(np.sum(th[ok] ** 2)), 1e-300)
    files = ", ".join(t.path.name for t, _ in trials)
    cross = {"scapula|humerus": cross_num / cross_den} if cross_den > 0 else {}
    return STAAmplitude(rotation=rot, translation=tra, nonrigid=nr, rigid=rigid, cross=cross,
                        source=source or f"fitted on {files} ({datetime.date.today().isoformat()})",
                        saturation_rad=saturation_rad)


def write_sta_amplitude(amplitude: STAAmplitude, path: str | Path, /, *, citation: str = CITATION) -> Path:
    """The model as JSON (the shipped file's layout)."""
    path = Path(path)
    data = amplitude.to_json()
    data["citation"] = citation
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path
