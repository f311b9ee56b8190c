"""Figs. 2-5 of the validation report, the paper's own figures redrawn from the study's typed
results: PF sensitivity to the spring constant (Fig. 2), marker residuals (Fig. 3), SIER against the
truth (Fig. 4) and the shoulder angles against Ludewig et al. 2009 and the in vivo corridor (Fig. 5).

Angles are in degrees, lengths in mm, times in s; every figure names its data source.
"""
from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.figure import Figure

from exubio.report.validation_common import (
    ANGLE_TITLES,
    CORPUS_NOTE,
    C_CORRIDOR,
    C_INPUT,
    C_LS,
    C_PF,
    C_REF,
    C_TRUE,
    LUDEWIG_COLUMNS,
    MOTION_LABEL,
    _angle,
    _data_footer,
    _definition_note,
    _fmt,
    _footer,
    _new_figure,
    _residuals,
    _sier_rotation,
    _sier_xyz,
    _source_label,
)
from exubio.validation.results import (
    TRIALS,
    ValidationResults,
)


def fig_sensitivity(r: ValidationResults) -> Figure:
    sens = r.sensitivity
    cs, ks = sens.stiffness_n_per_m, sens.ratio_s
    defl = sens.mean_deflection_mm
    fig = _new_figure((8.5, 6.0))
    ax = fig.add_subplot(111)
    markers = "osD^v<>"
    failed_label = True
    top = np.nanmax(defl) if np.isfinite(defl).any() else 1.0
    for a, k in enumerate(ks):
        ax.plot(cs, defl[a], marker=markers[a % len(markers)], label=f"k = d/c = {k:g} s")
        bad = ~np.isfinite(defl[a])
        if bad.any():
            ax.plot(cs[bad], np.full(bad.sum(), top * 1.15), "x", color="tab:red", ms=9,
                    label="run failed (ReconstructionError)" if failed_label else None)
            failed_label = False
    robust = [(f.stiffness_n_per_m, f.robust_deflection_mm) for f in sens.fallback_runs]
    if robust:  # finished on PF's fallback (exubio.methods.pf.PFOptions.fallback)
        c_r, d_r = zip(*robust)
        ax.plot(c_r, d_r, "o", mfc="none", mec="tab:red", ms=11, mew=1.5,
                label="first run stopped; finished on PF's fallback\n(inertia x 0.01, full Newton)")
    p = r.paper.sensitivity
    ax.axvline(p.chosen_stiffness_n_per_m, color="0.5", ls=":", lw=1)
    ax.text(p.chosen_stiffness_n_per_m * 1.08, 0.55, "c = 1500 N/m: the paper's and\nexubio's default "
            "(d = 300 Ns/m,\nk = 0.2 s)", transform=ax.get_xaxis_transform(), fontsize=7.5, va="center", color="0.3")
    ax.set_xscale("log")
    ax.set_xlabel("spring constant c (N/m), same for every marker")
    ax.set_ylabel("mean spring deflection over all markers and frames (mm)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    tr = sens.trial
    ax.set_title(f"Fig. 2 — PF sensitivity to spring constant c and damper-spring ratio k "
                 f"({sens.runs} runs, {len(sens.failed_runs)} failed, {len(sens.fallback_runs)} on PF's fallback)\n{MOTION_LABEL[tr]}: "
                 f"{_source_label(r, tr)}, {sens.frames} frames\nall {sens.runs} runs: "
                 f"{sens.total_wall_s:.0f} s wall time on this machine", fontsize=9)
    _footer(fig, "Each point: one PF reconstruction of the whole trial with c_i = c and d_i = k·c for every marker. "
            "Deflection = |model point − marker| (Eq. 8 residual). " + _data_footer(r))
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return fig


def fig_residuals(r: ValidationResults) -> Figure:
    fig = _new_figure((9.0, 9.5))
    t1 = r.table1
    for i, name in enumerate(TRIALS):
        ax = fig.add_subplot(3, 1, i + 1)
        row = t1[name]
        t = row.time_s
        for method, color in (("pf", C_PF), ("ls", C_LS)):
            st = _residuals(row.stats(method))
            if st is None:
                continue
            m, s = st.mean_mm, st.sd_mm
            if method == "pf":
                ax.fill_between(t, m - s, m + s, color="0.8", label="PF mean ± SD over markers")
                ax.plot(t, m, color=color, lw=0.8, label="PF mean")
            else:
                ax.plot(t, m, color=color, lw=0.7, ls="--", label="LS mean")
        pf = _residuals(row.pf)
        paper = r.paper.table1[name]
        ax.set_title(f"{MOTION_LABEL[name]} — {_source_label(r, name)}, {row.markers} markers\n"
                     f"max of mean: exubio PF {_fmt(pf.max_mean_residual_mm if pf else None, '.1f')} ± "
                     f"{_fmt(pf.sd_at_max_mean_mm if pf else None, '.1f')} mm, paper {paper.max_mean_residual_mm} ± "
                     f"{paper.sd_at_max_mean_mm} mm", fontsize=8.5)
        ax.set_ylabel("marker residual (mm)")
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7, loc="upper right")
    ax.set_xlabel("time (s)")
    fig.suptitle("Fig. 3 — Marker residuals |R_i − M_i| per frame, mean ± SD over all markers (Eq. 8)", fontsize=10)
    _footer(fig, _data_footer(r))
    fig.tight_layout(rect=(0, 0.03, 1, 0.97))
    return fig


def fig_sier(r: ValidationResults) -> Figure:
    sier = r.sier
    t = sier.time_s
    fig = _new_figure((11.0, 8.5))
    gs = fig.add_gridspec(3, 2, width_ratios=(2.2, 1.0))
    mid = 0.5 * (t[0] + t[-1])
    zoom = (mid - 2.0, mid + 2.0) if t[-1] - t[0] > 6.0 else (t[0], t[-1])
    pf, ls = sier.pf, sier.ls
    rows = [
        ("GH axial rotation,\ngh_internal_rotation (deg)", sier.gh_rotation_deg, None,
         f"PF RMSE {_fmt(_sier_rotation(pf))}°, LS {_fmt(_sier_rotation(ls))}° "
         f"(paper: PF 3.69°, LS 3.13°)"),
        (f"GH marker ({sier.gh_marker}) X\ndisplacement (mm)", sier.marker_mm, 0,
         f"PF RMSE {_fmt(_sier_xyz(pf)[0])} mm, LS "
         f"{_fmt(_sier_xyz(ls)[0])} mm (paper: PF 1.66, LS 1.59 mm)"),
        (f"GH marker ({sier.gh_marker}) Z\ndisplacement (mm)", sier.marker_mm, 2,
         f"PF RMSE {_fmt(_sier_xyz(pf)[2])} mm, LS "
         f"{_fmt(_sier_xyz(ls)[2])} mm (paper: PF 1.56, LS 1.62 mm)"),
    ]
    for row, (ylabel, by_source, comp, title) in enumerate(rows):
        for c in range(2):
            ax = fig.add_subplot(gs[row, c])
            series = [("input", C_INPUT, "-", 0.6, "simulated input (noise + STA)"),
                      ("true", C_TRUE, "--", 1.2, "true value"),
                      ("pf", C_PF, "-", 0.9, "PF"), ("ls", C_LS, "-", 0.7, "LS")]
            for src, color, ls_, lw, label in series:
                y = by_source.get(src)
                if y is None:
                    continue
                y = y if comp is None else y[:, comp]
                ax.plot(t, y, color=color, ls=ls_, lw=lw, label=label)
            ax.grid(True, alpha=0.3)
            if c == 1:
                ax.set_xlim(*zoom)
                ax.set_title("zoom", fontsize=8)
            else:
                ax.set_ylabel(ylabel, fontsize=8)
                ax.set_title(title, fontsize=8.5)
                if row == 1:
                    handles, labels = ax.get_legend_handles_labels()
            if row == 2:
                ax.set_xlabel("time (s)")
    fig.legend(handles, labels, loc="upper center", ncol=4, fontsize=8, bbox_to_anchor=(0.5, 0.93), frameon=False)
    desc = textwrap.fill(sier.description, 170)
    fig.suptitle(f"Fig. 4 — SIER with measurement noise and soft-tissue artefact (STA): truth vs PF vs LS "
                 f"({sier.frames} frames)\n{desc}", fontsize=8.5)
    _footer(fig, f"GH marker: exubio's humerus marker {sier.gh_marker} over the deltoid (~100 mm below the GH "
            f"centre; the paper's GH marker sits over the humeral head). Displacements in the ISB thorax frame "
            f"(X anterior, Z right) relative to the true first-frame position; STA peak on this marker "
            f"{sier.sta_peak_mm:.1f} mm. RMSEs over the whole trial. " + _data_footer(r))
    fig.tight_layout(rect=(0, 0.04, 1, 0.915))
    return fig


def _masked(y: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = np.array(y, dtype=float)
    out[~mask.astype(bool)] = np.nan
    return out


def fig_invivo(r: ValidationResults) -> Figure:
    fig = _new_figure((17.0, 10.5))
    iv = r.invivo
    axes = fig.subplots(3, 6, sharex=True)
    for m, name in enumerate(("abduction", "flexion")):
        res = iv[name]
        plane = res.plane
        ludewig = r.ludewig[plane]
        ht_grid = res.corridor_ht_deg
        for row, joint in enumerate(("SC", "ST", "GH")):
            cor = res.corridor.get(joint)
            members = cor.members if cor is not None else ()
            for i in range(3):
                ax = axes[row, 3 * m + i]
                key = LUDEWIG_COLUMNS[joint][i]
                lo, hi = (cor.lo, cor.hi) if cor is not None else (None, None)
                if lo is not None and np.isfinite(lo[:, i]).any():
                    ax.fill_between(ht_grid, lo[:, i], hi[:, i], color=C_CORRIDOR, alpha=0.35, lw=0,
                                    label=f"corridor ({len(members)} studies)")
                for mem in members:
                    if mem.ht_deg is not None and not mem.study.startswith("Ludewig"):
                        ax.plot(mem.ht_deg, mem.deg[:, i], ls=":", color="0.35", lw=0.9,
                                label=mem.study + (" (converted)" if mem.converted else ""))
                for src, color, ls_, lw, label in (("truth", C_TRUE, "--", 1.0, "simulated truth"),
                                                   ("pf", C_PF, "-", 1.1, "PF"), ("ls", C_LS, (0, (4, 2)), 1.1, "LS")):
                    curves = res.source(src)
                    if curves is None or curves.ht_deg is None:
                        continue
                    y = curves.joint_deg[joint][:, i]
                    ax.plot(_masked(curves.ht_deg, curves.raising), _masked(y, curves.raising), color=color, ls=ls_,
                            lw=lw, label=label)
                ax.plot(ludewig["ht_elevation_deg"], ludewig[key], "o-", color=C_REF,
                        ms=2.5, lw=1.0, label="Ludewig 2009 (mean)", zorder=5)
                title = ANGLE_TITLES[joint][i]
                e = _angle(res.pf, key)
                if e is not None and e.undetermined:
                    title += "\nNOT DETERMINED by this marker set"
                    ax.set_facecolor("#eeeeee")
                elif e is not None and e.inferred:
                    title += "\nINFERRED from the model (no marker on the bone)"
                    ax.set_facecolor("#f4f4f4")
                share = e.share_inside_corridor if e is not None else None
                if share is not None and np.isfinite(share):
                    title += f"\nPF inside corridor {100 * share:.0f}% of HT 30-120"
                ax.set_title(title, fontsize=7.2)
                ax.grid(True, alpha=0.3)
                ax.tick_params(labelsize=7)
                if i == 0:
                    ax.set_ylabel(f"{joint} angle (deg)", fontsize=8)
                if row == 2:
                    ax.set_xlabel("humerothoracic elevation (deg)", fontsize=8)
    handles = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in handles:
                handles[lab] = h
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(8, len(handles)), fontsize=7.5,
               bbox_to_anchor=(0.5, 0.035), frameon=False)
    fig.suptitle("Fig. 5 — shoulder angles during arm raising in Ludewig et al. 2009's frames: exubio PF and LS vs "
                 "Ludewig's bone-pin means and the corridor of comparable in vivo studies", fontsize=11, y=0.995)
    sim_note = ""
    if any(not r.is_real(n) for n in ("abduction", "flexion")):
        sim_note = ("Simulated trials: the 'simulated truth' is the model's rhythm; PF/LS should match the truth, the "
                    "truth need not match Ludewig. ")
    _footer(fig, f"{_definition_note()} Corridor: spread of the study means (≥ 2 studies) converted to these "
            f"definitions on the model's bones (exubio.literature.corridor); dotted: the other studies; {CORPUS_NOTE}. Only raising "
            f"phases are drawn. {sim_note}" + _data_footer(r))
    fig.tight_layout(rect=(0, 0.08, 1, 0.93), h_pad=1.2)
    for m, name in enumerate(("abduction", "flexion")):
        plane = iv[name].plane
        left, right = axes[0, 3 * m].get_position(), axes[0, 3 * m + 2].get_position()
        fig.text(0.5 * (left.x0 + right.x1), left.y1 + 0.045,
                 f"({'a' if m == 0 else 'b'}) {MOTION_LABEL[name]}: {_source_label(r, name)}\n"
                 f"compared with {plane}-plane elevation",
                 ha="center", va="bottom", fontsize=8.5, fontweight="bold")
    return fig
