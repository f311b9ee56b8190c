"""Figs. 6-8 of the validation report, exubio's comparisons beyond the paper's figures: PF-LS
agreement on the same trials (Fig. 6), model mismatch and its detection (Fig. 7) and the joint
rates against the simulated truth (Fig. 8).

Angles are in degrees, lengths in mm, times in s; every figure names its data source.
"""
from __future__ import annotations


import numpy as np
from matplotlib.figure import Figure

from exubio.report.validation_common import (
    A4_LANDSCAPE,
    _agreement,
    _data_footer,
    _fmt,
    _footer,
    _new_figure,
    _paragraphs,
)
from exubio.validation.results import (
    TRIALS,
    MasslessDiagnostic,
    ModelMismatch,
    Rates,
    Skipped,
    ValidationResults,
)


def fig_agreement(r: ValidationResults) -> Figure:
    fig = _new_figure((12.5, 8.5))
    gs = fig.add_gridspec(1, 2, width_ratios=(1.0, 1.0))
    ax1, ax2 = fig.add_subplot(gs[0]), fig.add_subplot(gs[1])
    agr = r.agreement
    p = r.paper
    compared = {n: a for n in TRIALS if (a := _agreement(r, n)) is not None}
    names = list(compared)
    width = 0.8 / max(len(names), 1)
    colors = {"abduction": "tab:blue", "flexion": "tab:orange", "sier": "tab:purple"}
    coords = [str(c) for c in compared[names[0]].coordinate_names] if names else []
    markers: list[str] = []
    for a in compared.values():  # union of the trials' marker sets, in order of appearance
        markers += [str(m) for m in a.marker_names if str(m) not in markers]
    top = agr.max_coordinate_rmse_deg
    lim = max(2.4, 1.3 * float(top if np.isfinite(top) else 0.0))
    for j, (name, a) in enumerate(compared.items()):
        off = (j - (len(names) - 1) / 2) * width
        v = a.coord_rmse_deg
        det = a.determined.astype(bool)
        y = np.arange(len(coords)) + off
        src = "real" if r.is_real(name) else "simulated"
        ax1.barh(y[det], v[det], height=width, color=colors[name],
                 label=f"{name} ({src}): max {a.max_coordinate_rmse_deg:.2f}°")
        if (~det).any():
            ax1.barh(y[~det], np.minimum(v[~det], lim), height=width, color=colors[name], alpha=0.3, hatch="////",
                     edgecolor=colors[name], label=f"{name}: not determined by its markers")
            for yy, vv in zip(y[~det], v[~det]):
                ax1.text(min(vv, lim) * 0.98, yy, f"{vv:.0f}°" if vv >= 10 else f"{vv:.1f}°", ha="right",
                         va="center", fontsize=5.5, color="0.15")
        diag = a.coord_rmse_massless_deg
        if diag is not None and isinstance(a.diagnostic_massless_unobserved, MasslessDiagnostic):
            ax1.plot(diag[det], y[det], "kx", ms=5, mew=1.2,
                     label=f"{name}: PF, marker-less forearm/hand massless (diagnostic): max "
                           f"{a.diagnostic_massless_unobserved.max_coordinate_rmse_deg:.2f}°")
        w = a.marker_rmse_series_mm
        idx = np.array([markers.index(str(m)) for m in a.marker_names])
        ax2.barh(idx + off, w, height=width, color=colors[name], label=f"{name} ({src}): max {np.nanmax(w):.2f} mm")
    ax1.set_yticks(np.arange(len(coords)), coords, fontsize=7.5)
    ax2.set_yticks(np.arange(len(markers)), markers, fontsize=7.5)
    ax1.set_xlim(0, lim)
    ax1.axvline(p.pf_ls_max_joint_rmse_deg, color="0.3", ls=":", label="paper's max (1.87°)")
    ax2.axvline(p.pf_ls_max_marker_rmse_mm, color="0.3", ls=":", label="paper's max (0.37 mm)")
    ax1.set_xlabel("RMSE between PF and LS joint coordinate (deg)")
    ax2.set_xlabel("RMSE between PF and LS model-point trajectories (mm)")
    for ax in (ax1, ax2):
        ax.invert_yaxis()
        ax.grid(True, axis="x", alpha=0.3)
        ax.legend(fontsize=6.8, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=1, frameon=False)
    ax1.set_title(f"joint coordinates; max over determined ones {_fmt(agr.max_coordinate_rmse_deg)}°", fontsize=9)
    ax2.set_title(f"model points of each trial's markers; max {_fmt(agr.max_marker_rmse_mm)} mm", fontsize=9)
    fig.suptitle("Fig. 6 — Agreement of the PF and LS reconstructions of the same trials (RMSE over all frames)",
                 fontsize=10)
    und = {n: a.undetermined_coordinates for n, a in compared.items() if a.undetermined_coordinates}
    note = ""
    if und:
        note = ("Hatched (clipped, value written): coordinates the trial's markers do not determine (null space of the "
                "constrained marker Jacobian, exubio.validation.determinacy.undetermined_coordinates): there PF and LS settle "
                "differently, which is no error of either. ")
    diag = {n: a.diagnostic_massless_unobserved for n, a in compared.items()
            if isinstance(a.diagnostic_massless_unobserved, MasslessDiagnostic)}
    if diag:
        note += ("Crosses: the same PF run with the segments that carry no marker ("
                 + ", ".join(sorted({s for v in diag.values() for s in v.segments}))
                 + ") made almost massless (x 1e-3): in PF those segments still swing on their free joints and load "
                 "the humerus through its markers' springs; LS has no inertia. Bars minus crosses = that effect. ")
    _footer(fig, note + _data_footer(r))
    fig.tight_layout(rect=(0, 0.06, 1, 0.96))
    return fig


RATE_SOURCES = (("pf", "PF (integrated)", "black"), ("ls", "LS (solved rates)", "tab:red"),
                ("pf_fd", "finite differences of PF's q", "0.55"), ("ls_fd", "finite differences of LS's q", "#f4a3a3"),
                ("pf_no_lead_in", "PF without lead-in (former start)", "tab:orange"))


def fig_rates(r: ValidationResults) -> Figure:
    """Fig. 8: q̇ and q̈ RMSE against the simulated truth per coordinate, noise-free and with noise
    and STA, for PF, LS and finite differences of their q (exubio.validation.rates)."""
    fig = _new_figure((12.5, 8.5))
    rates = r.rates
    if not isinstance(rates, Rates):
        why = rates.skipped if isinstance(rates, Skipped) else "not part of this run"
        fig.text(0.05, 0.5, f"Fig. 8 — rates against the truth: {why}", fontsize=11)
        return fig
    coords = list(rates.coordinates)
    keys = [k for k in ("noise_free", "noise_sta") if k in rates.conditions]
    axes = fig.subplots(len(keys), 2, squeeze=False)
    for row, key in enumerate(keys):
        c = rates.conditions[key]
        for col, (table, unit, truth) in enumerate(((c.qd_rmse_deg_s, "deg/s", c.truth_rms_qd_deg_s),
                                                    (c.qdd_rmse_deg_s2, "deg/s²", c.truth_rms_qdd_deg_s2))):
            ax = axes[row][col]
            sources = [s for s in RATE_SOURCES if s[0] in table]
            width = 0.8 / max(len(sources), 1)
            x = np.arange(len(coords))
            for j, (src, label, color) in enumerate(sources):
                v = np.array([table[src].get(n, np.nan) for n in coords])
                worst = np.nanmax([table[src][n] for n in rates.measured_coordinates if n in table[src]])
                ax.bar(x + (j - (len(sources) - 1) / 2) * width, v, width=width, color=color,
                       label=f"{label}: worst {worst:.3g}")
            ax.plot(x, [truth[n] for n in coords], "_", color="tab:blue", ms=9, mew=1.5, label="truth RMS (scale)")
            ax.set_yscale("log")
            ax.set_xticks(x, coords, rotation=60, ha="right", fontsize=6.5)
            ax.set_ylabel(f"RMSE vs truth ({unit})", fontsize=8)
            level = "q̇" if col == 0 else "q̈"
            cond = "noise-free" if key == "noise_free" else f"noise {c.noise_mm:g} mm + STA {c.sta_mm:g} mm"
            ax.set_title(f"{level}, {cond} ({c.frames} frames at {c.rate_hz:g} Hz)", fontsize=9)
            ax.grid(True, axis="y", alpha=0.3)
            ax.legend(fontsize=6, loc="upper left", ncol=2, frameon=False)
            if key == "noise_free":
                ax.axhline(rates.aim_qd_deg_s if col == 0 else rates.aim_qdd_deg_s2, color="0.3", ls=":")
    fig.suptitle("Fig. 8 — Joint rates against the simulated truth (simulated abduction, 21 markers): PF's integrated "
                 "q̇, q̈ vs LS's and vs finite differences of q", fontsize=10)
    cond = rates.conditions.get("noise_free")
    lines = []
    if cond is not None:
        lines.append("Constraint residuals noise-free, max |g| / |G q̇| (1/s) / |G q̈ + η| (1/s²): " + "; ".join(
            f"{k} {cond.max_abs_g[k]:.1e} / {cond.max_abs_g_qd_1_s[k]:.1e} / {cond.max_abs_g_qdd_eta_1_s2[k]:.1e}"
            for k in ("pf", "ls", "pf_fd", "ls_fd") if k in cond.max_abs_g) + ".")
    lines.append(f"Dotted: the aims of issue 21 for noise-free PF on every measured coordinate ({rates.aim_qd_deg_s:g} "
                 f"deg/s, {rates.aim_qdd_deg_s2:g} deg/s²); PF worst measured: "
                 f"{rates.pf_noise_free_max_qd_rmse_deg_s:.3g} deg/s, {rates.pf_noise_free_max_qdd_rmse_deg_s2:.3g} deg/s². "
                 "Orange: PF started at the first frame: its q̈ starts at the force-free value and the stiff "
                 "spring-damper mode settles in ~40 ms, which was the whole of PF's noise-free q̈ error; the run now "
                 "starts 0.1 s earlier on targets extrapolated backwards (PFOptions.lead_in_s). With noise and STA, "
                 "PF's springs and dampers act as a low-pass far above the targets' filter cut-off (d/m ~ 300 1/s): "
                 "its rates carry the filtered targets' error much as LS's do.")
    _footer(fig, " ".join(lines) + " " + _data_footer(r))
    fig.tight_layout(rect=(0, 0.07, 1, 0.95))
    return fig


def fig_mismatch(r: ValidationResults) -> Figure:
    """Fig. 7: per perturbation, the worst measured angle's RMSE of every run (motion x artefact x
    method), filled where the verdict's model-mismatch check named a segment; the cost limit."""
    fig = _new_figure(A4_LANDSCAPE)
    m: ModelMismatch | None = r.mismatch
    fig.text(0.03, 0.95, "Fig. 7 — Model mismatch: trials generated with a perturbed model, reconstructed with the "
             "generic one", fontsize=12, fontweight="bold")
    if m is None:
        fig.text(0.03, 0.85, "This results file has no model-mismatch section (made before it existed).", fontsize=9)
        return fig
    cases = list(dict.fromkeys(run.case for run in m.runs))
    ax = fig.add_axes((0.27, 0.36, 0.70, 0.54))
    colours = {"abduction": "tab:blue", "flexion": "tab:orange", "scaption": "tab:green"}
    for i, case in enumerate(cases):
        for run in (x for x in m.runs if x.case == case):
            y = len(cases) - 1 - i + (0.12 if run.artefact != "clean" else -0.12) + (0.05 if run.method == "pf" else 0.0)
            c = colours.get(run.motion, "0.4")
            ax.scatter([run.worst_rmse_deg], [y], s=34, marker="o" if run.artefact == "clean" else "^",
                       facecolors=c if run.mismatch_segments else "none", edgecolors=c, linewidths=1.2)
    ax.axvline(m.cost_limit_deg, color="0.3", ls="--", lw=1)
    ax.set_yticks(range(len(cases)))
    ax.set_yticklabels(list(reversed(cases)), fontsize=8)
    ax.set_xlabel("worst measured anatomical angle, RMSE against the truth (deg)")
    ax.grid(axis="x", alpha=0.3)
    for name, c in colours.items():
        ax.scatter([], [], color=c, label=name)
    ax.scatter([], [], marker="o", facecolors="none", edgecolors="0.3", label="no artefact")
    ax.scatter([], [], marker="^", facecolors="none", edgecolors="0.3",
               label=f"noise {m.noise_mm:g} mm + STA {m.sta_mm:g} mm")
    ax.scatter([], [], marker="o", color="0.3", label="filled: verdict names a model mismatch")
    ax.legend(fontsize=7, loc="lower right")
    lines = [f"Simulated trials of {m.duration_s:g} s at {m.rate_hz:g} Hz (one elevation cycle, HT 10-120-10 deg), "
             f"generated with the perturbed model, reconstructed with the generic one (methods: "
             f"{', '.join(sorted({x.method.upper() for x in m.runs}))}); each run assessed alone. Mismatch cost = the "
             f"worst measured angle's RMSE of the same perturbation and motion without artefact.",
             f"Runs whose mismatch costs more than {m.cost_limit_deg:g} deg: {m.costly}; the verdict is check naming "
             f"the segment in {m.caught}. Missed: {'; '.join(m.missed) or 'none'}.",
             f"Runs without mismatch: {m.no_mismatch}; model-mismatch check raised: {len(m.false_alarms)}"
             + (f" ({'; '.join(m.false_alarms)})" if m.false_alarms else "") + f"; verdict not ok for any reason: "
             f"{len(m.no_mismatch_not_ok)}" + (f" ({'; '.join(m.no_mismatch_not_ok)})" if m.no_mismatch_not_ok else "")
             + ".",
             "Flagged although cheaper than the limit: " + ("; ".join(m.flagged_cheap) or "none") + ".",
             "What it cannot catch (studies/README.md, 'Model mismatch'): one scapula marker placed off on the model "
             "(SCAP_IA 20 mm: the scapula's rigid fit absorbs it; a per-marker rule would fire on every real C3D trial, "
             "whose SCAP_Cor sits 17-19 mm off on average); an ellipsoid moved along the scapula's path (15 mm superior: "
             "GH plane of elevation and axial rotation 8-10 deg RMSE with 3 mm residual) or stretched along one axis; "
             "a scapula with fewer than 3 markers; a segment-length error with no marker distal to it; what noise and "
             "soft-tissue artefact cost by themselves (up to ~5 deg here with 20 mm STA; not a model mismatch). A static "
             "calibration removes most of these generic-model mismatches (studies/model_mismatch.py --calibrate)."]
    _paragraphs(fig, lines, 0.29, width=185, fontsize=7.5, gap=0.006)
    _footer(fig, "Data: simulated (exubio.synth.simulate with exubio.synth.perturb). " + f"exubio {r.exubio_version}"
            + (" — QUICK RUN (two cases, abduction, LS only)" if r.quick else ""))
    return fig
