"""Fill a trial's marker gaps from its reconstruction (what a capture program's model-based fill does by hand).

A protocol marker missing in frames [a, b) is filled, frame by frame, with its model point (fixed in
its segment, placed by the reconstruction's q) plus the marker's mean offset from that point over
the measured frames within ``FILL_WINDOW_S`` before and after the gap, the offset taken in the
segment's frame (so it turns with the segment):

    filled(t) = P_i(q(t)) + R_s(q(t)) * mean_w[ R_s(q(w))^T (m_i(w) - P_i(q(w))) ]

in the thorax frame the model lives in, then back in the trial's lab frame (the thorax frame of that
frame, built from the thorax landmarks as exubio.prep.targets builds it; a left arm mirrored back)
and in the file's units at the writer. The offset carries what the model point does not: where the
marker sits on the skin relative to its calibrated point, and the slowly varying part of the
soft-tissue artefact around the gap.

Left empty, with the reason in the fill table: a gap longer than ``MAX_FILL_S`` (the measured fill
error grows with the gap: studies/gap_table.py), a gap with no measured sample of the marker within
the window, frames whose pose or thorax frame is unknown, markers the protocol does not track (other
labels of the file, the thorax landmarks, which define the frame the model is placed in).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import Kinematics, PointSet
from exubio.prep.filtering import fill_short_gaps, valid_runs
from exubio.prep.thorax import MAX_THORAX_GAP_S, isb_landmarks, thorax_frame
from exubio.protocol.labels import resolve_labels
from exubio.types import Model, Protocol, Trajectories

__all__ = ["FILL_WINDOW_S", "MAX_FILL_S", "FilledGap", "GapFill", "fill_gaps", "fill_table_text"]

FILL_WINDOW_S = 0.1
"""The marker's offset from its model point is averaged over its measured samples this long before and
after the gap (10 samples a side at 100 Hz, enough to average out measurement noise). The offset
changes with the posture (the soft-tissue artefact, the model's misfit), so the nearer the samples to
the gap the better: measured on 24 gaps of 0.25 s and 1 s cut from two C3D trials (martin_dynamique,
kinova_martin_tete; EPI_lat, SCAP_IA, MET2), the median fill error was 3.7 and 4.8 mm with 0.1 s,
5.5 and 5.2 mm with 0.5 s; studies/gap_table.py gives both windows on every trial."""

MAX_FILL_S = 1.0
"""Gaps longer than this are left empty. Measured (studies/gap_table.py: 91 markers cut from the eight
real movement trials of ../shared/data, LS): the fill error's median grows from 2.3 mm (0.1 s gaps)
to 5.0 mm (1 s) and 6.0 mm (2 s), its 95th percentile from 26 mm to 31 mm and 36 mm, its maximum to
109 mm at 2 s. Up to 1 s the 95th percentile stays at about the upper end of a skin marker's own
artefact (5-30 mm, Cappozzo et al. 1996), so a filled sample is no worse than a measured one is
likely to be; beyond, it is handed on as data no longer."""


@dataclass(frozen=True)
class FilledGap:
    """One gap of one marker: frames [first, last] (0-based rows of the trial), filled or left empty
    (reason), and the offset used (mm, in the segment's frame; NaN where not filled)."""

    marker: str
    first: int
    last: int
    filled: bool
    reason: str
    offset_mm: tuple[float, float, float] = (np.nan, np.nan, np.nan)


@dataclass(frozen=True)
class GapFill:
    """positions_m: (n, k, 3) the trial's markers (its labels, lab frame, m) with the filled samples
    set; filled: (n, k) bool, the samples set here; gaps: every gap of every marker."""

    labels: tuple[str, ...]
    positions_m: np.ndarray
    filled: np.ndarray
    gaps: tuple[FilledGap, ...]

    @property
    def n_filled(self) -> int:
        return int(self.filled.sum())


def _lab_frames(trajectories: Trajectories, protocol: Protocol, match) -> tuple[np.ndarray, np.ndarray]:
    """Per frame the thorax frame (R (n, 3, 3), origin (n, 3)) in the lab, as exubio.prep.targets builds it
    (NaN where a landmark gap is longer than MAX_THORAX_GAP_S); the identity where the protocol's
    frame is the lab's."""
    n = trajectories.n_frames
    if protocol.thorax_frame.is_identity:
        return np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), np.zeros((n, 3))
    max_gap = int(round(MAX_THORAX_GAP_S * trajectories.rate_hz))
    landmarks = {}
    for key, col in match.thorax_columns.items():
        lm = trajectories.positions_m[:, col].copy()
        lm[~np.isfinite(lm).all(axis=1)] = np.nan
        landmarks[key] = fill_short_gaps(lm, max_gap_frames=max_gap)
    return thorax_frame(*isb_landmarks(landmarks))


def fill_gaps(trajectories: Trajectories, model: Model, protocol: Protocol, q_rad: np.ndarray, /, *,
              max_gap_s: float = MAX_FILL_S, window_s: float = FILL_WINDOW_S) -> GapFill:
    """Fill the gaps of ``trajectories`` (as read from the file) from the reconstruction's q (n, m) made
    with ``model`` and ``protocol`` on the same frames (module docstring). The input is not changed."""
    n = trajectories.n_frames
    q = np.asarray(q_rad, dtype=float)
    if q.shape[0] != n:
        raise InputError(f"{trajectories.source or 'trial'}: the reconstruction has {q.shape[0]} frames, the trial "
                         f"{n}; fill a trial from its own reconstruction")
    match = resolve_labels(protocol, trajectories.labels, source=trajectories.source)
    rot, origin = _lab_frames(trajectories, protocol, match)
    kin = Kinematics(model)
    points = PointSet(np.array([model.segment_index(m.segment) for m in protocol.markers], dtype=int),
                      np.array([np.asarray(m.local_position_m, dtype=float) for m in protocol.markers]).reshape(-1, 3),
                      protocol.marker_names)
    ok_q = np.isfinite(q).all(axis=1) & np.isfinite(rot).all(axis=(1, 2)) & np.isfinite(origin).all(axis=1)
    qz = np.where(ok_q[:, None], q, 0.0)
    R_seg, _ = kin.poses(qz)
    P = kin.points(qz, points)  # (n, k_protocol, 3) thorax frame
    mirror = np.array([1.0, 1.0, -1.0]) if protocol.side == "left" else np.ones(3)
    pos = np.array(trajectories.positions_m, dtype=float)
    present = np.isfinite(pos).all(axis=2)
    filled = np.zeros(present.shape, dtype=bool)
    tracked = {col: j for j, col in enumerate(match.columns[nm] for nm in protocol.marker_names) if col is not None}
    rate = trajectories.rate_hz
    w = max(int(round(window_s * rate)), 1)
    max_frames = max_gap_s * rate
    gaps: list[FilledGap] = []
    for col, label in enumerate(trajectories.labels):
        miss = ~present[:, col]
        if not miss.any() or miss.all():
            if miss.all():
                gaps.append(FilledGap(label, 0, n - 1, False, "missing in every frame: nothing to place it by"))
            continue
        for a, b in valid_runs(miss):
            if col not in tracked:
                why = ("a thorax landmark: it defines the frame the model is placed in" if col in
                       match.thorax_columns.values() else "not a marker of the protocol: no model point")
                gaps.append(FilledGap(label, a, b - 1, False, why))
                continue
            if b - a > max_frames:
                gaps.append(FilledGap(label, a, b - 1, False, f"longer than {max_gap_s:g} s ({(b - a) / rate:.2f} s)"))
                continue
            j = tracked[col]
            s = points.segment_index[j]
            win = np.r_[max(a - w, 0):a, b:min(b + w, n)]
            win = win[present[win, col] & ok_q[win]]
            if not win.size:
                gaps.append(FilledGap(label, a, b - 1, False, f"no measured sample within {window_s:g} s of the gap"))
                continue
            if not ok_q[a:b].all():
                gaps.append(FilledGap(label, a, b - 1, False, "pose or thorax frame unknown in the gap"))
                continue
            m_th = np.einsum("nji,nj->ni", rot[win], pos[win, col] - origin[win]) * mirror  # measured, thorax frame
            local = np.einsum("nji,nj->ni", R_seg[win, s], m_th - P[win, j]).mean(axis=0)
            fill_th = (P[a:b, j] + np.einsum("nij,j->ni", R_seg[a:b, s], local)) * mirror
            pos[a:b, col] = np.einsum("nij,nj->ni", rot[a:b], fill_th) + origin[a:b]
            filled[a:b, col] = True
            gaps.append(FilledGap(label, a, b - 1, True, "", tuple(float(v) for v in local * 1e3)))
    return GapFill(tuple(trajectories.labels), pos, filled, tuple(gaps))


FILL_TABLE_COLUMNS = ("marker", "first_frame", "last_frame", "first_time_s", "n_frames", "filled", "reason",
                      "offset_x_mm", "offset_y_mm", "offset_z_mm")


def fill_table_text(fill: GapFill, time_s: np.ndarray, /, *, first_frame: int = 1) -> str:
    """The fill table (CSV text): one row per gap, frames numbered as the file numbers them
    (``first_frame``: the number of its first row), filled 1/0 and why not."""
    lines = [",".join(FILL_TABLE_COLUMNS)]
    for g in sorted(fill.gaps, key=lambda g: (fill.labels.index(g.marker), g.first)):
        off = ",".join("" if not np.isfinite(v) else f"{v:.3f}" for v in g.offset_mm)
        reason = g.reason.replace('"', "'")
        lines.append(f"{g.marker},{g.first + first_frame},{g.last + first_frame},{time_s[g.first]:.6f},"
                     f"{g.last - g.first + 1},{int(g.filled)},\"{reason}\",{off}")
    return "\n".join(lines) + "\n"
