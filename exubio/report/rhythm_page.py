"""The rhythm pages: ST, SC and GH angles against HT elevation, raising and lowering apart.

A trial's page (exubio.report.trial_report): every cycle's frames, the +-2u band where the angle is
measured, grey where it is not a measurement, the in vivo corridor (exubio.scapulohumeral.reference) and
each study's curve in the same frames. A study's pages (exubio.report.study_report): per method
and plane, the group (each subject's mean thin, the group's mean +- SD over the subjects' means)
and one page per subject (its trials thin, their mean ± SD). Draws from exubio.scapulohumeral (no solver).
"""
from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from exubio.report.page_figures import _bisect_wrap, _envelope, _page_figure, _pin_titles, _release
from exubio.model.signs import factors, meaning
from exubio.scapulohumeral.files import StudyRhythm, shown_band
from exubio.scapulohumeral.reference import Reference
from exubio.scapulohumeral.table import HT_GRID_DEG, PHASES, RHYTHM_ANGLES, Average, TrialRhythm

__all__ = ["trial_rhythm_page", "study_rhythm_pages", "each_study_rhythm_page", "angle_label"]

_PHASE_STYLE = {1: ("tab:blue", "-"), 2: ("tab:orange", (0, (5, 2)))}
_CORRIDOR = "0.55"
CYCLE_BIN_DEG = 1.0
"""A trial page's cycle is drawn thinned to its envelope (exubio.report.page_figures._envelope) in
bins of about this much HT elevation: a panel is 180 deg over about 2.3 inches, so 1 deg is finer
than the angles page's time bins (400 over about 7.7 inches)."""


def _cycle_points(ht_deg: np.ndarray) -> int:
    """The points a cycle's curve keeps: two per ``CYCLE_BIN_DEG`` of the HT elevation it spans."""
    finite = ht_deg[np.isfinite(ht_deg)]
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    return 2 * max(2, int(np.ceil(span / CYCLE_BIN_DEG)))


def angle_label(name: str, labels: dict | None = None, signs: str = "isb") -> str:
    """The angle's name in the figure with its sign in the convention ``signs`` (exubio.model.signs;
    ``labels`` overrides)."""
    if labels and name in labels:
        return labels[name]
    title = dict(RHYTHM_ANGLES)[name]
    return f"{title} (deg)\n{meaning(name, signs)}"


def _figure() -> tuple[Figure, np.ndarray]:
    fig = Figure(figsize=(11.69, 8.27))
    FigureCanvasAgg(fig)
    axes = np.asarray(fig.subplots(2, 4, sharex=True)).ravel()
    fig.subplots_adjust(left=0.06, right=0.985, top=0.86, bottom=0.2, hspace=0.28, wspace=0.33)
    return fig, axes


def _corridor(ax, ref: Reference | None, name: str, signs: str) -> None:
    if ref is None or name not in ref.lo:
        return
    f = factors([name], signs)[0]  # the corridor is ISB: drawn in the page's convention
    lo, hi = shown_band(ref.lo[name], ref.hi[name], f)
    ax.fill_between(ref.ht_grid_deg, lo, hi, color=_CORRIDOR, alpha=0.28, lw=0, zorder=0)
    for _, ht, deg in ref.studies.get(name, []):
        ax.plot(ht, np.asarray(deg) * f, color=_CORRIDOR, lw=0.8, ls=":", zorder=0)


def _axes_style(ax, name: str, labels: dict | None, bottom: bool, signs: str = "isb") -> None:
    label = angle_label(name, labels, signs)
    ax.set_title(label.split("\n")[0], fontsize=8)
    ax.set_ylabel(label.split("\n")[1] if "\n" in label else "deg", fontsize=6.5)
    ax.tick_params(labelsize=6.5)
    ax.grid(alpha=0.3)
    ax.set_xlim(0, 180)
    if bottom:
        ax.set_xlabel("HT elevation (deg)", fontsize=7)


def _legend(fig: Figure, ref: Reference | None, extra: Sequence = ()) -> None:
    handles = [Line2D([], [], color=_PHASE_STYLE[1][0], ls=_PHASE_STYLE[1][1], label="raising"),
               Line2D([], [], color=_PHASE_STYLE[2][0], ls=_PHASE_STYLE[2][1], label="lowering"), *extra]
    if ref is not None and ref.lo:
        handles += [Patch(color=_CORRIDOR, alpha=0.28, label="in vivo corridor (>= 2 studies)"),
                    Line2D([], [], color=_CORRIDOR, ls=":", label="each study's mean")]
    fig.legend(handles=handles, loc="upper right", ncol=len(handles), fontsize=7, frameon=False,
               bbox_to_anchor=(0.985, 0.915))


def _notes(ref: Reference | None, lines: Sequence[str]) -> str:
    out = list(lines)
    if ref is not None:
        out.append(f"corridor: {ref.why}")
        if ref.lo:
            studies = sorted({s for v in ref.studies.values() for s, _, _ in v})
            out.append("studies in the corridor (converted to these frames and sequences on the model's bones, "
                       "exubio.literature.corridor): " + ", ".join(studies)
                       + f"; left out: {sum(len(v) for v in ref.excluded.values())} study curves (each with its reason: df.attrs of exubio.rhythm)")
    return "\n".join(out)


def _phase_curves(r: TrialRhythm, k: int, f: float, cycles: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
    """Angle k's cycles of one phase (each its frames' indices) as one curve each of HT elevation,
    not-measured values (grey), measured values and the +-2u band's edges (measured frames): every
    cycle thinned to its envelope (``_cycle_points``), a NaN between cycles (a break in the line
    and the band)."""
    parts = []
    for sel in cycles:
        ht, y, ok = r.ht_deg[sel], r.values_deg[sel, k] * f, r.measured[sel, k]
        band = 2.0 * r.u_deg[sel, k]
        parts.append(np.column_stack(_envelope(ht, np.where(ok, np.nan, y), np.where(ok, y, np.nan),
                                               np.where(ok, y - band, np.nan), np.where(ok, y + band, np.nan),
                                               keep=4, points=_cycle_points(ht))))
        parts.append(np.full((1, 5), np.nan))
    return tuple(np.concatenate(parts[:-1]).T) if parts else tuple(np.empty(0) for _ in range(5))


def trial_rhythm_page(r: TrialRhythm, ref: Reference | None, title: str, /, *, model_note: str = "",
                      method: str = "") -> Figure:
    """The trial's rhythm page (module docstring)."""
    fig, _ = _page_figure(("rhythm",), lambda: _figure()[0])  # a free rhythm page of this process, else a new one
    axes = np.asarray(fig.axes)
    has_u = np.isfinite(r.u_deg).any()
    frames = [np.flatnonzero(r.cycle == c) for c in np.unique(r.cycle[r.cycle >= 0])]  # each cycle's, in time order
    by_phase = {p: [sel for sel in frames if r.phase[sel[0]] == p] for p in (1, 2)}
    for k, (ax, name) in enumerate(zip(axes, r.names)):
        _corridor(ax, ref, name, r.signs)
        f = factors([name], r.signs)[0]  # ISB inside, drawn in the trial's convention
        phases = {p: _phase_curves(r, k, f, cycles) for p, cycles in by_phase.items()}
        if has_u:  # the bands first, every line above them
            for p, (ht, _, _, lo, hi) in phases.items():
                if ht.size:
                    ax.fill_between(ht, lo, hi, color=_PHASE_STYLE[p][0], alpha=0.15, lw=0)
        for p, (ht, grey, shown, _, _) in phases.items():
            if ht.size:
                colour, ls = _PHASE_STYLE[p]
                ax.plot(ht, grey, color="silver", lw=1.0, ls=ls)
                ax.plot(ht, shown, color=colour, lw=1.3, ls=ls)
        _axes_style(ax, name, r.labels, k >= 4, r.signs)
    extra = [Line2D([], [], color="silver", label="not a measurement")]
    if has_u:
        extra.append(Patch(color="grey", alpha=0.15, label="±2u (standard uncertainty)"))
    _legend(fig, ref, extra)
    n_cycles = {PHASES[p - 1]: len(np.unique(r.cycle[r.phase == p])) for p in (1, 2)}
    fig.suptitle(f"{title}\nscapulohumeral rhythm{f' ({method.upper()})' if method else ''}: "
                 f"{n_cycles['raising']} raising and {n_cycles['lowering']} lowering cycle(s); "
                 f"{'ISB' if r.signs == 'isb' else 'clinical'} signs (stated under each title)", fontsize=9)
    _bisect_wrap(fig.text(0.06, 0.015, _notes(ref, [
        "x: HT elevation, the angle between the humerus and the thorax's vertical axis. Frames: raising or lowering faster "
        "than 5 deg/s over at least 20 deg (exubio.scapulohumeral.table); ST and SC Y-X'-Z'', GH X-Z'-Y'' (Phadke) in ISB frames.",
        *([f"corridor bones: {model_note}"] if model_note else [])]), fontsize=6.5, va="bottom", wrap=True))
    return _pin_titles(fig)


def _average_curves(ax, a: Average, k: int, *, thick: bool, band: bool, f: float = 1.0) -> None:
    for p in (1, 2):
        colour, ls = _PHASE_STYLE[p]
        m, sd = a.mean_deg[p - 1, :, k] * f, a.sd_deg[p - 1, :, k]
        ax.plot(HT_GRID_DEG, m, color=colour, ls=ls, lw=2.0 if thick else 0.7, alpha=1.0 if thick else 0.55)
        if band:
            ax.fill_between(HT_GRID_DEG, m - sd, m + sd, color=colour, alpha=0.18, lw=0)


def _study_page(g: StudyRhythm, title: str, main: Average, thin: Sequence[Average | np.ndarray], what: str,
                labels: dict | None, reuse: bool) -> Figure:
    fig = _page_figure(("study rhythm",), lambda: _figure()[0])[0] if reuse else _figure()[0]
    axes = np.asarray(fig.axes)
    for k, (ax, name) in enumerate(zip(axes, (a for a, _ in RHYTHM_ANGLES))):
        _corridor(ax, g.reference, name, g.signs)
        f = factors([name], g.signs)[0]  # averaged as ISB, drawn in the study's convention
        for t in thin:
            if isinstance(t, Average):
                _average_curves(ax, t, k, thick=False, band=False, f=f)
            else:
                for p in (1, 2):
                    ax.plot(HT_GRID_DEG, t[p - 1, :, k] * f, color=_PHASE_STYLE[p][0], ls=_PHASE_STYLE[p][1], lw=0.7,
                            alpha=0.55)
        _average_curves(ax, main, k, thick=True, band=True, f=f)
        _axes_style(ax, name, labels, k >= 4, g.signs)
    _legend(fig, g.reference, [Patch(color="grey", alpha=0.18, label="mean ± SD")])
    fig.suptitle(f"{title}\n{what}; {'ISB' if g.signs == 'isb' else 'clinical'} signs (stated under each title)",
                 fontsize=9)
    n = int(main.n.max(initial=0))
    fig.text(0.06, 0.015, _notes(g.reference, [
        f"resampled on HT elevation every {HT_GRID_DEG[1] - HT_GRID_DEG[0]:.0f} deg (exubio.scapulohumeral.table): a trial is the "
        f"mean of its cycles, measured frames only (a value not measured is never bridged); at most {n} curve(s) per point.",
        "thick: the mean, band: +- SD (ddof 1, where two or more curves); thin: the curves averaged."]),
        fontsize=6.5, va="bottom", wrap=True)
    return fig


def study_rhythm_pages(groups: Sequence[StudyRhythm], study: str, /, *, labels: dict | None = None) -> list[Figure]:
    """The group page and one page per subject of every method and plane (module docstring)."""
    return list(each_study_rhythm_page(groups, study, labels=labels))


def each_study_rhythm_page(groups: Sequence[StudyRhythm], study: str, /, *, labels: dict | None = None,
                           reuse: bool = False) -> Iterator[Figure]:
    """``study_rhythm_pages`` one page at a time. ``reuse``: every page is drawn into the same
    figure (a free study rhythm page of this process, exubio.report.page_figures), handed back to
    be drawn into again when the next page is asked for: a study's 20-odd pages cost one figure's
    axes and ticks instead of one each (write each page before asking for the next)."""
    for g in groups:
        head = f"exubio study: {study} — {g.method.upper()}, arm raised in the {g.plane} plane"
        pages = [(g.group, list(g.subjects.values()),
                  f"group scapulohumeral rhythm: {len(g.subjects)} subjects, {len(g.trials)} trials; mean ± "
                  f"SD over the subjects' means (each subject counts once)")]
        for s, a in g.subjects.items():
            mine = [rs.values_deg for st, rs in g.trials if st.subject == s]
            pages.append((a, mine, f"subject {s}: {len(mine)} trial(s); mean +- SD over its trials"))
        for main, thin, what in pages:
            fig = _study_page(g, head, main, thin, what, labels, reuse)
            yield fig
            if reuse:
                _release(fig)
    if groups and groups[0].left_out:
        fig = Figure(figsize=(11.69, 8.27))
        FigureCanvasAgg(fig)
        fig.text(0.04, 0.95, "trials without a rhythm (left out of the rhythm pages)", fontsize=11, weight="bold",
                 va="top")
        fig.text(0.04, 0.9, "\n".join(f"{t.subject}/{t.session}/{t.trial} ({t.method.upper()}): {why}"
                                      for t, why in groups[0].left_out[:60]), fontsize=7, va="top", family="monospace",
                 wrap=True)
        yield fig


def trial_rhythm_figure(npz_path, title: str, method: str, /, *, angles=None, model=None,
                        metadata=None) -> Figure | None:
    """The rhythm page of one method's result, or None when it has no shoulder angles with a
    status or no raising or lowering of the arm (no rhythm to draw). From its files (``npz_path``
    and the CSV beside it; the model file its metadata names), or from memory: ``angles`` (its
    exubio.report.trial_report.Angles, as the files hold them), ``model`` (the one it was
    reconstructed with) and ``metadata`` (the run's)."""
    from exubio.errors import InputError
    from exubio.scapulohumeral import files

    try:
        r = (files.read_trial_rhythm(npz_path) if angles is None else
             files.rhythm_of(angles.time_s, angles.names, angles.values_rad, angles.uncertainty_rad, angles.status,
                             angles.signs, where=npz_path))
    except InputError:
        return None
    if not (r.phase > 0).any():
        return None
    if model is None and metadata is None:
        ref, which = files.trial_reference(npz_path, r)
    else:
        ref, which = files.rhythm_reference(r, *files.model_of(metadata or {}, model=model))
    return trial_rhythm_page(r, ref, title, model_note=which, method=method)
