"""The report of one reconstructed trial: a PDF (and a PNG of its first page) a lab can show.

It reads the ``<trial>.<method>.npz`` results and their ``summary.json`` written by ``exubio
reconstruct`` (through exubio.io.results) and never imports the solver. Page 1 (and the PNG): the
quality verdict of every method with its reasons, the key figures, the worst markers, the
comparison of the measured anatomical angles with the truth of a simulated trial, the label
findings and the angles that are not measurements. Page 2: the anatomical angles of every method
against time (``<trial>.<method>.csv``; one colour per angle, PF solid, LS dashed, the truth dotted;
modelled and not measured in grey). Then, for a trial that raises or lowers the arm, the rhythm
page of each method (exubio.report.rhythm_page: ST, SC, GH angles against HT elevation with the
in vivo corridor), and, with ``--body-mass``, the joint-moments page of each method
(exubio.report.moments_page: against time and HT elevation). Page 3: marker residuals (mean ± SD over markers per frame, per-marker RMSE), constraint residuals and the gaps.

The pages share one loaded set of results; the drawing machinery (re-used figures, envelopes,
wrapped text) is exubio.report.page_figures.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.text import Text

from exubio.trust.evaluate import per_frame_residuals_mm, residual_statistics
from exubio.errors import InputError
from exubio.io.result_names import beside
from exubio.io.results import atomic_write, read_angles_csv, read_npz, read_npz_arrays, read_npz_metadata
from exubio.model.signs import CLINICAL_FLIPPED, convert, factors, signs_of_file
from exubio.types import FrameStatus, Reconstruction
from exubio.report.calibration_page import calibration_page, short_paths
from exubio.report.page_figures import (PLOT_POINTS, _bisect_wrap, _empty, _envelope, _figure, _figure_with_axes, _page_figure,  # noqa: F401
                                        _pin_titles, _release, _x_labels_at_top, pdf_pages)
from exubio.method_registry import REGISTRY, method_style

_JOINTS = (("SC (ISB Y-X'-Z'')", "SC_"), ("AC (ISB Y-X'-Z'')", "AC_"), ("ST (ISB Y-X'-Z'')", "ST_"),
           ("GH (ISB Y-X'-Y'')", ("GH_Y_", "GH_X_")), ("GH (Phadke X-Z'-Y'')", "GH_phadke_"),
           ("HT (ISB Y-X'-Y'')", "HT_"), ("elbow, forearm,\nwrist", ("elbow_", "forearm_", "wrist_")))
"""Rows of the angles page: the anatomical angles (exubio.model.angles.ANATOMICAL_ANGLES) by joint."""


@dataclass(frozen=True)
class Angles:
    """The anatomical angles of one method's result: from <trial>.<method>.csv (degrees -> rad)
    and their status per frame from the .npz (exubio.trust.observability.AngleStatus codes: 0 measured,
    1 modelled, 2 not measured)."""

    time_s: np.ndarray
    names: tuple[str, ...]
    values_rad: np.ndarray
    status: np.ndarray
    uncertainty_rad: np.ndarray | None = None  # (n, a) standard uncertainty, where the result carries it
    signs: str = "isb"  # the convention of the CSV (exubio.model.signs); values_rad are ISB, converted on reading

    def measured(self, j: int) -> np.ndarray:
        return self.status[:, j] == 0

    def shown_deg(self, j: int) -> np.ndarray:
        """Angle j in degrees as the CSV holds it (in ``signs``): what the pages draw."""
        return np.degrees(self.values_rad[:, j]) * factors([self.names[j]], self.signs)[0]


def read_angles(npz_path: Path) -> Angles | None:
    """The anatomical angles of a result (None for a result written before they existed)."""
    csv = beside(npz_path, "csv")
    try:
        status = read_npz_arrays(npz_path, ("angle_status",))["angle_status"]
    except InputError:
        return None
    t, names, values, u = read_angles_csv(csv, uncertainty=True)
    names = tuple(n.removesuffix("_deg") for n in names)
    signs = signs_of_file(csv)
    return Angles(t, names, convert(names, values, signs, "isb"), status, None if np.isnan(u).all() else u, signs)


def _members(names: Sequence[str], prefix) -> list[int]:
    prefixes = (prefix,) if isinstance(prefix, str) else prefix
    return [i for i, n in enumerate(names) if n.startswith(prefixes)]


def _title(recons: Sequence[Reconstruction], meta: dict) -> str:
    trial = Path(meta.get("trial", "trial")).name
    protocol = Path(str(meta.get("protocol") or meta.get("protocol_name", ""))).name
    return (f"exubio {meta.get('exubio_version', '')}: {trial} — methods {', '.join(r.method.upper() for r in recons)}"
            f"\nmodel {meta.get('model_name', '')}, protocol {protocol}")


_VERDICT_COLOURS = {"ok": "tab:green", "check": "tab:orange", "fail": "tab:red"}


def verdict_page(recons: Sequence[Reconstruction], meta: dict, summaries: dict[str, dict], *,
                 truth: "Truth | None" = None, angles: dict[str, Angles] | None = None) -> Figure:
    """Page 1: what a supervisor reads first: the verdict of every method with the figures and the
    reasons (a reason every method shares is written once, files by their names), the comparison
    with the truth when it is known, the findings, and the key angles over time. Every text block
    is measured as drawn: the reasons stop above the findings (the rest: '... N more', in the
    summary.json) and nothing overlaps the picture."""
    fig, _ = _page_figure(("verdict", bool(angles)), lambda: _figure_with_axes(*[(0.07, 0.06, 0.66, 0.5)] * bool(angles)))
    fig.suptitle(_title(recons, meta), fontsize=9)
    fig.set_dpi(PAGE1_DPI)  # measured at the resolution of the PNG, where the lines break the same way
    renderer = fig.canvas.get_renderer()
    footer = _bisect_wrap(fig.text(0.04, FOOTER_BOTTOM, "\n".join(_findings(recons, meta, summaries, truth, angles)),
                                   fontsize=8, va="bottom", family="monospace", wrap=True))
    floor = _box(footer, fig, renderer).y1 + 0.015
    quality = {r.method: summaries.get(r.method, {}).get("quality") or {"verdict": "unknown", "reasons": []}
               for r in recons}
    shared = _shared_reasons([q["reasons"] for q in quality.values()]) if len(recons) > 1 else []
    y = 0.90
    for i, r in enumerate(recons):
        s, q = summaries.get(r.method, {}), quality[r.method]
        fig.text(0.04, y, f"{r.method.upper()}: {q['verdict'].upper()}", fontsize=18,
                 color=_VERDICT_COLOURS.get(q["verdict"], "grey"), weight="bold", va="top")
        fig.text(0.22, y - 0.005, _figures_line(r, s), fontsize=8, va="top")
        y -= 0.045
        own = [x for x in q["reasons"] if _reason_key(x) not in {_reason_key(z) for z in shared}]
        if shared and own:
            own = own + [{"level": "note", "message": "and the reasons of every method, below"}]
        blocks = len(recons) - i + bool(shared)  # this one and those below share what is left
        headers_below = 0.06 * (len(recons) - i - 1) + 0.04 * bool(shared)
        share = (y - floor - headers_below) / blocks
        y = _reasons(fig, renderer, own, y, floor if blocks == 1 else y - share, f"{r.method}.summary.json")
        y -= 0.015
    if shared:
        fig.text(0.04, y, "every method:", fontsize=9, weight="bold", va="top")
        y = _reasons(fig, renderer, shared, y - 0.025, floor, "each summary.json")
    height = floor - 0.015 - FOOTER_BOTTOM
    bottom = max(FOOTER_BOTTOM, y - 0.02 - height)  # the findings just below the reasons
    footer.set_y(bottom)
    if angles:
        _key_angles(fig, recons, angles, summaries, top=bottom - 0.045)
    return fig


PAGE1_DPI = 110  # page 1 as a PNG
FOOTER_BOTTOM = 0.36  # the findings end above the key angles' picture (its axes, title and labels)


def _box(text: Text, fig: Figure, renderer):
    return text.get_window_extent(renderer).transformed(fig.transFigure.inverted())


def _reason_key(reason: dict) -> tuple:
    return reason.get("level"), reason.get("message")


def _shared_reasons(per_method: Sequence[Sequence[dict]]) -> list[dict]:
    """The reasons every method gives (same level and words), in the first method's order."""
    keys = [{_reason_key(x) for x in reasons} for reasons in per_method]
    common = set.intersection(*keys) if keys else set()
    return [x for x in per_method[0] if _reason_key(x) in common]


def _reasons(fig: Figure, renderer, reasons: Sequence[dict], y: float, floor: float, where: str) -> float:
    """Draw ``reasons`` from ``y`` down, each wrapped and measured; those that would pass ``floor``
    are counted in one '... N more' line. Returns the y below the last line."""
    for i, reason in enumerate(reasons):
        level = reason["level"]
        t = _bisect_wrap(fig.text(0.06, y, f"{level}: {short_paths(reason['message'])}", fontsize=7, va="top",
                                  wrap=True, color="dimgrey" if level == "note" else _VERDICT_COLOURS.get(level, "black")))
        bottom = _box(t, fig, renderer).y0
        if bottom < floor + 0.02 * (i < len(reasons) - 1):
            t.remove()
            fig.text(0.06, y, f"... {len(reasons) - i} more (the first: {level}) in {where}", fontsize=7, va="top")
            return y - 0.022
        y = bottom - 0.006
    return y


def _figures_line(r: Reconstruction, s: dict) -> str:
    rs = s.get("residual_mm", {})
    per = {k: v for k, v in (rs.get("per_marker_rmse") or {}).items() if v is not None}
    worst = sorted(per, key=per.get, reverse=True)[:3]
    return (f"{s.get('n_frames', r.n_frames)} frames; residual mean {rs.get('mean', float('nan')):.1f} mm, "
            f"worst markers (RMSE): " + ", ".join(f"{m} {per[m]:.1f} mm" for m in worst)
            + f"; max |g| {np.nanmax(np.abs(r.constraint)):.0e}" + _pf_inertia(s.get("pf_inertia_scale")))


def _pf_inertia(entry: dict | None) -> str:
    """PF's inertia scale as page 1 names it (summary.json's pf_inertia_scale; '' for LS)."""
    if not entry:
        return ""
    fallback = f", fallback run (asked x{entry['asked']:g})" if entry.get("fallback") and entry.get("asked") else ""
    return f"; PF's segment inertia x{entry['used']:g}{fallback}"


def _ellipsis(text: str, n: int) -> str:
    """``text`` cut at a word before ``n`` characters, with an ellipsis when cut."""
    return text if len(text) <= n else text[:n].rsplit(" ", 1)[0].rstrip(",;:") + " …"


def _findings(recons: Sequence[Reconstruction], meta: dict, summaries: dict[str, dict], truth: "Truth | None",
              angles: dict[str, Angles] | None) -> list[str]:
    """Page 1's lines below the verdicts: truth, relabel, agreement, filter, angle status, labels,
    calibration, how to read the verdict."""
    first = summaries.get(recons[0].method, {})
    lines = []
    if truth is not None:
        for r in recons:
            a = (angles or {}).get(r.method)
            rm = truth_rmse_deg(a, truth) if a is not None else {}
            if rm:
                worst = max(rm, key=rm.get)
                lines.append(f"{r.method.upper()} against the {truth.label}: RMSE mean {np.mean(list(rm.values())):.2f} "
                             f"deg, max {rm[worst]:.2f} deg ({worst}) over the {len(rm)} measured anatomical angles")
    if meta.get("protocol_relabel"):
        lines.append("relabelled by the protocol (trial label -> read as): " + ", ".join(
            f"{a} -> {b}" for a, b in meta["protocol_relabel"].items()))
    agree = {k: v for k, v in (first.get("pf_ls_agreement_deg") or {}).items() if isinstance(v, float)}
    if agree:
        worst = max(agree, key=agree.get)
        lines.append(f"PF-LS agreement on the measured anatomical angles: max RMSE {agree[worst]:.2f} deg ({worst})")
    cut = first.get("filter_cutoff_hz") or {}
    if cut:
        lines.append(f"low-pass cut-off per marker: {min(cut.values()):.1f}-{max(cut.values()):.1f} Hz")
    status = (first.get("anatomical_angles") or {}).get("status") or {}
    rules = (first.get("anatomical_angles") or {}).get("rules") or {}
    for label in ("modelled", "not measured"):
        these = [n for n, v in status.items() if v.endswith(label)]
        if these:
            rule = sorted({rules[n] for n in these if n in rules}) if label == "modelled" else []
            lines.append(f"{label} (not a measurement; grey on the angles page): " + ", ".join(
                n + (" in part" if status[n].startswith("partly") else "") for n in these)
                + (f" (rule: {'; '.join(rule)})" if rule else ""))
    for f in first.get("labels") or []:
        lines.append(_ellipsis(f"labels: {f.get('kind')} {', '.join(f.get('markers', []))}: {f.get('evidence', '')}", 190))
    cal = first.get("calibration") or {}
    if cal:
        lines.append(f"calibrated on {Path(str(cal.get('static', ''))).name}"
                     + (f" frames {cal['frames']}" if cal.get("frames") else "")
                     + f": calibration residual mean {cal.get('mean_residual_mm', float('nan')):.2f} mm")
    lines.append("verdict: ok = nothing found; check = read the reasons before using the angles; "
                 "fail = the angles are wrong as they stand (exit code 1). Thresholds: exubio/trust/quality.py.")
    return lines


KEY_ANGLES = (("HT_X_elevation", "HT elevation"), ("GH_phadke_X_elevation", "GH elevation (Phadke)"),
              ("ST_X_upward_rotation", "ST upward rotation"), ("SC_X_elevation", "SC elevation"),
              ("elbow_flexion", "elbow flexion"))
"""The angles page 1 draws: what a shoulder study reads first."""


def _key_angles(fig: Figure, recons: Sequence[Reconstruction], angles: dict[str, Angles], summaries: dict, *,
                top: float = FOOTER_BOTTOM - 0.045) -> None:
    """Page 1's picture: the key anatomical angles of the first method over time, in colour where
    measured, grey where modelled or not measured (legend says which), thinned to their envelope as
    page 2's curves are; its axes end at ``top``."""
    method = recons[0].method if recons[0].method in angles else next(iter(angles))
    a = angles[method]
    ax = fig.axes[0]  # made with the page (verdict_page), placed here below its texts
    ax.set_position([0.07, 0.06, 0.66, min(top, 0.6) - 0.06])
    palette = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown")
    for (name, label), colour in zip(KEY_ANGLES, palette):
        if name not in a.names:
            continue
        j = a.names.index(name)
        deg = a.shown_deg(j)  # as the CSV has it, in its convention; the label says the sign
        ok = a.measured(j)
        label += " (-)" if name in CLINICAL_FLIPPED and a.signs == "isb" else " (+)"  # the named motion's sign
        ax.plot(*_envelope(a.time_s, np.where(ok, deg, np.nan)), color=colour, lw=1.4, label=label)
        if a.uncertainty_rad is not None:  # the +-2u band (about 95 %) where the angle is measured
            band = 2.0 * np.degrees(a.uncertainty_rad[:, j])
            ax.fill_between(*_envelope(a.time_s, np.where(ok, deg - band, np.nan), np.where(ok, deg + band, np.nan),
                                       keep=2), color=colour, alpha=0.15, lw=0)
        if (~ok).any():
            ax.plot(*_envelope(a.time_s, np.where(ok, np.nan, deg)), color="silver", lw=1.4)
    if any((~a.measured(a.names.index(n))).any() for n, _ in KEY_ANGLES if n in a.names):
        ax.plot([], [], color="silver", lw=1.4, label="not a measurement")
    if a.uncertainty_rad is not None:
        ax.fill_between([], [], [], color="grey", alpha=0.15, lw=0, label="+-2u (standard uncertainty)")
    ax.set_xlabel("time (s)", fontsize=7)
    ax.set_ylabel("deg", fontsize=7)
    ax.tick_params(labelsize=6.5)
    ax.grid(alpha=0.3)
    ax.set_title(f"key anatomical angles ({method.upper()}; {'raw ISB' if a.signs == 'isb' else 'clinical'} signs, as "
                 f"in the CSV: (+)/(-) the sign of the named motion; every angle: page 2)", fontsize=8)
    ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)


@dataclass(frozen=True)
class Truth:
    """Known true joint coordinates of a simulated trial (radians), drawn and compared with."""

    time_s: np.ndarray
    names: tuple[str, ...]
    q_rad: np.ndarray
    label: str = "simulated truth"


def truth_rmse_deg(angles: Angles, truth: Truth) -> dict[str, float]:
    """RMSE (deg) of every anatomical angle measured in every frame against the truth
    (interpolated onto the result's times); the other angles are left out."""
    out = {}
    for j, name in enumerate(angles.names):
        if name not in truth.names or not angles.measured(j).all():
            continue
        ref = np.interp(angles.time_s, truth.time_s, truth.q_rad[:, truth.names.index(name)])
        d = np.angle(np.exp(1j * (angles.values_rad[:, j] - ref)))
        out[name] = float(np.degrees(np.sqrt(np.nanmean(d ** 2))))
    return out


def _angles_layout() -> Figure:
    fig = _figure()
    fig.subplots(len(_JOINTS), 1, sharex=True)
    return fig


def angles_page(recons: Sequence[Reconstruction], meta: dict, summaries: dict[str, dict] | None = None,
                truth: Truth | None = None, angles: dict[str, Angles] | None = None) -> Figure:
    """The anatomical angles against time, one row per joint: one colour per angle, PF solid and
    thick, LS dashed on top (both visible where they agree), the truth dotted; an angle that is not
    a measurement (modelled, or not measured) in grey; legends outside the axes."""
    angles = angles or {}
    names = next(iter(angles.values())).names
    signs = next(iter(angles.values())).signs
    groups = [_members(names, prefix) for _, prefix in _JOINTS]
    fig, _ = _page_figure(("angles", tuple(bool(g) for g in groups)), _angles_layout)
    axes = fig.axes
    status = (next(iter((summaries or {}).values()), {}).get("anatomical_angles") or {}).get("status") or {}
    palette = ("tab:blue", "tab:orange", "tab:green", "tab:purple")
    line_style = {m.name: (m.style.linestyle, m.style.linewidth, m.style.alpha) for m in REGISTRY.values()}
    for ax, (label, _), idx in zip(axes, _JOINTS, groups):
        handles = {}
        for k, i in enumerate(idx):
            state = status.get(names[i], "measured")
            grey = state != "measured"
            colour = "silver" if grey else palette[k % len(palette)]
            for method, a in angles.items():
                ls_, lw, alpha = line_style.get(method, ("-", 1.0, 1.0))
                (h,) = ax.plot(*_envelope(a.time_s, a.shown_deg(i)), ls=ls_, lw=lw, alpha=alpha,
                               color=colour)
                handles.setdefault(names[i] + (f" ({state})" if grey else ""), h)
            if truth is not None and names[i] in truth.names:
                ax.plot(*_envelope(truth.time_s, np.rad2deg(truth.q_rad[:, truth.names.index(names[i])])
                                   * factors([names[i]], signs)[0]), ls=":", lw=1.2, color="black")
        ax.set_ylabel(f"{label}\n(deg)", fontsize=7)
        ax.grid(alpha=0.3)
        ax.legend(list(handles.values()), list(handles), fontsize=6, loc="upper left", bbox_to_anchor=(1.005, 1.0),
                  frameon=False)
        ax.tick_params(labelsize=6.5)
    axes[-1].set_xlabel("time (s)")
    key = [Line2D([], [], color="dimgrey", ls=line_style[r.method][0], lw=line_style[r.method][1],
                  label=r.method.upper()) for r in recons if r.method in line_style]
    if truth is not None:
        key.append(Line2D([], [], color="black", ls=":", lw=1.2, label=truth.label))
    fig.legend(handles=key, loc="upper right", ncol=len(key), fontsize=8, frameon=False)
    fig.suptitle(_title(recons, meta) + "\nanatomical angles (ISB frames of Wu et al. 2005 from the model's landmarks, "
                 f"intrinsic sequences, {'raw' if signs == 'isb' else 'clinical'} signs; the definitions and each "
                 "angle's sign are in the CSV header)", fontsize=9)
    fig.subplots_adjust(left=0.1, right=0.76, top=0.89, bottom=0.06, hspace=0.2)
    return fig


def _residuals_layout() -> Figure:
    fig = _figure()
    grid = fig.add_gridspec(2, 2, height_ratios=[1.0, 1.0])
    fig.add_subplot(grid[0, :])
    fig.add_subplot(grid[1, 0])
    fig.add_subplot(grid[1, 1])
    return fig


def residuals_page(recons: Sequence[Reconstruction], meta: dict, summaries: dict[str, dict]) -> Figure:
    fig, _ = _page_figure(("residuals",), _residuals_layout)
    ax_t, ax_m, ax_text = fig.axes
    width = 0.8 / len(recons)
    markers = recons[0].marker_names
    for k, r in enumerate(recons):
        mean, sd = per_frame_residuals_mm(r)
        c = method_style(r.method).colour
        t_d, mean_d, sd_d = _envelope(r.time_s, mean, sd)
        ax_t.plot(t_d, mean_d, color=c, lw=1.0, label=f"{r.method.upper()} mean over markers")
        ax_t.fill_between(t_d, mean_d - sd_d, mean_d + sd_d, color=c, alpha=0.12, lw=0, label=f"{r.method.upper()} ± SD")
        stats = residual_statistics(r)
        rmse = [stats["per_marker_rmse"].get(m) or np.nan for m in markers]
        ax_m.bar(np.arange(len(markers)) + k * width, rmse, width, color=c, label=r.method.upper())
    n0 = recons[0].n_frames
    gaps = [g for g in recons[0].gaps if g.n_frames < n0]  # a marker absent throughout is no gap
    absent = [g.marker for g in recons[0].gaps if g.n_frames >= n0]
    for g in gaps:
        t = recons[0].time_s
        ax_t.axvspan(t[g.start], t[min(g.stop, len(t)) - 1], color="orange", alpha=0.2)
    ax_t.set_xlabel("time (s)")
    ax_t.set_ylabel("marker residual (mm)")
    ax_t.grid(alpha=0.3)
    ax_t.legend(fontsize=7)
    ax_t.set_title("distance between each skin marker and its model point (orange: marker gaps)", fontsize=9)
    ax_m.set_xticks(np.arange(len(markers)) + 0.4 - width / 2)
    ax_m.set_xticklabels(markers, rotation=70, fontsize=7)
    ax_m.set_ylabel("RMSE per marker (mm)")
    ax_m.legend(fontsize=7)
    ax_m.grid(alpha=0.3, axis="y")
    ax_text.axis("off")
    lines = []
    for r in recons:
        s = summaries.get(r.method, {})
        rs = s.get("residual_mm", {})
        lines += [f"{r.method.upper()}: {s.get('n_frames', r.n_frames)} frames, {s.get('wall_time_s', float('nan')):.2f} s "
                  f"({s.get('ms_per_frame', float('nan')):.3f} ms/frame)",
                  f"  residual mean {rs.get('mean', float('nan')):.2f} mm, SD {rs.get('sd', float('nan')):.2f} mm, "
                  f"max {rs.get('max', float('nan')):.1f} mm ({rs.get('max_marker')})",
                  f"  max per-frame mean {rs.get('max_frame_mean', float('nan')):.2f} ± "
                  f"{rs.get('max_frame_mean_sd', float('nan')):.2f} mm",
                  f"  constraints: max |g| {np.nanmax(np.abs(r.constraint)):.1e}, "
                  f"max |G q̇| {np.nanmax(np.abs(r.constraint_velocity)):.1e} 1/s",
                  f"  frames not converged / too few markers: {int((np.asarray(r.status) == FrameStatus.NOT_CONVERGED).sum())} / "
                  f"{int((np.asarray(r.status) == FrameStatus.TOO_FEW_MARKERS).sum())}", ""]
    lines.append(f"gaps: {len(gaps)}" + ("" if not gaps else " — " + ", ".join(
        f"{g.marker} ({g.n_frames} frames)" for g in gaps[:6]) + (" ..." if len(gaps) > 6 else "")))
    if absent:
        lines.append(f"markers absent from the whole trial (left out, not gaps): {', '.join(absent)}")
    unused = meta.get("ignored_labels", [])
    if unused:
        lines.append(f"ignored trial labels: {', '.join(unused[:10])}")
    lines.append(f"units in the trial file: {meta.get('units_in_trial_file', '?')}; rate {meta.get('rate_hz', '?')} Hz")
    ax_text.text(0.0, 1.0, "\n".join(lines), va="top", family="monospace", fontsize=7)
    fig.suptitle(_title(recons, meta), fontsize=9)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.90, bottom=0.13, hspace=0.35, wspace=0.2)
    return _pin_titles(fig)


@dataclass(frozen=True)
class ReportedResult:
    """One method's result as the report draws it: its reconstruction (no model points), the run's
    metadata and summary.json as their files hold them, its anatomical angles (None for a result
    written before they existed), its .npz, the model (the rhythm page's bones) and the joint moments (None: read
    from the files). From files: ``read_result``; from a run's outcome in memory: exubio.run.outcome.reported."""

    npz: Path
    reconstruction: Reconstruction
    metadata: Mapping[str, Any]
    summary: Mapping[str, Any] | None = None
    angles: Angles | None = None
    model: Any = None  # the model it was reconstructed with, in memory; None: the file its metadata names
    moments: Any = None  # its joint moments in memory (exubio.dynamics.moments.Moments); None: the file beside it, if any


def read_result(npz_path: str | Path, /) -> ReportedResult:
    """A written result as the report draws it (``exubio report`` on existing results)."""
    p = Path(npz_path)
    summary = beside(p, "summary")
    return ReportedResult(p, read_npz(p, points=False),  # no page draws the 3-D points: long trials stay light
                          read_npz_metadata(p),
                          json.loads(summary.read_text(encoding="utf-8")) if summary.is_file() else None,
                          read_angles(p))


def build_trial_report(npz_paths: Sequence[str | Path], pdf_path: str | Path, /, *,
                       truth: Truth | None = None) -> tuple[Path, Path]:
    """The report of written results (their .npz files): draw_trial_report of read_result."""
    return draw_trial_report([read_result(p) for p in npz_paths], pdf_path, truth=truth)


def draw_trial_report(results: Sequence[ReportedResult], pdf_path: str | Path, /, *,
                      truth: Truth | None = None) -> tuple[Path, Path]:
    """Write ``pdf_path`` and a PNG of its first page (the verdict) beside it (``.png``), atomically,
    from each method's result (a run's in memory, or read from its files). ``truth``: the known
    anatomical angles of a simulated trial (exubio.model.angles.anatomical_table of its true
    coordinates), compared on page 1 (the measured angles) and drawn."""
    recons = [r.reconstruction for r in results]
    meta = dict(results[0].metadata)
    summaries = {r.reconstruction.method: dict(r.summary) for r in results if r.summary is not None}
    angles = {r.reconstruction.method: r.angles for r in results if r.angles is not None}
    pages = [verdict_page(recons, meta, summaries, truth=truth, angles=angles)]
    if angles:
        pages.append(angles_page(recons, meta, summaries, truth, angles))
        from exubio.report.rhythm_page import trial_rhythm_figure

        pages += [f for f in (trial_rhythm_figure(r.npz, _title(recons, meta), r.reconstruction.method, angles=r.angles,
                                                  model=r.model, metadata=r.metadata)
                              for r in results if r.angles is not None) if f is not None]
    from exubio.report.moments_page import trial_moments_figure  # with --body-mass: the joint moments

    pages += [f for f in (trial_moments_figure(r.npz, _title(recons, meta), r.reconstruction.method, r.angles, r.summary,
                                               moments=r.moments) for r in results) if f is not None]
    pages.append(residuals_page(recons, meta, summaries))
    cal_page = calibration_page(meta, summaries)
    if cal_page is not None:
        pages.append(cal_page)
    pdf_path = Path(pdf_path)

    def write_pdf(tmp: Path) -> None:
        with pdf_pages(tmp) as pdf:
            for page in pages:
                pdf.savefig(page)

    atomic_write(pdf_path, write_pdf)
    png = pdf_path.with_suffix(".png")
    atomic_write(png, lambda tmp: pages[0].savefig(tmp, dpi=PAGE1_DPI))
    for page in pages:
        _release(page)
    return pdf_path, png
