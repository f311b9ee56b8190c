"""The geometry of the 3D view (``exubio.report.viewer``), in mm in the ISB thorax frame: the
animation frames shown, the bones of every segment, the segment each model point moves with, the
thorax ellipsoid mesh, and one method's scene data (bones, markers, model points, residual lines).
"""
from __future__ import annotations

import contextlib
import math
import warnings
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from exubio.report.viewer_results import _Result
from exubio.types import Model

_RIGID_TOLERANCE_M = 1e-3  # a model point moving < 1 mm in a segment's frame belongs to that segment


def _frame_selection(n: int, max_frames: int) -> tuple[np.ndarray, int]:
    step = max(1, math.ceil(n / max_frames))
    return np.arange(0, n, step), step


def _nearest(times: np.ndarray, t: np.ndarray) -> np.ndarray:
    idx = np.clip(np.searchsorted(times, t), 1, max(1, len(times) - 1))
    if len(times) == 1:
        return np.zeros(len(t), dtype=int)
    left = times[idx - 1]
    right = times[np.minimum(idx, len(times) - 1)]
    return np.where(np.abs(t - left) <= np.abs(right - t), idx - 1, idx)


def _bone_points(model: Model, marker_names: set[str]) -> tuple[list[tuple[str, np.ndarray]], list[str]]:
    """Pairs of (segment, local position) as line vertices: origin -> child joint centre and
    origin -> each landmark, two vertices per line; and a hover label per vertex."""
    verts: list[tuple[str, np.ndarray]] = []
    labels: list[str] = []
    zero = np.zeros(3)
    for seg in model.segments:
        origin_name = next((n for n, v in seg.points.items() if np.allclose(v, 0.0)), "origin")
        targets = [(f"{child.name} joint ({child.joint.name})", child.joint.centre_m)
                   for child in model.segments if child.parent == seg.name and child.joint is not None]
        seen: list[np.ndarray] = [zero]
        for name, local in seg.points.items():
            if name in marker_names or any(np.allclose(local, s) for s in seen):
                continue  # markers are drawn as model points; aliases (MAN = IJ) once
            seen.append(np.asarray(local))
            targets.append((name, local))
        for name, local in targets:
            verts += [(seg.name, zero), (seg.name, np.asarray(local, dtype=float))]
            labels += [f"{seg.name}: {origin_name}", f"{seg.name}: {name}"]
    return verts, labels


def _marker_segments(model: Model, kin, q: np.ndarray, points_m: np.ndarray, names: Sequence[str]) -> list[str]:
    """The segment each model point moves rigidly with: the one in whose frame its position varies
    least (and < 1 mm); "" when none. Among segments rigidly linked in this trial (a held joint:
    the same variation within 1 µm), the one whose origin is nearest."""
    R, p = kin.poses(q)  # (n, s, 3, 3), (n, s, 3)
    local = np.einsum("nsji,nskj->nski", R, points_m[:, None, :, :] - p[:, :, None, :])  # (n, s, k, 3)
    with np.errstate(invalid="ignore"), _quiet():
        spread = np.nanmax(np.linalg.norm(local - np.nanmean(local, axis=0), axis=-1), axis=0)  # (s, k)
        dist = np.nanmean(np.linalg.norm(points_m[:, None, :, :] - p[:, :, None, :], axis=-1), axis=0)
    out = []
    for k in range(len(names)):
        sk = np.nan_to_num(spread[:, k], nan=np.inf)
        rigid = np.flatnonzero((sk < _RIGID_TOLERANCE_M) & (sk <= sk.min() + 1e-6))
        out.append(model.segments[int(rigid[np.argmin(dist[rigid, k])])].name if rigid.size else "")
    return out


@contextlib.contextmanager
def _quiet():
    """No RuntimeWarnings of NaN-only slices (a marker absent throughout)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def _ellipsoid_mesh(model: Model, n_lat: int = 18, n_lon: int = 36) -> dict[str, Any]:
    c = np.asarray(model.ellipsoid.centre_m) * 1000.0
    r = np.asarray(model.ellipsoid.radii_m) * 1000.0
    lat = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 1)[1:-1]
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    ring = np.stack([np.cos(la) * np.cos(lo), np.sin(la), np.cos(la) * np.sin(lo)], axis=-1).reshape(-1, 3)
    pts = np.vstack([[0, -1, 0], ring, [0, 1, 0]]) * r + c  # south pole, rings, north pole
    south, north, n_ring = 0, len(pts) - 1, len(lat)

    def v(a: int, b: int) -> int:  # vertex of ring a, meridian b
        return 1 + a * n_lon + (b % n_lon)

    triangles = []
    for b in range(n_lon):
        triangles.append((south, v(0, b + 1), v(0, b)))
        triangles.append((north, v(n_ring - 1, b), v(n_ring - 1, b + 1)))
        for a in range(n_ring - 1):
            triangles.append((v(a, b), v(a, b + 1), v(a + 1, b)))
            triangles.append((v(a, b + 1), v(a + 1, b + 1), v(a + 1, b)))
    i, j, k = (list(t) for t in zip(*triangles))
    return {"x": _r(pts[:, 0]), "y": _r(pts[:, 1]), "z": _r(pts[:, 2]), "i": i, "j": j, "k": k}


def _r(a: np.ndarray) -> list:
    """Rounded to 0.1 mm, NaN -> None (a gap in a plotly line)."""
    flat = np.round(np.asarray(a, dtype=float).ravel(), 1)
    return [None if not math.isfinite(x) else x for x in flat.tolist()]


def _with_breaks(pts: np.ndarray) -> np.ndarray:
    """(n_lines * 2, 3) vertices -> (n_lines * 3, 3) with a NaN row after each pair."""
    pairs = pts.reshape(-1, 2, 3)
    return np.concatenate([pairs, np.full((pairs.shape[0], 1, 3), np.nan)], axis=1).reshape(-1, 3)


@dataclass
class _SceneData:
    bones: np.ndarray  # (n_shown, v, 3) mm, with NaN breaks
    measured: np.ndarray  # (n_shown, k, 3) mm
    model_points: np.ndarray  # (n_shown, k, 3) mm
    residual_lines: np.ndarray  # (n_shown, 3k, 3) mm
    mean_residual_mm: float
    constraint_mismatch: float


def _scene_data(res: _Result, model: Model, kin, bone_set, frames: np.ndarray) -> _SceneData:
    r = res.recon
    q = r.q_rad[frames]
    bones = np.stack([_with_breaks(b) for b in kin.points(q, bone_set)]) * 1000.0
    meas = r.measured_m[frames] * 1000.0
    mod = r.model_points_m[frames] * 1000.0
    res_lines = np.concatenate([meas[:, :, None, :], mod[:, :, None, :], np.full(meas.shape[:2] + (1, 3), np.nan)],
                               axis=2).reshape(len(frames), -1, 3)
    with _quiet():
        mean_res = float(np.nanmean(r.residuals_m)) * 1000.0 if np.isfinite(r.residuals_m).any() else float("nan")
    stored = np.asarray(r.constraint, dtype=float)
    mismatch = float("nan")
    if stored.shape == (r.n_frames, 2):
        diff = np.abs(kin.g(q) - stored[frames])
        if np.isfinite(diff).any():
            mismatch = float(np.nanmax(diff))
    return _SceneData(bones, meas, mod, res_lines, mean_res, mismatch)
