"""An interactive 3D view of a reconstruction: one self-contained HTML file (``exubio view``).

``write_view([trial.pf.npz], view.html)`` reads the result (and the result of the trial's other
method beside it, ``trial.ls.npz``), recovers the model the run used, and writes one HTML page that
works offline, without a server: per method a 3D scene with the bones of every segment, the
measured markers, the model points, the residual line between each marker and its model point and
the thorax ellipsoid; a time slider and a play button; PF and LS side by side, their cameras
linked; the quality verdict of each method in the title. Positions are shown in millimetres in the
ISB thorax frame of the model (X anterior, Y superior, Z right).

Library: plotly (``plotly.io.to_html`` with ``include_plotlyjs=True``). It embeds plotly.js (about
4.8 MB, MIT) in the page, so the file opens offline in any browser with WebGL; 3D scatter/line/mesh
traces, animation frames, the slider and the play/pause buttons are built in and documented, and
it is a widely used, actively released library with no further runtime dependency than narwhals.
Hand-writing WebGL/three.js code would mean shipping and maintaining our own renderer.

What is drawn (everything from the result files plus the model file the run names):
- bones: for every segment a line from its origin (its joint centre; IJ for the thorax) to the
  joint centre of each child and to each of its anatomical landmarks (model points that are not
  markers of the result), at the reconstructed q (``exubio.model.kinematics``);
- measured markers: the targets the method tracked (thorax frame, filtered), ``measured_m``;
- model points: ``model_points_m``, coloured by the segment they move rigidly with;
- residual lines: measured marker to model point, per frame (the springs of PF);
- the thorax ellipsoid of the model (axis-aligned in the thorax frame: centre and radii).

Long trials are decimated to at most ``MAX_ANIMATION_FRAMES`` animation frames (one frame
in k); the page says so. The page embeds its own summary as JSON in
``<script id="exubio-data" type="application/json">`` (frames, times, markers, methods, verdicts,
model file) for tests and scripts, and records JavaScript errors in ``<pre id="exubio-errors">``.
``view.html#t=4.5`` opens the view at the frame nearest 4.5 s.

The model: the ``model`` path in the result's metadata (the YAML file the run read: the generic
model or a calibrated ``<trial>.model.yaml``), else a file of that name beside the result, else
the shipped generic model when the result names it; ``model_path=`` overrides all of these. The
model is checked against the result (coordinate names must match; the ellipsoid constraint g
recomputed from q must match the stored one, otherwise the page warns that the bones may not be
those of the run).
"""
from __future__ import annotations

import contextlib
import html
import json
import logging
import math
import os
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from exubio.errors import ExubioError, InputError
from exubio.io.results import atomic_write, read_npz, read_npz_metadata, writable_folder
from exubio.types import Model, Reconstruction

log = logging.getLogger(__name__)

MAX_ANIMATION_FRAMES = 300
_METHOD_ORDER = ("pf", "ls")
_METHOD_TITLES = {"pf": "PF (potential field)", "ls": "LS (least squares)"}
_VERDICT_COLOURS = {"ok": "#2ca02c", "check": "#ff7f0e", "fail": "#d62728"}
_BONE_COLOUR = "#7a4b1e"
_MEASURED_COLOUR = "#1f4fd1"
_RESIDUAL_COLOUR = "#e0115f"
_ELLIPSOID_COLOUR = "#7fb3d5"
_SEGMENT_COLOURS = ("#7f7f7f", "#ff7f0e", "#2ca02c", "#9467bd", "#17becf", "#e377c2", "#bcbd22", "#8c564b")
_CONSTRAINT_TOLERANCE = 1e-6  # |g recomputed - g stored| above this: the model is not the run's
_RIGID_TOLERANCE_M = 1e-3  # a model point moving < 1 mm in a segment's frame belongs to that segment
_PLOT_ID = "exubio-plot"


@dataclass
class _Result:
    path: Path
    recon: Reconstruction
    metadata: dict[str, Any]
    verdict: str = "unknown"
    reasons: list[Any] = field(default_factory=list)  # as the summary gives them: {code, level, message} (or text)
    verdict_source: str = ""


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
def write_view(result_paths: Sequence[str | os.PathLike], out_html: str | os.PathLike, /, *,
               overwrite: bool = False, model_path: str | os.PathLike | None = None,
               max_frames: int = MAX_ANIMATION_FRAMES) -> Path:
    """Write the 3D view of one trial's results as a self-contained HTML file; returns its path.

    result_paths: one ``<trial>.<method>.npz`` (the result of the trial's other method beside it,
    e.g. ``<trial>.ls.npz`` for ``<trial>.pf.npz``, is found and shown side by side), or the
    results to show. model_path: the model YAML, when the one the result names cannot be found
    (or to override it). max_frames: at most this many animation frames (one frame in k).
    Bad input (missing file, not an exubio result, a model that does not fit it) raises
    InputError naming the file; an existing ``out_html`` is replaced only with ``overwrite``.
    """
    out = Path(out_html)
    if out.is_dir():
        raise InputError(f"{out}: output file expected, but this is a folder")
    if out.exists() and not overwrite:
        raise InputError(f"{out}: file already exists; pass --overwrite to replace it")
    if max_frames < 1:
        raise InputError(f"max_frames must be >= 1, got {max_frames}")
    paths = find_results(result_paths)
    results = [_load_result(p) for p in paths]
    model, model_file = _load_model(results[0], model_path)
    page, _ = _build_page(results, model, model_file, max_frames=max_frames)
    writable_folder(out.parent, label=str(out))

    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(page)

    atomic_write(out, writer)
    log.info("wrote %s (%d bytes)", out, out.stat().st_size)
    return out


def find_results(result_paths: Sequence[str | os.PathLike]) -> list[Path]:
    """The result files to show: the given ones, plus, for a single ``<trial>.<method>.npz``, the
    results of the trial's other methods beside it. PF first, then LS. InputError for a missing
    file."""
    if isinstance(result_paths, (str, os.PathLike)):
        result_paths = [result_paths]
    paths: list[Path] = []
    for p in result_paths:
        path = Path(p)
        if not path.is_file():
            raise InputError(f"{path}: file not found" if not path.exists() else f"{path}: not a file")
        if path.resolve() not in [q.resolve() for q in paths]:
            paths.append(path)
    if not paths:
        raise InputError("no result file given (expected a <trial>.<method>.npz)")
    if len(paths) == 1:
        paths += _siblings(paths[0])
    return sorted(paths, key=lambda p: _method_rank(_method_from_name(p) or ""))


# --------------------------------------------------------------------------------------------
# Reading the results and the model
# --------------------------------------------------------------------------------------------
def _method_rank(method: str) -> tuple[int, str]:
    return (_METHOD_ORDER.index(method) if method in _METHOD_ORDER else len(_METHOD_ORDER), method)


def _method_from_name(path: Path) -> str | None:
    """``pf`` for ``trial.pf.npz``; None when the name has no method part."""
    parts = path.name.split(".")
    if len(parts) >= 3 and parts[-1] == "npz" and parts[-2]:
        return parts[-2]
    return None


def _siblings(path: Path) -> list[Path]:
    """Results of the same trial by the other methods: ``<trial>.<other>.npz`` in the same folder
    whose stored method is ``<other>``."""
    method = _method_from_name(path)
    if method is None:
        return []
    trial = path.name[: -len(f".{method}.npz")]
    out = []
    for cand in sorted(path.parent.glob(f"{trial}.*.npz")):
        other = _method_from_name(cand)
        if other is None or other == method or cand.name != f"{trial}.{other}.npz" or not cand.is_file():
            continue
        try:
            with np.load(cand, allow_pickle=False) as data:
                stored = str(data["method"]) if "method" in data.files else None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile):  # a damaged sibling is not shown
            stored = None
        if stored == other:
            out.append(cand)
        else:
            log.warning("%s: not shown beside %s (not an exubio result of method '%s')", cand, path, other)
    return out


def _load_result(path: Path) -> _Result:
    try:  # read_npz names the file for a missing, unreadable or non-.npz file
        recon = read_npz(path)
        meta = read_npz_metadata(path)
    except InputError:
        raise
    except (ValueError, KeyError, IndexError, TypeError, AttributeError) as exc:  # a foreign .npz
        raise InputError(f"{path}: not an exubio result ({type(exc).__name__}: {exc})") from exc
    _check_shapes(path, recon)
    res = _Result(path, recon, meta if isinstance(meta, dict) else {})
    summary_path = path.with_name(path.name[: -len(".npz")] + ".summary.json") if path.name.endswith(".npz") else None
    quality = None
    if summary_path is not None and summary_path.is_file():
        try:
            quality = json.loads(summary_path.read_text(encoding="utf-8")).get("quality")
            res.verdict_source = str(summary_path)
        except (OSError, ValueError, AttributeError) as exc:
            log.warning("%s: cannot read the verdict (%s)", summary_path, exc)
    if quality is None and res.metadata.get("quality") is not None:
        quality = res.metadata["quality"]
        res.verdict_source = f"{path} (metadata)"
    if isinstance(quality, dict):
        res.verdict = str(quality.get("verdict", "unknown"))
        res.reasons = [{str(k): str(v) for k, v in r.items()} if isinstance(r, dict) else str(r)
                       for r in quality.get("reasons") or []]
    elif isinstance(quality, str):
        res.verdict = quality
    return res


def _check_shapes(path: Path, r: Reconstruction) -> None:
    n = r.time_s.shape[0] if r.time_s.ndim == 1 else -1
    k = len(r.marker_names)
    problems = []
    if n < 1:
        problems.append(f"time_s has shape {r.time_s.shape}, expected (n_frames >= 1,)")
    if r.q_rad.shape != (n, len(r.coordinate_names)):
        problems.append(f"q_rad has shape {r.q_rad.shape}, expected ({n}, {len(r.coordinate_names)})")
    for name in ("model_points_m", "measured_m"):
        if getattr(r, name).shape != (n, k, 3):
            problems.append(f"{name} has shape {getattr(r, name).shape}, expected ({n}, {k}, 3)")
    if problems:
        raise InputError(f"{path}: not a consistent exubio result: " + "; ".join(problems))


def _model_candidates(res: _Result) -> list[Path]:
    named = str(res.metadata.get("model") or "")
    out: list[Path] = []
    if named:
        p = Path(named)
        out.append(p)
        if not p.is_absolute():
            out.append(res.path.parent / p)
        out.append(res.path.parent / p.name)  # results (and a calibrated model) moved together
    return out


def _load_model(res: _Result, model_path: str | os.PathLike | None) -> tuple[Model, Path]:
    from exubio.model.load import DEFAULT_MODEL, load_model

    if model_path is not None:
        chosen = Path(model_path)
        if not chosen.is_file():
            raise InputError(f"{chosen}: model file not found")
    else:
        candidates = _model_candidates(res)
        chosen = next((c for c in candidates if c.is_file()), None)
        named = str(res.metadata.get("model") or "")
        if chosen is None and named and Path(named).name == Path(DEFAULT_MODEL).name:
            chosen = Path(DEFAULT_MODEL)  # the shipped generic model, installed elsewhere
        if chosen is None:
            raise InputError(
                f"{res.path}: cannot find the model the result was made with (metadata names "
                f"'{named or 'none'}'; looked at {[str(c) for c in candidates]}); give the model YAML "
                f"(model_path=..., the calibrated <trial>.model.yaml or the generic model)")
    try:
        model = load_model(chosen)
    except ExubioError as exc:
        raise InputError(f"{chosen}: cannot read the model ({exc})") from exc
    coords = tuple(res.recon.coordinate_names)
    if tuple(model.coordinate_names) != coords:
        raise InputError(f"{chosen}: the model's coordinates {list(model.coordinate_names)} are not those of "
                         f"{res.path} {list(coords)}; give the model the result was made with")
    return model, chosen


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------------
# The page
# --------------------------------------------------------------------------------------------
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


def _verdict_html(res: _Result) -> str:
    colour = _VERDICT_COLOURS.get(res.verdict, "#555555")
    return f"{res.recon.method.upper()}: <span style='color:{colour}'><b>{html.escape(res.verdict.upper())}</b></span>"


def _build_page(results: list[_Result], model: Model, model_file: Path, *,
                max_frames: int = MAX_ANIMATION_FRAMES) -> tuple[str, dict[str, Any]]:
    """The HTML page and the data summary embedded in it."""
    import plotly.io as pio

    from exubio.model.kinematics import Kinematics

    kin = Kinematics(model)
    first = results[0].recon
    frames, step = _frame_selection(first.n_frames, max_frames)
    times = first.time_s[frames]
    marker_names = list(first.marker_names)
    verts, vert_labels = _bone_points(model, set().union(*(r.recon.marker_names for r in results)))
    bone_set = kin.point_set(verts)
    bone_labels = [x for pair in zip(vert_labels[::2], vert_labels[1::2]) for x in (*pair, "")]
    scenes: list[_SceneData] = []
    seg_of: list[list[str]] = []
    notes: list[str] = []
    for res in results:
        fr = frames if res is results[0] else _nearest(res.recon.time_s, times)
        scenes.append(_scene_data(res, model, kin, bone_set, fr))
        seg_of.append(_marker_segments(model, kin, res.recon.q_rad[fr], res.recon.model_points_m[fr],
                                       res.recon.marker_names))
        if res is not results[0] and (res.recon.n_frames != first.n_frames
                                      or not np.allclose(res.recon.time_s, first.time_s)):
            notes.append(f"{res.recon.method.upper()} has other sample times than {first.method.upper()}: "
                         f"the nearest sample is shown.")
        mism = scenes[-1].constraint_mismatch
        if math.isfinite(mism) and mism > _CONSTRAINT_TOLERANCE:
            notes.append(f"WARNING: the model {model_file} does not reproduce the ellipsoid constraint stored in "
                         f"{res.path.name} (|Δg| up to {mism:.2g}): it is probably not the model of the run, "
                         f"the bones and the ellipsoid may be misplaced.")
            log.warning(notes[-1])
    trial = Path(str(results[0].metadata.get("trial") or results[0].path.name)).name
    if step > 1:
        notes.insert(0, f"Long trial: one frame in {step} is shown ({len(frames)} of {first.n_frames} frames; "
                        f"at most {max_frames} animation frames).")
    else:
        notes.insert(0, f"All {first.n_frames} frames are shown.")

    fig, n_animated = _figure(results, scenes, seg_of, times, bone_labels, model, trial, frames_note=notes[0])
    frame_ms = int(np.clip(1000.0 * np.median(np.diff(times)) if len(times) > 1 else 100, 30, 200))
    fig["layout"]["updatemenus"] = [_play_buttons(frame_ms)]
    fig["layout"]["sliders"] = [_slider(times)]
    data = {
        "schema": "exubio-view/1",
        "trial": trial,
        "methods": [r.recon.method for r in results],
        "sources": [str(r.path) for r in results],
        "verdicts": {r.recon.method: r.verdict for r in results},
        "verdict_reasons": {r.recon.method: r.reasons for r in results},
        "verdict_sources": {r.recon.method: r.verdict_source for r in results},
        "n_frames_total": first.n_frames,
        "n_frames_shown": len(frames),
        "frame_step": step,
        "max_animation_frames": max_frames,
        "time_s": [round(float(t), 6) for t in times],
        "marker_names": marker_names,
        "marker_segments": dict(zip(marker_names, seg_of[0])),
        "segments": list(model.segment_names),
        "mean_residual_mm": {r.recon.method: _round_or_none(s.mean_residual_mm) for r, s in zip(results, scenes)},
        "model": str(model_file),
        "model_constraint_mismatch": {r.recon.method: _round_or_none(s.constraint_mismatch, 12)
                                      for r, s in zip(results, scenes)},
        "units": "mm",
        "frame": "ISB thorax frame: X anterior, Y superior, Z right",
        "animated_traces_per_scene": n_animated,
        "notes": notes,
    }
    div = pio.to_html(fig, include_plotlyjs=True, full_html=False, auto_play=False, div_id=_PLOT_ID,
                      post_script=_POST_SCRIPT, default_height="92vh", default_width="100%", validate=False,
                      config={"responsive": True, "displaylogo": False})
    return _page(results, trial, data, div, notes), data


def _round_or_none(x: float, nd: int = 3):
    return round(float(x), nd) if math.isfinite(x) else None


def _figure(results, scenes, seg_of, times, bone_labels, model, trial, *, frames_note):
    """The plotly figure as a dict (data, layout, frames) and the number of animated traces per scene."""
    n_scenes = len(results)
    gap = 0.02
    width = (1.0 - gap * (n_scenes - 1)) / n_scenes
    allpts = [model_pt for s in scenes for model_pt in (s.bones, s.measured, s.model_points)]
    ell = _ellipsoid_mesh(model)
    stack = np.concatenate([a.reshape(-1, 3) for a in allpts] +
                           [np.column_stack([ell["x"], ell["y"], ell["z"]]).astype(float)])
    lo, hi = np.nanmin(stack, axis=0) - 30.0, np.nanmax(stack, axis=0) + 30.0
    span = hi - lo
    aspect = span / span.max()
    seg_colour = {s: _SEGMENT_COLOURS[i % len(_SEGMENT_COLOURS)] for i, s in enumerate(model.segment_names)}
    traces: list[dict] = []
    animated: list[int] = []
    layout: dict[str, Any] = {
        "title": {"text": f"exubio — {html.escape(trial)} — " + " · ".join(_verdict_html(r) for r in results)
                  + f"<br><span style='font-size:12px'>{html.escape(frames_note)} Units: mm, ISB thorax frame "
                    "(X anterior, Y superior, Z right).</span>",
                  "x": 0.5, "xanchor": "center", "y": 0.97, "yanchor": "top"},
        "template": _template(),
        "margin": {"l": 0, "r": 0, "t": 110, "b": 95},
        "legend": {"orientation": "h", "x": 0.5, "xanchor": "center", "y": 1.0, "yanchor": "bottom"},
        "annotations": [],
        "uirevision": "exubio",
    }
    for s, (res, sc) in enumerate(zip(results, scenes)):
        scene = "scene" if s == 0 else f"scene{s + 1}"
        x0 = s * (width + gap)

        def axis(title: str, i: int) -> dict:
            return {"title": {"text": title}, "range": [float(lo[i]), float(hi[i])], "autorange": False, "nticks": 5}

        layout[scene] = {
            "domain": {"x": [x0, x0 + width], "y": [0.0, 0.94]},
            "xaxis": axis("X anterior (mm)", 0), "yaxis": axis("Y superior (mm)", 1), "zaxis": axis("Z right (mm)", 2),
            "aspectmode": "manual", "aspectratio": {"x": aspect[0], "y": aspect[1], "z": aspect[2]},
            "camera": {"up": {"x": 0, "y": 1, "z": 0}, "eye": {"x": 1.25, "y": 0.25, "z": 0.65},
                       "center": {"x": 0, "y": 0, "z": 0}},
        }
        title = _METHOD_TITLES.get(res.recon.method, res.recon.method.upper())
        res_txt = f"{sc.mean_residual_mm:.2f} mm" if math.isfinite(sc.mean_residual_mm) else "n/a"
        layout["annotations"].append({
            "text": f"<b>{html.escape(title)}</b> — verdict {_verdict_html(res).split(': ', 1)[1]}, "
                    f"mean residual {res_txt}",
            "x": x0 + width / 2, "y": 0.99, "xref": "paper", "yref": "paper", "showarrow": False,
            "xanchor": "center", "yanchor": "top", "font": {"size": 13}})
        show = s == 0
        names = list(res.recon.marker_names)
        colours = [seg_colour.get(g, "#000000") for g in seg_of[s]]
        traces.append({"type": "mesh3d", "scene": scene, "name": "thorax ellipsoid", "legendgroup": "ellipsoid",
                       "showlegend": show, **ell, "color": _ELLIPSOID_COLOUR, "opacity": 0.22,
                       "hoverinfo": "skip", "flatshading": False})
        first = [
            {"type": "scatter3d", "scene": scene, "mode": "lines+markers", "name": "bones",
             "legendgroup": "bones", "showlegend": show, "line": {"color": _BONE_COLOUR, "width": 7},
             "marker": {"color": _BONE_COLOUR, "size": 2.5}, "text": bone_labels, "hoverinfo": "text",
             "connectgaps": False},
            {"type": "scatter3d", "scene": scene, "mode": "markers", "name": "measured markers",
             "legendgroup": "measured", "showlegend": show,
             "marker": {"color": _MEASURED_COLOUR, "size": 6, "symbol": "circle-open"},
             "text": [f"{n} (measured)" for n in names], "hoverinfo": "text"},
            {"type": "scatter3d", "scene": scene, "mode": "markers", "name": "model points",
             "legendgroup": "model", "showlegend": show,
             "marker": {"color": colours, "size": 4, "symbol": "diamond",
                        "line": {"color": "#000000", "width": 1}},
             "text": [f"{n} (model point, {g or 'segment?'})" for n, g in zip(names, seg_of[s])],
             "hoverinfo": "text"},
            {"type": "scatter3d", "scene": scene, "mode": "lines", "name": "residuals (marker to model point)",
             "legendgroup": "residuals", "showlegend": show, "line": {"color": _RESIDUAL_COLOUR, "width": 4},
             "hoverinfo": "skip", "connectgaps": False},
        ]
        for tr in first:
            animated.append(len(traces))
            traces.append(tr)
    per_scene = 4

    def frame_data(i: int) -> list[dict]:
        out = []
        for sc in scenes:
            for arr in (sc.bones[i], sc.measured[i], sc.model_points[i], sc.residual_lines[i]):
                out.append({"x": _r(arr[:, 0]), "y": _r(arr[:, 1]), "z": _r(arr[:, 2])})
        return out

    initial = frame_data(0)
    for idx, upd in zip(animated, initial):
        traces[idx].update(upd)
    frames = [{"name": _frame_name(i), "data": frame_data(i), "traces": animated} for i in range(len(times))]
    return {"data": traces, "layout": layout, "frames": frames}, per_scene


def _template() -> dict:
    import plotly.io as pio

    return pio.templates["plotly_white"].to_plotly_json()


def _frame_name(i: int) -> str:
    return f"f{i}"


def _play_buttons(frame_ms: int) -> dict:
    return {
        "type": "buttons", "direction": "left", "showactive": False, "x": 0.0, "y": -0.01,
        "xanchor": "left", "yanchor": "top", "pad": {"t": 10, "r": 10},
        "buttons": [
            {"label": "▶ Play", "method": "animate",
             "args": [None, {"frame": {"duration": frame_ms, "redraw": True}, "fromcurrent": True,
                             "transition": {"duration": 0}, "mode": "immediate"}]},
            {"label": "❚❚ Pause", "method": "animate",
             "args": [[None], {"frame": {"duration": 0, "redraw": False}, "mode": "immediate",
                               "transition": {"duration": 0}}]},
        ],
    }


def _slider(times: np.ndarray) -> dict:
    return {
        "active": 0, "x": 0.16, "len": 0.82, "y": -0.01, "yanchor": "top", "pad": {"t": 10, "b": 0},
        "currentvalue": {"prefix": "t = ", "suffix": " s", "visible": True, "xanchor": "left"},
        "transition": {"duration": 0},
        "steps": [{"label": f"{t:.2f}", "method": "animate",
                   "args": [[_frame_name(i)], {"mode": "immediate", "frame": {"duration": 0, "redraw": True},
                                                  "transition": {"duration": 0}}]}
                  for i, t in enumerate(times)],
    }


# Runs after the plot and its frames exist: link the cameras of the scenes, and record in the
# DOM that the plot rendered (its frame and trace counts), for a headless browser to check.
_POST_SCRIPT = """
var gd = document.getElementById('{plot_id}');
var syncing = false;
gd.on('plotly_relayout', function(ev) {
  if (syncing) { return; }
  var cam = null;
  Object.keys(ev).forEach(function(k) { if (/^scene\\d*\\.camera$/.test(k)) { cam = ev[k]; } });
  if (!cam) { return; }
  var upd = {};
  Object.keys(gd._fullLayout).forEach(function(k) { if (/^scene\\d*$/.test(k)) { upd[k + '.camera'] = cam; } });
  syncing = true;
  Plotly.relayout(gd, upd).then(function() { syncing = false; }, function() { syncing = false; });
});
function exubioRendered() {
  var frames = (gd._transitionData && gd._transitionData._frames) ? gd._transitionData._frames.length : -1;
  var gl = gd.querySelectorAll('canvas').length;
  var status = document.getElementById('exubio-status');
  status.setAttribute('data-frames', String(frames));
  status.setAttribute('data-traces', String(gd.data.length));
  status.setAttribute('data-canvases', String(gl));
  var external = (window.performance && performance.getEntriesByType ? performance.getEntriesByType('resource') : [])
    .map(function(r) { return r.name; }).filter(function(u) { return !/^(file|data|blob|about):/.test(u); });
  status.setAttribute('data-external', external.join(' '));
  status.textContent = 'rendered: ' + frames + ' frames, ' + gd.data.length + ' traces, ' + gl + ' canvases';
}
// a time in the address, e.g. view.html#t=4.5, shows the frame nearest that time
var hashTime = /(?:^#|&)t=([0-9.]+)/.exec(window.location.hash);
if (hashTime && gd._transitionData && gd._transitionData._frames.length) {
  var fr = gd._transitionData._frames, data = JSON.parse(document.getElementById('exubio-data').textContent);
  var best = 0, t = parseFloat(hashTime[1]);
  data.time_s.forEach(function(v, i) { if (Math.abs(v - t) < Math.abs(data.time_s[best] - t)) { best = i; } });
  Plotly.animate(gd, [fr[best].name], {mode: 'immediate', frame: {duration: 0, redraw: true}, transition: {duration: 0}});
  var sl = gd._fullLayout.sliders;
  if (sl && sl.length) { Plotly.relayout(gd, {'sliders[0].active': best}); }
}
if (document.readyState === 'loading') {
  document.addEventListener('DOMContentLoaded', exubioRendered);
} else {
  exubioRendered();
}
"""

_ERROR_HOOK = """
window.exubioErrors = [];
function exubioReport(msg) {
  window.exubioErrors.push(String(msg));
  var el = document.getElementById('exubio-errors');
  if (el) { el.textContent = window.exubioErrors.join('\\n'); el.hidden = false; }
}
window.addEventListener('error', function(e) {
  exubioReport('error: ' + e.message + ' (' + e.filename + ':' + e.lineno + ')');
});
window.addEventListener('unhandledrejection', function(e) {
  exubioReport('unhandled rejection: ' + ((e.reason && e.reason.message) || e.reason));
});
document.addEventListener('DOMContentLoaded', function() {
  if (window.exubioErrors.length) { exubioReport('(errors before the page loaded)'); }
});
"""


def _page(results: list[_Result], trial: str, data: dict, plot_div: str, notes: list[str]) -> str:
    verdicts = " · ".join(f"{r.recon.method.upper()}: {r.verdict.upper()}" for r in results)
    payload = json.dumps(data, allow_nan=False).replace("</", "<\\/")
    reasons = "".join(
        f"<li><b>{html.escape(r.recon.method.upper())}</b> ({html.escape(r.verdict)}): "
        + (html.escape("; ".join(f"{x.get('level', '')}: {x.get('message', '')}" if isinstance(x, dict) else x
                                 for x in r.reasons))
           if r.reasons else "no reasons given")
        + (f" <small>[{html.escape(r.verdict_source)}]</small>" if r.verdict_source else " <small>[no summary.json found]</small>")
        + "</li>" for r in results)
    note_items = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>exubio view — {html.escape(trial)} — {html.escape(verdicts)}</title>
<script>{_ERROR_HOOK}</script>
<style>
 html {{ overflow-y: scroll; }}
 body {{ font-family: sans-serif; margin: 0; }}
 .notes, #exubio-errors {{ margin: 0 12px; }}
 #exubio-errors {{ color: #b00; background: #fee; padding: 4px; }}
 .notes {{ font-size: 13px; color: #333; }}
</style>
</head>
<body>
<pre id="exubio-errors" hidden></pre>
<script id="exubio-data" type="application/json">{payload}</script>
{plot_div}
<div class="notes">
<p id="exubio-status">not rendered (JavaScript disabled, or the plot failed)</p>
<ul>{note_items}</ul>
<p>Quality verdicts:</p><ul>{reasons}</ul>
<p>Bones: each segment's origin (joint centre) to its children's joint centres and its landmarks, from the
reconstructed joint angles and the model {html.escape(data['model'])}. Measured markers: the filtered targets
the method tracked. Model points: coloured by segment. Residual lines join each marker to its model point.
Drag to rotate (the scenes turn together), scroll to zoom, click a legend entry to hide it.</p>
</div>
</body>
</html>
"""
