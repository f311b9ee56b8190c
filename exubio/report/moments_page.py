"""The trial report's joint-moments page (one per method with ``--body-mass``): the net joint
moments against time and against HT elevation, raising and lowering apart.

Top row, against time: the GH moment in the humerus's ISB frame (X, Y, Z), the elbow's and the
forearm's moments about their own axes, the wrist's, and the scapulothoracic contact forces. Bottom
row: the same against HT elevation (the frames of a raising or a lowering of the arm,
exubio.scapulohumeral.table.phases; HT elevation where it is measured). The title states body mass,
hand load, the inertia source and, for PF, the inertia scale it integrated with (and its fallback).
Draws the arrays it is given (the moments CSV's table, exubio.dynamics.moments_file); no solver.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from exubio.scapulohumeral.table import phases
from exubio.io.result_names import beside

__all__ = ["PANELS", "moments_page"]

PANELS: tuple[tuple[str, tuple[tuple[str, str], ...], str], ...] = (
    ("GH (humerus ISB frame)", (("GH_X_moment_Nm", "X"), ("GH_Y_moment_Nm", "Y"), ("GH_Z_moment_Nm", "Z")), "N m"),
    ("elbow and forearm", (("elbow_flexion_moment_Nm", "elbow flexion"),
                           ("forearm_pronation_moment_Nm", "forearm pronation")), "N m"),
    ("wrist", (("wrist_flexion_moment_Nm", "flexion"), ("wrist_radial_deviation_moment_Nm", "radial deviation")), "N m"),
    ("scapulothoracic contact", (("TS_contact_normal_N", "TS"), ("AI_contact_normal_N", "AI")), "N (> 0 compression)"),
)
"""Panels: (title, ((column, label), ...), unit) of the moment table's columns (exubio.dynamics.moments)."""

_COLOURS = ("black", "tab:red", "tab:green")
_PHASE_STYLE = {1: "-", 2: (0, (4, 2))}


def _header(method: str, moments: Mapping, pf_inertia: Mapping | None) -> str:
    parts = [f"body mass {moments.get('body_mass_kg', float('nan')):g} kg",
             f"hand load {moments.get('hand_load_kg', 0.0):g} kg"]
    if pf_inertia:
        scale = f"PF inertia scale x{pf_inertia['used']:g} (q'' of PF's integration; the moments use the real inertia)"
        if pf_inertia.get("fallback"):
            asked = pf_inertia.get("asked")
            scale += f"; asked x{asked:g}, the fallback run changed it" if asked is not None else "; the fallback run's"
        parts.append(scale)
    return f"joint moments ({method.upper()}): " + "; ".join(parts)


def moments_page(time_s: np.ndarray, columns: Sequence[str], values: np.ndarray, /, *, title: str, method: str,
                 ht_deg: np.ndarray | None = None, moments_summary: Mapping | None = None,
                 pf_inertia: Mapping | None = None) -> Figure:
    """The page (module docstring) of one method's moment table: ``time_s`` (n,), ``columns``,
    ``values`` (n, k) SI; ``ht_deg`` (n,) HT elevation (deg, NaN where not measured) or None (no
    bottom row's curves); ``moments_summary``: summary.json's ``moments``; ``pf_inertia``: its
    ``pf_inertia_scale`` (PF)."""
    t = np.asarray(time_s, dtype=float)
    values = np.asarray(values, dtype=float)
    columns = list(columns)
    fig = Figure(figsize=(11.69, 8.27))
    FigureCanvasAgg(fig)
    axes = np.asarray(fig.subplots(2, len(PANELS)))
    fig.subplots_adjust(left=0.06, right=0.985, top=0.85, bottom=0.16, hspace=0.35, wspace=0.32)
    phase, cycle = phases(ht_deg, t) if ht_deg is not None else (np.zeros(t.size, int), np.full(t.size, -1))
    for k, (name, curves, unit) in enumerate(PANELS):
        top, bottom = axes[0, k], axes[1, k]
        for (col, label), colour in zip(curves, _COLOURS):
            if col not in columns:
                continue
            y = values[:, columns.index(col)]
            top.plot(t, y, color=colour, lw=1.0, label=label)
            for c in np.unique(cycle[cycle >= 0]):
                sel = cycle == c
                bottom.plot(ht_deg[sel], y[sel], color=colour, lw=1.0, ls=_PHASE_STYLE[int(phase[sel][0])])
        for ax in (top, bottom):
            ax.set_title(name, fontsize=8)
            ax.set_ylabel(unit, fontsize=7)
            ax.tick_params(labelsize=6.5)
            ax.grid(alpha=0.3)
            ax.axhline(0.0, color="0.6", lw=0.6)
        top.set_xlabel("time (s)", fontsize=7)
        bottom.set_xlabel("HT elevation (deg)", fontsize=7)
        if top.get_legend_handles_labels()[0]:
            top.legend(fontsize=6.5, frameon=False, loc="best")
        if not (cycle >= 0).any():
            bottom.text(0.5, 0.5, "no raising or lowering of the arm", transform=bottom.transAxes, ha="center",
                        va="center", fontsize=7, color="0.4")
    fig.legend(handles=[Line2D([], [], color="0.3", ls=_PHASE_STYLE[1], label="raising"),
                        Line2D([], [], color="0.3", ls=_PHASE_STYLE[2], label="lowering")],
               loc="lower right", ncol=2, fontsize=7, frameon=False, bbox_to_anchor=(0.985, 0.865),
               title="against HT elevation:", title_fontsize=7, alignment="right")
    summary = dict(moments_summary or {})
    fig.suptitle(f"{title}\n{_header(method, summary, pf_inertia)}", fontsize=9)
    notes = ["Net joint moments: the moment the proximal segment applies to the distal one about the joint centre "
             "(muscles and ligaments together), positive about each axis by the right-hand rule; GH in the humerus's ISB "
             "frame (X anterior, Y along the humerus towards the shoulder, Z right in the anatomical posture); elbow, "
             "forearm, wrist about their own axes, positive towards the named motion. Contact: the thorax's push on the "
             "scapula along the ellipsoid's normal (least-squares share of the girdle's load; docs: moments).",
             f"inertia: {summary.get('inertia_source', '')}"]
    contact = summary.get("scapulothoracic_contact") or {}
    if contact:
        notes.append("contact force: " + "; ".join(
            f"{p} peak {v['peak_N']:.1f} N, median {v['median_N']:.1f} N, in compression {100 * v['compression_share']:.0f} % "
            "of the frames" for p, v in contact.items() if v.get("peak_N") is not None))
    fig.text(0.06, 0.015, "\n".join(notes), fontsize=6.5, va="bottom", wrap=True)
    return fig


def trial_moments_figure(npz_path, title: str, method: str, angles, summary: Mapping | None, /, *,
                         moments=None) -> Figure | None:
    """The moments page of one method's result set when it has joint moments (``--body-mass``):
    ``moments`` in memory (exubio.dynamics.moments.Moments), else its ``<stem>.moments.csv`` beside
    its .npz; None without; ``angles``: its anatomical angles with their status
    (exubio.report.trial_report.Angles) or None; ``summary``: its summary.json."""

    from exubio.dynamics.moments_file import read_moments_csv
    from exubio.scapulohumeral.table import HT_COLUMN

    if moments is not None:
        t, columns, values = moments.time_s, tuple(moments.columns), moments.values
    else:
        path = beside(npz_path, "moments")
        if not path.is_file():
            return None
        t, columns, values = read_moments_csv(path)
    ht = None
    if angles is not None and HT_COLUMN in angles.names and angles.values_rad.shape[0] == t.size:
        j = angles.names.index(HT_COLUMN)
        ht = np.where(angles.status[:, j] == 0, -np.degrees(angles.values_rad[:, j]), np.nan)
    summary = dict(summary or {})
    return moments_page(t, columns, values, title=title, method=method, ht_deg=ht,
                        moments_summary=summary.get("moments"), pf_inertia=summary.get("pf_inertia_scale"))
