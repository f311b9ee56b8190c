"""Reading what the 3D view shows (``exubio.report.viewer``): the result files of one trial (and
the other methods' results beside it), their quality verdicts, and the model the run used.
"""
from __future__ import annotations

import json
import logging
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from exubio.errors import ExubioError, InputError
from exubio.io.result_names import beside
from exubio.io.results import read_npz, read_npz_metadata
from exubio.types import Model, Reconstruction
from exubio.method_registry import method_names

log = logging.getLogger(__name__)



@dataclass
class _Result:
    path: Path
    recon: Reconstruction
    metadata: dict[str, Any]
    verdict: str = "unknown"
    reasons: list[Any] = field(default_factory=list)  # as the summary gives them: {code, level, message} (or text)
    verdict_source: str = ""


def _method_rank(method: str) -> tuple[int, str]:
    order = method_names()
    return (order.index(method) if method in order else len(order), method)


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
    summary_path = beside(path, "summary") if path.name.endswith(".npz") else None
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
