"""The trial report's calibration page (exubio.report.trial_report adds it when the trial was
reconstructed with a subject calibration): from what the model was calibrated, what was fitted
(segment scales, the thorax ellipsoid, the joint centres and the static pose, the functional
glenohumeral centre), where each marker sits (its residual, its offset from its generic place,
its distance from the landmark it is declared over, the worst marked) and the calibration's checks
in full. Read from the summaries' ``calibration`` entries only: no solver here."""
from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

LANDMARK_LIMIT_MM = 40.0  # exubio.trust.quality.LANDMARK_OFFSET_MM, drawn on the marker chart
_MONO_EM = 0.6  # a monospace character's width, in font sizes
_LEVEL_COLOURS = {"fail": "tab:red", "check": "tab:orange", "note": "0.35"}
_PATH = re.compile(r"(?<![\w.])(?:[A-Za-z]:)?(?:[\\/][^\s()\\/,:;]+)+[\\/]([^\s()\\/,:;]+)")


def short_paths(text: str) -> str:
    """A message with every absolute path written as its file name (the report's pages name the
    trial's files; the full paths are in the summary.json)."""
    return _PATH.sub(lambda m: m.group(1), text)


def calibration_page(meta: dict, summaries: dict[str, dict]) -> Figure | None:
    """The page (None when the trial was reconstructed without a calibration)."""
    first = next(iter(summaries.values()), {})
    cal = first.get("calibration") or {}
    rep = cal.get("report") or {}
    if not rep:
        return None
    fig = Figure(figsize=(11.69, 8.27))
    FigureCanvasAgg(fig)
    fr = rep.get("frames") or {}
    fig.suptitle(f"Subject calibration from {Path(str(cal.get('static') or rep.get('source', ''))).name}",
                 fontsize=13, y=0.975)
    window = (f"static pose: frames {fr.get('start')}:{fr.get('stop')} ({fr.get('n_frames')} frames"
              + (", the stillest stretch, found automatically" if fr.get("chosen_automatically") else "") + ")"
              + f"; calibrated model: {Path(str(cal.get('model_file', ''))).name}")
    fig.text(0.5, 0.935, window, ha="center", fontsize=9)
    checks = _checks(summaries)
    bottom = _draw_checks(fig, checks)
    _draw_fitted(fig, rep, top=0.89, bottom=bottom + 0.03)
    _draw_markers(fig, rep, top=0.84, bottom=bottom + 0.06)
    return fig


def _checks(summaries: dict[str, dict]) -> list[tuple[str, str]]:
    seen, out = set(), []
    for s in summaries.values():
        for r in (s.get("quality") or {}).get("reasons", []):
            if r["code"].startswith("calibration") and r["message"] not in seen:
                seen.add(r["message"])
                out.append((r["level"], r["message"]))
    return out


def _wrap(text: str, width_fig: float, fontsize: float, fig: Figure) -> list[str]:
    chars = max(20, int(width_fig * fig.get_figwidth() * 72 / (fontsize * _MONO_EM)))
    return textwrap.wrap(text, chars, subsequent_indent="    ") or [""]


def _draw_checks(fig: Figure, checks: list[tuple[str, str]], max_lines: int = 10) -> float:
    """The calibration's checks at the foot of the page, in full, each in its level's colour; the
    top of the block (figure fraction)."""
    size, line = 8.5, 8.5 * 1.35 / 72 / fig.get_figheight()
    if not checks:
        checks = [("note", "no calibration warning: the scales inside their bounds, the static pose inside the ranges, "
                           "a still window, every landmark marker near its landmark")]
    y, used = 0.03, 0
    blocks = []
    for level, message in checks:
        lines = _wrap(f"{level}: {short_paths(message)}", 0.9, size, fig)
        if used + len(lines) > max_lines:
            blocks.append(("note", [f"... {len(checks) - len(blocks)} more in the summary.json (quality.reasons)"]))
            break
        blocks.append((level, lines))
        used += len(lines)
    for level, lines in reversed(blocks):
        fig.text(0.03, y, "\n".join(lines), fontsize=size, family="monospace", va="bottom",
                 color=_LEVEL_COLOURS.get(level, "black"))
        y += len(lines) * line + 0.008
    fig.text(0.03, y, "the calibration's checks (also in the verdict)", fontsize=9.5, weight="bold", va="bottom")
    return y + 0.025


def _draw_fitted(fig: Figure, rep: dict, *, top: float, bottom: float) -> None:
    """Two text columns: scales, ellipsoid and joint centres; the static pose."""
    left = ["segment scale factors"] + [f"  {k:<10}{v:6.3f}" for k, v in (rep.get("scale_factors") or {}).items()]
    ell = rep.get("ellipsoid") or {}
    if ell:
        c = [round(float(x)) for x in ell.get("centre_mm", [])]
        r = [round(float(x)) for x in ell.get("radii_mm", [])]
        left += ["", "thorax ellipsoid (mm, thorax frame)", f"  centre {c}", f"  radii  {r}"]
    poses = rep.get("ellipsoid_poses_mm") or {}
    if len(poses) > 1:
        left += ["  through the contact points of:"] + [f"    {Path(str(k)).name[:26]} ({v:.1f} mm off)"
                                                       for k, v in poses.items()]
    centres = {k: v for k, v in (rep.get("joint_centres_mm") or {}).items() if k != "definition"}
    if centres:
        left += ["", "joint centres, static pose (mm)"] + [f"  {k:<8}{[round(float(x)) for x in v]}"
                                                           for k, v in centres.items()]
    gh = (rep.get("functional") or {}).get("gh")
    if gh:
        left += ["", "glenohumeral centre"]
        left += (_wrap(f"  SCoRE on {Path(str(gh.get('trial'))).name}, {gh.get('shift_from_marker_fit_mm', float('nan')):.1f}"
                       " mm from the marker fit's", 0.24, 8.5, fig) if gh.get("used")
                 else _wrap(f"  functional trial not used: {gh.get('reason')}", 0.24, 8.5, fig))
    at = rep.get("static_pose_at_limit_deg") or {}
    right = ["static pose (deg)"] + [f"  {k:<24}{v:6.0f}" + ("  AT LIMIT" if k in at else "")
                                     for k, v in (rep.get("static_pose_deg") or {}).items()]
    size = _fit_size(fig, max(len(left), len(right)), top - bottom)
    fig.text(0.03, top, "\n".join(left), fontsize=size, family="monospace", va="top")
    fig.text(0.27, top, "\n".join(right), fontsize=size, family="monospace", va="top")


def _fit_size(fig: Figure, n_lines: int, height: float, largest: float = 9.0) -> float:
    """The largest font size (pt, at most ``largest``) at which n_lines fit in ``height``."""
    return float(min(largest, height * fig.get_figheight() * 72 / (1.2 * max(n_lines, 1))))


def _draw_markers(fig: Figure, rep: dict, *, top: float, bottom: float) -> None:
    """Per marker: its distance from its landmark (declared ones) and its offset from its generic
    place, in mm, with its fit residual written beside; the worst landmark distance marked."""
    markers = rep.get("markers") or {}
    land = rep.get("landmark_offsets_mm") or {}
    names = list(markers)
    if not names:
        return
    ax = fig.add_axes((0.64, bottom, 0.33, top - bottom))
    y = np.arange(len(names))[::-1]
    generic = np.array([markers[n].get("generic_offset_mm") or np.nan for n in names], dtype=float)
    landmark = np.array([land.get(n, np.nan) for n in names], dtype=float)
    ax.barh(y + 0.2, generic, 0.38, color="0.75", label="offset from its generic place")
    colours = ["tab:red" if d > LANDMARK_LIMIT_MM else "tab:blue" for d in np.nan_to_num(landmark)]
    ax.barh(y - 0.2, landmark, 0.38, color=colours, label="distance from its landmark")
    ax.axvline(LANDMARK_LIMIT_MM, color="tab:red", ls="--", lw=0.8)
    ax.text(LANDMARK_LIMIT_MM, len(names) - 0.4, f" {LANDMARK_LIMIT_MM:.0f} mm", color="tab:red", fontsize=7, va="bottom")
    top_x = np.nanmax(np.concatenate([generic, landmark, [LANDMARK_LIMIT_MM]])) * 1.25
    for yi, n in zip(y, names):
        m = markers[n]
        note = f"{m.get('residual_mm') or 0:.2f}" if m.get("registered") else "not in the frames"
        ax.text(top_x, yi, note, fontsize=7, va="center", ha="right", family="monospace")
    ax.text(top_x, len(names) - 0.4, "residual", fontsize=7, va="bottom", ha="right", family="monospace")
    worst = int(np.nanargmax(landmark)) if np.isfinite(landmark).any() else -1
    ax.set_yticks(y, [f"{n} (worst)" if i == worst else n for i, n in enumerate(names)], fontsize=7)
    ax.set_xlim(0, top_x)
    ax.set_ylim(-0.7, len(names) + 0.3)
    ax.set_xlabel("mm", fontsize=8)
    ax.tick_params(axis="x", labelsize=7)
    ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2, frameon=False)
    fig.text(0.64, top + 0.035, "where the markers sit on the subject", fontsize=9.5, weight="bold")
    ax.grid(alpha=0.3, axis="x")
