"""The page of the 3D view (``exubio.report.viewer``): the plotly figure (one 3D scene per
method, animation frames, slider and play buttons, linked cameras) and the self-contained HTML
page around it with the embedded data summary and the error hook. The only module that imports
plotly.
"""
from __future__ import annotations

import html
import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from exubio.report.viewer_results import _Result
from exubio.report.viewer_scene import (
    _bone_points,
    _ellipsoid_mesh,
    _frame_selection,
    _marker_segments,
    _nearest,
    _r,
    _scene_data,
    _SceneData,
)
from exubio.types import Model
from exubio.method_registry import method_style

log = logging.getLogger(__name__)

MAX_ANIMATION_FRAMES = 300
_VERDICT_COLOURS = {"ok": "#2ca02c", "check": "#ff7f0e", "fail": "#d62728"}
_BONE_COLOUR = "#7a4b1e"
_MEASURED_COLOUR = "#1f4fd1"
_RESIDUAL_COLOUR = "#e0115f"
_ELLIPSOID_COLOUR = "#7fb3d5"
_SEGMENT_COLOURS = ("#7f7f7f", "#ff7f0e", "#2ca02c", "#9467bd", "#17becf", "#e377c2", "#bcbd22", "#8c564b")
_CONSTRAINT_TOLERANCE = 1e-6  # |g recomputed - g stored| above this: the model is not the run's
_PLOT_ID = "exubio-plot"


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
        notes.insert(0, f"Animation: one frame in {step} is shown ({len(frames)} of {first.n_frames} frames; "
                        f"at most {max_frames} animation frames; every frame is in the result files).")
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


_SCENES_WIDTH = 0.84  # of the page's width; the legend is right of the scenes
_TORSO_COLOUR = "#34495e"
_TORSO_LOOP = ("IJ", "C7", "T8", "PX", "IJ")  # the ISB thorax landmarks, around the sagittal outline


def _torso(model) -> dict[str, list] | None:
    """The thorax's ISB landmarks joined around the sagittal outline of the torso (IJ, C7, T8, PX),
    mm in the thorax frame (the thorax is fixed), with their names; None when the model lacks one."""
    thorax = model.segments[0]
    if not all(n in thorax.points for n in _TORSO_LOOP):
        return None
    pts = np.array([thorax.points[n] for n in _TORSO_LOOP], dtype=float) * 1000.0
    return {"x": pts[:, 0].round(1).tolist(), "y": pts[:, 1].round(1).tolist(), "z": pts[:, 2].round(1).tolist(),
            "text": [*_TORSO_LOOP[:-1], ""]}


def _round_or_none(x: float, nd: int = 3):
    return round(float(x), nd) if math.isfinite(x) else None


def _figure(results, scenes, seg_of, times, bone_labels, model, trial, *, frames_note):
    """The plotly figure as a dict (data, layout, frames) and the number of animated traces per scene."""
    n_scenes = len(results)
    gap = 0.02
    width = (_SCENES_WIDTH - gap * (n_scenes - 1)) / n_scenes  # the legend takes the right edge
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
        "legend": {"orientation": "v", "x": 1.0, "xanchor": "right", "y": 0.9, "yanchor": "top",
                   "font": {"size": 11}, "tracegroupgap": 4},
        "annotations": [],
        "uirevision": "exubio",
    }
    for s, (res, sc) in enumerate(zip(results, scenes)):
        scene = "scene" if s == 0 else f"scene{s + 1}"
        x0 = s * (width + gap)

        def axis(title: str, i: int) -> dict:
            return {"title": {"text": title}, "range": [float(lo[i]), float(hi[i])], "autorange": False, "nticks": 5}

        layout[scene] = {
            "domain": {"x": [x0, x0 + width], "y": [0.02, 0.94]},
            "xaxis": axis("X anterior (mm)", 0), "yaxis": axis("Y superior (mm)", 1), "zaxis": axis("Z right (mm)", 2),
            "aspectmode": "manual", "aspectratio": {"x": aspect[0], "y": aspect[1], "z": aspect[2]},
            "camera": {"up": {"x": 0, "y": 1, "z": 0}, "eye": {"x": 1.55, "y": 0.3, "z": 0.85},
                       "center": {"x": 0, "y": 0, "z": 0}},
        }
        title = method_style(res.recon.method).title
        res_txt = f"{sc.mean_residual_mm:.2f} mm" if math.isfinite(sc.mean_residual_mm) else "n/a"
        layout["annotations"].append({
            "text": f"<b>{html.escape(title)}</b> — verdict {_verdict_html(res).split(': ', 1)[1]}, "
                    f"mean residual {res_txt}",
            "x": x0 + width / 2, "y": 0.99, "xref": "paper", "yref": "paper", "showarrow": False,
            "xanchor": "center", "yanchor": "top", "font": {"size": 13}})
        show = s == 0
        names = list(res.recon.marker_names)
        colours = [seg_colour.get(g, "#000000") for g in seg_of[s]]
        traces.append({"type": "mesh3d", "scene": scene, "name": "thorax ellipsoid (scapula glides on it)",
                       "legendgroup": "ellipsoid", "showlegend": show, **ell, "color": _ELLIPSOID_COLOUR,
                       "opacity": 0.3, "hoverinfo": "skip", "flatshading": False})
        torso = _torso(model)
        if torso is not None:
            traces.append({"type": "scatter3d", "scene": scene, "mode": "lines+markers+text", "name": "thorax landmarks",
                           "legendgroup": "torso", "showlegend": show, **torso, "textposition": "middle left",
                           "line": {"color": _TORSO_COLOUR, "width": 5}, "marker": {"color": _TORSO_COLOUR, "size": 3},
                           "hoverinfo": "text", "textfont": {"size": 10, "color": _TORSO_COLOUR}})
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
    drawn = [g for g in model.segment_names if any(g in segs for segs in seg_of)]
    for g in drawn:  # a legend of the model points' colours (no data: the points are the animated trace)
        traces.append({"type": "scatter3d", "scene": "scene", "mode": "markers", "name": f"{g} points",
                       "legendgroup": "segments", "showlegend": True, "x": [None], "y": [None], "z": [None],
                       "marker": {"color": seg_colour[g], "size": 5, "symbol": "diamond"}, "hoverinfo": "skip"})

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
  status.hidden = true;  // for a headless browser to check, not for the reader
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
