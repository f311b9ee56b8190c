"""The table pages of the validation report: Table 1 (effort and residuals), the SIER spread over
noise/STA seeds, the Ludewig comparison (numbers, corridor membership, the C3D tasks) and the
cross-validated scapula calibration.
"""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from exubio.report.validation_common import (
    A4_LANDSCAPE,
    CORPUS_NOTE,
    LUDEWIG_CITATION,
    MOTION_LABEL,
    _angle,
    _data_footer,
    _definition_note,
    _fmt,
    _footer,
    _new_figure,
    _paragraphs,
    _residuals,
    _table,
)
from exubio.validation.results import (
    METHODS,
    TRIALS,
    AngleComparison,
    MedianMax,
    ScapulaVariant,
    SierRunMethod,
    Skipped,
    ValidationResults,
)


def table1_page(r: ValidationResults) -> Figure:
    fig = _new_figure(A4_LANDSCAPE)
    cells = []
    for name in TRIALS:
        row, pp = r.table1[name], r.paper.table1[name]
        for method in METHODS:
            m = _residuals(row.stats(method))
            if m is None:
                cells.append([f"{name} ({row.data})", method.upper()] + ["failed"] * 7)
                continue
            cells.append([f"{name} ({row.data})", method.upper(), str(row.frames), f"{row.duration_s:.1f}",
                          _fmt(row.wall_time_s(method), ".1f"), _fmt(m.ms_per_frame, ".2f"),
                          f"{_fmt(m.max_mean_residual_mm, '.1f')} ± {_fmt(m.sd_at_max_mean_mm, '.1f')}",
                          f"{_fmt(m.max_residual_mm, '.1f')} ({m.max_residual_marker})",
                          f"{_fmt(m.max_rmse_mm, '.1f')} ({m.max_rmse_marker})"])
        cells.append([f"{name}: paper", "PF / LS", str(pp.frames), str(pp.duration_s),
                      f"{pp.pf_wall_s} / {pp.ls_wall_s}",
                      f"{pp.pf_wall_s / pp.frames * 1000:.1f} / {pp.ls_wall_s / pp.frames * 1000:.0f}",
                      f"{pp.max_mean_residual_mm} ± {pp.sd_at_max_mean_mm}",
                      f"{pp.max_residual_mm} ({pp.max_residual_marker})",
                      f"{pp.max_rmse_mm} ({pp.max_rmse_marker})"])
    ax = fig.add_axes((0.03, 0.30, 0.94, 0.6))
    tab = _table(ax, cells, ["scenario (data)", "method", "input\nframes", "simulated\nduration (s)",
                             "wall time\n(s)", "ms / frame", "max mean residual\n± SD (mm)",
                             "max residual\n(marker), mm", "max RMSE\n(marker), mm"],
                 col_widths=[0.16, 0.07, 0.08, 0.09, 0.09, 0.08, 0.15, 0.14, 0.14], fontsize=7.5, header_lines=2)
    for (row, _), cell in tab.get_celld().items():
        if row > 0 and row % 3 == 0:
            cell.set_facecolor("#f3f3f3")
    fig.text(0.03, 0.95, "Table 1 — Computational effort and reconstruction errors (exubio rows, then the paper's row)",
             fontsize=12, fontweight="bold")
    note = ("Residual = |model point − marker| (mm). 'max mean residual ± SD': the largest per-frame mean over "
            "markers (Eq. 8) and the SD over markers in that frame; 'max residual': largest single-marker residual; "
            "'max RMSE': largest per-marker RMSE over the trial. Wall time: exubio's whole reconstruction (initial "
            "state, build, integration/solve, recovery) in one process on this machine; the paper's PF is SIMPACK "
            "and its LS an in-house MATLAB fmincon code on a 3.3 GHz desktop, so the LS/PF ratio is not a "
            "like-for-like comparison. Marker names differ: the paper's 'GH' marker (over the humeral head) is gu "
            "in the real TRC trials and DELT/ARM in the simulated upper_limb_21 set; its 'TS1' is ts resp. SCAP_BACK. "
            "The real trials have 6 tracked markers (paper: 21) and last 11 s and 8 s (paper: 25 s). Simulated "
            "residuals contain the simulated STA (peak "
            f"{r.settings.sta_mm:g} mm on each humerus marker) and noise, not a real subject's STA. "
            + _data_footer(r))
    for k, line in enumerate(textwrap.wrap(note, 190)):
        fig.text(0.03, 0.86 - (len(cells) + 2) * 0.034 - 0.04 - k * 0.022, line, fontsize=7.5)
    return fig


def _median_or_max(stat: MedianMax | None, worst: bool) -> float | None:
    return None if stat is None else (stat.max if worst else stat.median)


def sier_realisations_page(r: ValidationResults) -> Figure:
    fig = _new_figure(A4_LANDSCAPE)
    rz = r.sier_realisations
    main_seed = r.settings.seed
    cells = []
    for row in rz.runs:
        line = [str(row.seed) + (" (Fig. 4 seed)" if row.seed == main_seed else "")]
        for method in METHODS:
            m = row.method(method)
            if not isinstance(m, SierRunMethod):
                line += ["failed", "failed", "failed"]
                continue
            line += [_fmt(m.gh_axial_rotation_rmse_deg), " / ".join(_fmt(v) for v in m.gh_marker_rmse_xyz_mm),
                     f"{_fmt(m.max_joint_rmse_deg)} ({m.max_joint})"]
        cells.append(line)
    for worst, label in ((False, "median"), (True, "worst")):
        line = [label]
        for method in METHODS:
            sm = rz.summary.get(method)
            rot, x, z = (sm.gh_axial_rotation_rmse_deg, sm.gh_marker_x_rmse_mm, sm.gh_marker_z_rmse_mm) if sm else (
                None, None, None)
            line += [_fmt(_median_or_max(rot, worst)),
                     f"X {_fmt(_median_or_max(x, worst))}, Z {_fmt(_median_or_max(z, worst))}", ""]
        cells.append(line)
    cells.append(["paper", "3.69", "X 1.66, Z 1.56", "", "3.13", "X 1.59, Z 1.62", ""])
    ax = fig.add_axes((0.03, 0.2, 0.94, 0.7))
    _table(ax, cells, ["noise/STA seed", "PF GH axial\nRMSE (deg)", "PF GH marker\nX / Y / Z RMSE (mm)",
                       "PF worst joint\nRMSE (deg)", "LS GH axial\nRMSE (deg)", "LS GH marker\nX / Y / Z RMSE (mm)",
                       "LS worst joint\nRMSE (deg)"],
           col_widths=[0.11, 0.12, 0.17, 0.18, 0.12, 0.17, 0.18], fontsize=7.2, header_lines=2)
    fig.text(0.03, 0.95, f"Fig. 4 (spread) — SIER accuracy over {len(rz.runs)} noise/STA realisations "
             f"({rz.duration_s:g} s at {rz.rate_hz:g} Hz, noise SD {rz.noise_mm:g} mm, "
             f"STA {rz.sta_mm:g} mm)", fontsize=11.5, fontweight="bold")
    note = ("The soft-tissue artefact of exubio.synth.simulate has a random direction and a random mix of driving joint "
            "angles per marker (seeded); its size is fixed (every humerus marker peaks at the STA amplitude). How "
            "much of it leaks into the joint angles depends on that realisation, so one seed (Fig. 4) is not enough: "
            "this table repeats SIER with seeds 0, 1, ... at a lower sampling rate. RMSE against the simulated true "
            "joint angles / true model-point positions over the whole trial; 'worst joint' = the model coordinate "
            f"with the largest RMSE. The paper reports X and Z of its GH marker only. GH marker = "
            f"{r.sier.gh_marker}. " + _data_footer(r))
    n_rows = len(cells) + 2
    for k, line in enumerate(textwrap.wrap(note, 190)):
        fig.text(0.03, 0.86 - n_rows * 0.034 - 0.04 - k * 0.022, line, fontsize=7.5)
    return fig


COMPARED_ROWS = (("ST_medRotation_X", "ST upward rotation (X′, − = up)"), ("ST_protraction_Y", "ST internal rotation (Y)"),
                 ("ST_tilt_Z", "ST posterior tilt (Z″)"), ("GH_abduction_X", "GH elevation (X, − = up)"),
                 ("GH_flexion_Z", "GH flexion (Z′)"), ("GH_rotation_Y", "GH axial rotation (Y″)"),
                 ("SC_elevation_X", "SC elevation (X′, − = up)"), ("SC_protraction_Y", "SC protraction (Y)"),
                 ("SC_rotation_Z", "SC posterior rotation (Z″)"))


def _share(e: AngleComparison) -> str:
    v = e.share_inside_corridor
    if v is None or not np.isfinite(v):
        return f"n/a ({e.corridor_studies} study)"
    return f"{100 * v:.0f}% ({e.corridor_studies})"


def ludewig_page(r: ValidationResults) -> list[Figure]:
    iv = r.invivo
    hts = [int(h) for h in iv["abduction"].ht_check_deg]
    h = "/".join(str(v) for v in hts)
    fig = _new_figure(A4_LANDSCAPE)
    head = ["motion", "angle", f"Ludewig at HT\n{h}° (deg)", f"PF − Ludewig\nat {h}° (deg)",
            f"LS − Ludewig\nat {h}° (deg)", "PF / LS inside\ncorridor (studies)", "PF − Ludewig in ISB\nframes (AA) (deg)",
            "flag"]
    widths = [0.07, 0.17, 0.14, 0.14, 0.14, 0.13, 0.14, 0.07]
    rows = []
    for name in ("abduction", "flexion"):
        for key, label in COMPARED_ROWS:
            pf, ls = _angle(iv[name].pf, key), _angle(iv[name].ls, key)
            if pf is None:
                continue
            flag = "not det." if pf.undetermined else ("inferred" if pf.inferred else "")
            rows.append([name, label, " / ".join(_fmt(v, ".1f") for v in pf.ludewig_deg),
                         " / ".join(_fmt(v, "+.1f") for v in pf.deviation_deg),
                         " / ".join(_fmt(v, "+.1f") for v in ls.deviation_deg) if ls else "—",
                         f"{_share(pf)} / {_share(ls).split(' ')[0] if ls else '—'}",
                         " / ".join(_fmt(v, "+.1f") for v in pf.isb_frame_deviation_deg)
                         if pf.isb_frame_deviation_deg is not None else "", flag])
    fig.text(0.02, 0.965, f"Fig. 5 (numbers) — exubio vs Ludewig et al. 2009 in Ludewig's frames at HT {h}°, "
             f"and the share of HT 30-120° inside the corridor", fontsize=11.5, fontweight="bold", va="top")
    ax = fig.add_axes((0.02, 0.33, 0.96, 0.6))
    _table(ax, rows, head, col_widths=widths, fontsize=6.3, row_scale=1.1, header_lines=2)
    lines = []
    for c in r.invivo_aims:
        if c.passed is None:
            lines.append(f"[n/a] {c.what}: {c.note or ''}")
        else:
            val = f"{100 * c.value:.0f}% (aim ≥ {100 * c.limit:.0f}%)" if c.unit == "share" else \
                f"{_fmt(c.value, '.1f')} deg (aim ≤ {c.limit:g})"
            lines.append(f"[{'MET' if c.passed else 'NOT MET'}] {c.what}: {val}")
    fig.text(0.02, 0.315, "Aims (issue 10), per trial and method:", fontsize=8, va="top", fontweight="bold")
    col = [lines[i::2] for i in range(2)]
    for j, chunk in enumerate(col):
        for k, line in enumerate(chunk):
            fig.text(0.02 + 0.49 * j, 0.295 - k * 0.0125, textwrap.shorten(line, 125), fontsize=5.6, va="top")
    note = (f"Values: mean over raising frames with HT within ±2.5° of each elevation (n/a = not reached). "
            f"Deviation = exubio − Ludewig, both in Ludewig's definitions; the ISB column repeats the deviation with "
            f"exubio's ISB frames (scapula on AA): the difference between the two columns is the frame definition "
            f"alone. Corridor: studies (count in brackets) whose frames are built on the model; 'n/a (1 study)': "
            f"Ludewig is the only comparable study in that plane. 'not det.': the marker set does not determine "
            f"the angle; 'inferred': a bone of the joint carries no marker. {_definition_note()} {LUDEWIG_CITATION}.")
    for k, line in enumerate(textwrap.wrap(note, 230)):
        fig.text(0.02, 0.075 - k * 0.0135, line, fontsize=6.3)
    return [fig, _corridor_studies_page(r), _c3d_tasks_page(r)]


def _c3d_tasks_page(r: ValidationResults) -> Figure:
    fig = _new_figure(A4_LANDSCAPE)
    c3d = r.c3d_tasks
    fig.text(0.02, 0.965, "Fig. 5 (C3D tasks) — the 21-marker C3D trials against Ludewig et al. 2009 where a plane of "
             "elevation matches", fontsize=11.5, fontweight="bold", va="top")
    if isinstance(c3d, Skipped):
        fig.text(0.02, 0.9, f"Not run: {c3d.skipped}", fontsize=9, va="top")
        return fig
    rows, reasons = [], []
    for trial, rec in c3d.trials.items():
        if isinstance(rec, Skipped):
            reasons.append(f"{trial}: skipped: {rec.skipped}")
            continue
        for plane, res in rec.matched.items():
            for key, label in COMPARED_ROWS[:6]:
                pf, ls = _angle(res.pf, key), _angle(res.ls, key)
                if pf is None and ls is None:
                    continue
                e = pf if pf is not None else ls
                span = (res.ls or res.pf).raising_ht_range_deg
                flag = "not det." if e.undetermined else ("inferred" if e.inferred else "")
                rows.append([trial.replace("bioptim_exo_", ""), plane, f"{span[0]:.0f}-{span[1]:.0f}", label,
                             " / ".join(_fmt(v, ".1f") for v in e.ludewig_deg),
                             " / ".join(_fmt(v, "+.1f") for v in pf.deviation_deg) if pf else "—",
                             " / ".join(_fmt(v, "+.1f") for v in ls.deviation_deg) if ls else "—",
                             f"{_share(pf) if pf else '—'} / {_share(ls).split(' ')[0] if ls else '—'}", flag])
        for plane, why in rec.not_matched.items():
            reasons.append(f"{trial.replace('bioptim_exo_', '')}, {plane}: {why}")
    head = ["trial", "plane", "HT range\n(deg)", "angle", "Ludewig at HT\n30/60/90/120 (deg)",
            "PF − Ludewig\n(deg)", "LS − Ludewig\n(deg)", "PF / LS inside\ncorridor", "flag"]
    widths = [0.16, 0.06, 0.06, 0.16, 0.13, 0.12, 0.12, 0.1, 0.06]
    top = 0.93
    if rows:
        ax = fig.add_axes((0.02, top - 0.03 * (len(rows) + 2), 0.96, 0.03 * (len(rows) + 2)))
        _table(ax, rows, head, col_widths=widths, fontsize=6.5, row_scale=1.1, header_lines=2)
        top -= 0.03 * (len(rows) + 2) + 0.03
    fig.text(0.02, top, "Planes not compared, and why:", fontsize=8, fontweight="bold", va="top")
    for k, line in enumerate(reasons):
        fig.text(0.03, top - 0.02 - k * 0.0135, textwrap.shorten(line, 240), fontsize=6.2, va="top")
    _footer(fig, "The C3D trials are free tasks, not planar elevations: a frame counts as elevation in a reference plane "
            f"when the arm is being raised and its plane of elevation (ISB HT Y angle) is within "
            f"{c3d.plane_tolerance_deg:g}° of the plane's (frontal 0°, scapular 40°, sagittal 90°); a plane is "
            f"compared when those frames cover at least {c3d.min_span_deg:g}° of HT elevation above 30°. "
            "Each trial is calibrated on its session's static trial. Deviation: exubio − Ludewig in Ludewig's frames "
            "(n/a = elevation not reached). " + _data_footer(r))
    return fig


def _corridor_studies_page(r: ValidationResults) -> Figure:
    fig = _new_figure(A4_LANDSCAPE)
    iv = r.invivo
    fig.text(0.02, 0.965, "Fig. 5 (corridor) — which studies are in each corridor, and why the others are not",
             fontsize=11.5, fontweight="bold", va="top")
    y = 0.925
    cited: dict[str, str] = {}
    for name in ("abduction", "flexion"):
        res = iv[name]
        for joint in ("SC", "ST", "GH"):
            cor = res.corridor.get(joint)
            members = cor.members if cor is not None else ()
            mem = ", ".join(m.study + (" (converted)" if m.converted else "") for m in members)
            for m in members:
                cited[m.study] = m.citation
            fig.text(0.02, y, f"{MOTION_LABEL[name]} ({res.plane} plane), {joint}: in the corridor: {mem or 'none'}",
                     fontsize=7.2, va="top", fontweight="bold")
            y -= 0.018
            for study, why in sorted((cor.excluded if cor is not None else {}).items()):
                fig.text(0.04, y, textwrap.shorten(f"left out: {study}: {why}", 200), fontsize=6.4, va="top")
                y -= 0.0145
            y -= 0.006
    y -= 0.01
    fig.text(0.02, y, "Studies shown: " + "; ".join(cited[k] for k in sorted(cited)) + f". Corpus: {CORPUS_NOTE}.",
             fontsize=6.4, va="top", wrap=True)
    _footer(fig, "Converted: the study's three angles re-expressed in Ludewig's definitions with the constant frame "
            "offsets between the two definitions on the model's bones (exubio.literature.corridor.convert_angles); a study in "
            "Ludewig's own definitions is taken as published. " + _data_footer(r))
    return fig


SCAPULA_VARIANTS = {"own_still": "own still frames (as Fig. 5)",
                    "cal_still": "other trial: still frames",
                    "cal_still_motion": "other trial: still + motion",
                    "pooled_not_cross_validated": "both motions: NOT cross-val."}


def scapula_page(r: ValidationResults) -> Figure:
    """The scapula calibrated over motion, cross-validated (exubio.validation.scapula): one table
    row per direction and calibration, and the simulated subject."""
    fig = _new_figure(A4_LANDSCAPE)
    fig.text(0.03, 0.95, "The scapula calibrated over motion — cross-validated: calibrated on one trial, reconstructing "
                         "the other", fontsize=12, fontweight="bold")
    scv = r.scapula
    if scv is None:
        fig.text(0.03, 0.88, "not part of this run", fontsize=10)
        return fig
    cells = []
    for d in scv.real.values():
        for vk, label in SCAPULA_VARIANTS.items():
            v = d.variants.get(vk)
            head = [f"{Path(d.calibration_trial).stem.replace('tsm_rmr_', '')} → "
                    f"{Path(d.reconstructed_trial).stem.replace('tsm_rmr_', '')}", label]
            if not isinstance(v, ScapulaVariant):
                cells.append(head + [getattr(v, "skipped", "not run")] + [""] * 6)
                continue
            fit = (f"{_fmt(v.contact_rms_before_mm, '.1f')} → {_fmt(v.contact_rms_after_mm, '.1f')}"
                   if v.motion_fit == "used" else v.motion_fit)
            mk = v.marker_rmse_mm["pf"]
            st = v.st_model_minus_data_rmse_deg["pf"]
            stx = v.st_model_minus_data_max_deg["pf"]
            lud = " / ".join(f"{v.ludewig_deviation_deg[k][0]:+.0f}, {v.ludewig_deviation_deg[k][-1]:+.0f}"
                             for k in ("ST_protraction_Y", "ST_medRotation_X", "ST_tilt_Z"))
            share = " / ".join(f"{v.ludewig_share_inside_corridor[k]:.0%}"
                               for k in ("ST_protraction_Y", "ST_medRotation_X", "ST_tilt_Z"))
            cells.append(head + [fit, f"{mk.get('aa', np.nan):.1f} / {mk.get('ts', np.nan):.1f} / {mk.get('ai', np.nan):.1f}",
                                 " / ".join(f"{x:.1f}" for x in st), " / ".join(f"{x:.0f}" for x in stx), lud, share,
                                 f"{max(v.marker_rmse_mm['ls'].get('ts', np.nan), v.marker_rmse_mm['ls'].get('ai', np.nan)):.1f}"])
    if not cells:
        cells.append(["real TRC subject", scv.real_skipped or "skipped"] + [""] * 7)
    ax = fig.add_axes((0.02, 0.36, 0.96, 0.55))
    _table(ax, cells, ["direction", "calibration", "contact points off\nellipsoid (mm RMS)",
                       "PF RMSE aa / ts / ai\n(mm)", "PF model − data ST\nRMSE int. rot / upward / tilt (°)",
                       "PF model − data ST\nmax (°)", "PF − Ludewig at HT 30, 120 (°)\nST int. rot / upward / tilt",
                       "inside corridor\nint. rot / upward / tilt", "LS worst ts/ai\nRMSE (mm)"],
           col_widths=[0.09, 0.15, 0.1, 0.1, 0.15, 0.09, 0.15, 0.11, 0.07], fontsize=6.5, header_lines=2)
    sim = scv.simulated
    pooled = " / ".join(_fmt(d.variants["pooled_not_cross_validated"].contact_rms_after_mm, ".1f")
                        for d in scv.real.values()
                        if isinstance(d.variants.get("pooled_not_cross_validated"), ScapulaVariant)) or "n/a"
    lines = [
        "Model − data: the model's ISB scapula orientation (ST, Y-X′-Z″) minus the registered scapula rigidly fitted to "
        "each frame's aa/ts/ai (a rigid triangle in these data), RMSE and max over the frames at HT 30-120°. Ludewig "
        "et al. 2009 in his own frames (ST on AC); the corridor as on the Fig. 5 pages. Aims (issue 21): ts and ai RMSE "
        "≤ 12 mm in both directions, model − data ST ≤ 5° RMSE.",
        "Simulated subject: " + sim.description + ": flexion ST max error per angle (int. rot / upward / tilt) "
        + "; ".join(f"{k.replace('_', ' + ')}: " + " / ".join(f"{x:.2f}" for x in v) + "°"
                    for k, v in sim.st_max_error_deg.items())
        + "; its true contact points up to " + ", ".join(f"{v:.1f} mm ({k.replace('_', ' + ')})"
                                                         for k, v in sim.flexion_contacts_max_off_ellipsoid_mm.items())
        + " off the calibrated ellipsoid.",
        "What the data allow: no acromion-cluster double calibration (the TRC subject's aa/ts/ai are one rigid "
        "registration, constant to 0.01 mm; each C3D session has one static trial, arm down). A single thorax-aligned "
        "ellipsoid fitted through both trials' postures (last rows, not a validation) still leaves the contact points "
        f"{pooled} mm RMS off it: the two planes' scapula paths do not lie on one such surface, which bounds "
        "what a cross-validated calibration can reach on these data.",
    ]
    _paragraphs(fig, lines, 0.33, width=200, fontsize=7.2, gap=0.01)
    _footer(fig, _data_footer(r))
    return fig


def bone_page(r: ValidationResults) -> Figure:
    """exubio against bone (exubio.validation.bone): per bone-referenced trial and angle, LS's RMSE /
    max / coverage of +-2u (PF beside it where it ran), beside the published skin-marker ranges."""
    from exubio.validation.records_comparisons import BONE_PUBLISHED as PUBLISHED
    from exubio.validation.records_comparisons import BONE_SHOWN as SHOWN
    from exubio.validation.records_comparisons import BoneTruth

    fig = _new_figure(A4_LANDSCAPE)
    fig.text(0.03, 0.95, "exubio against bone: the ISB soft-tissue-artefact data-sharing trials (Cereatti et al. 2017)",
             fontsize=12, fontweight="bold")
    bone = r.bone
    if not isinstance(bone, BoneTruth):
        fig.text(0.03, 0.88, getattr(bone, "skipped", None) or "not part of this run", fontsize=10)
        return fig
    tasks = list(bone.tasks.values())
    cells = []
    for a in SHOWN:
        row = [a]
        for t in tasks:
            for m in ("ls", "pf"):
                e = t.angles.get(a, {}).get(m)
                if e is None or not np.isfinite(e.rmse_deg):
                    row.append("failed" if str(t.verdicts.get(m, "")).startswith("failed") else "not measured")
                    continue
                cov = "-" if not np.isfinite(e.coverage) else f"{e.coverage:.0%}"
                row.append(f"{e.rmse_deg:.1f} / {e.max_deg:.0f} / {cov}")
        cells.append(row)
    def verdict(text: str) -> str:  # "failed: FILE: why" -> "failed: why"
        parts = text.split(": ", 2)
        return (f"failed: {parts[2]}" if text.startswith("failed") and len(parts) == 3 else text)[:24]

    cells.append(["verdict"] + [verdict(str(t.verdicts.get(m, "-"))) for t in tasks for m in ("ls", "pf")])
    head = ["angle"] + [f"{t.task}\n{m.upper()}" for t in tasks for m in ("ls", "pf")]
    ax = fig.add_axes((0.02, 0.30, 0.96, 0.60))
    w = (1 - 0.2) / max(len(head) - 1, 1)
    _table(ax, cells, head, col_widths=[0.2] + [w] * (len(head) - 1), fontsize=6.2, header_lines=2)
    fig.text(0.03, 0.24, "cells: RMSE / max (deg) over the frames where the angle is measured / coverage: the fraction "
                         "of those frames where the bone lies within +-2u (aim about 95 %)", fontsize=8)
    fig.text(0.03, 0.20, f"published, skin markers against bone (Begon et al. 2018): GH {PUBLISHED['GH'][0]:g}-"
                         f"{PUBLISHED['GH'][1]:g} deg RMSE; the scapula, best methods below 120 deg of elevation, "
                         f"{PUBLISHED['ST'][0]:g}-{PUBLISHED['ST'][1]:g} deg", fontsize=8)
    fig.text(0.03, 0.16, "assumed (the files carry no thorax or clavicle marker): " + bone.assumption, fontsize=7,
             wrap=True)
    fig.text(0.03, 0.08, "what remains without any skin artefact (each marker carried by its bone), the artefact "
                         "model and the coverage on simulations: studies/README.md, 'exubio against bone'",
             fontsize=7)
    return fig
