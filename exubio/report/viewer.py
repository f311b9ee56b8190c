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

This module is the entry point; the work is split by job: reading the results and the model
(``viewer_results``), the geometry of the scenes (``viewer_scene``) and the plotly figure and HTML
page (``viewer_page``, the one plotly user).
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Sequence

from exubio.errors import InputError
from exubio.io.results import atomic_write, writable_folder
from exubio.report.viewer_page import MAX_ANIMATION_FRAMES, _build_page
from exubio.report.viewer_results import _load_model, _load_result, _method_from_name, _method_rank, _siblings

log = logging.getLogger(__name__)


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
