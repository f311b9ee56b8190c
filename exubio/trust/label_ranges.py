"""Labels exchanged in part of a trial only: auto-labelling that jumps between two markers for some
frames (a common Vicon and Qualisys failure), found per frame range and, on request, repaired.

For two markers i, j of the protocol, frame by frame: the distances of each to its partners (the
markers of its own segment when it has two or more there, else also those of the neighbouring
segments) against their medians over the trial, as labelled and with i and j exchanged. Frames
where the exchange brings the distances back by more than ``GAIN_MM`` (RMS over the partners,
summed over both markers), in runs of at least ``MIN_RUN_FRAMES``, are a partial swap. Medians over
the trial are the reference because the swap holds in part of it only (a swap over the whole trial
is the whole-trial check's: exubio.trust.labels). Pure numpy on raw positions (any frame: distances only).
"""
from __future__ import annotations

import itertools
import logging
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from exubio.protocol.labels import resolve_labels
from exubio.types import Model, Protocol, Trajectories

__all__ = ["GAIN_MM", "MIN_RUN_FRAMES", "PartialSwap", "find_partial_swaps", "repair_partial_swaps"]

log = logging.getLogger(__name__)

GAIN_MM = 30.0
"""Measured on the 10 real trials of ../shared/data as recorded (``python studies/partial_swaps.py``):
no exchange of any two markers reaches 10 mm over 5 frames in a row; two markers exchanged in a
fifth of a trial give 44-76 mm (epicondyles), 53-75 mm (ARM/DELT), 96-119 mm (SCAP_IA/SCAP_AA) and
33-43 mm (ULNA/RADIUS, in the frames where the forearm's posture tells them apart). Not found:
markers whose distances to their partners barely differ (MET2/MET5 on the hand; the epicondyles of
F0, whose humerus markers are few): the whole-trial check and the residuals remain for them."""

MAX_SHARE = 0.5
"""Runs covering more than this share of the trial are not a partial swap: the trial's medians then
follow the swapped labels (the whole-trial label check judges it)."""

MIN_RUN_FRAMES = 5
"""Shorter runs are a marker's noise or a reconstruction ghost, not a labelling jump."""


@dataclass(frozen=True)
class PartialSwap:
    """Markers ``a`` and ``b`` exchanged in frames ``ranges`` ([start, stop) each); ``gain_mm``: the
    median gain over those frames."""

    a: str
    b: str
    ranges: tuple[tuple[int, int], ...]
    gain_mm: float

    @property
    def n_frames(self) -> int:
        return sum(b - a for a, b in self.ranges)

    def describe(self) -> str:
        where = ", ".join(f"{a}-{b - 1}" for a, b in self.ranges)
        return (f"{self.a} and {self.b} look exchanged in frames {where} ({self.n_frames} frames): there the exchange "
                f"brings their distances to the markers rigid with them back by {self.gain_mm:.0f} mm")


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    v = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(v))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


BLOCK_FRAMES = 8192
"""Frames whose pair distances are held at once (a long trial is scanned a block at a time)."""


def find_partial_swaps(traj: Trajectories, protocol: Protocol, model: Model, /, *,
                       gain_mm: float = GAIN_MM) -> tuple[PartialSwap, ...]:
    """The partial swaps of a trial (module docstring), each pair of markers at most once, the
    largest first; a marker takes part in one at most. Memory: a block of frames at a time plus one
    bit per frame and pair."""
    from exubio.trust.labels import pair_distances

    match = resolve_labels(protocol, traj.labels, source=traj.source)
    markers = [m for m in protocol.markers if match.columns.get(m.name) is not None and m.segment != "thorax"]
    if len(markers) < 3:
        return ()
    cols = [match.columns[m.name] for m in markers]
    n, k = traj.positions_m.shape[0], len(markers)
    ref = pair_distances(traj.positions_m[:, cols], [m.name for m in markers]).median_m
    parent = {s.name: s.parent for s in model.segments}
    seg = [m.segment for m in markers]
    same = np.array([[seg[a] == seg[b] and a != b for b in range(k)] for a in range(k)])
    near = np.array([[(seg[a] == seg[b] or parent.get(seg[a]) == seg[b] or parent.get(seg[b]) == seg[a]) and a != b
                      for b in range(k)] for a in range(k)])
    pairs = []
    for i, j in itertools.combinations(range(k), 2):
        parts = []
        rigid_only = False
        for me, other in ((i, j), (j, i)):
            own = same[me] & (np.arange(k) != other)
            if own.sum() >= 2:
                p = same[me]
            elif own.sum() == 1 and same[other][me]:  # both on one segment with one more marker: that
                p, rigid_only = same[me], True        # marker alone (neighbours' distances move with the posture)
            else:
                p = near[me]
            parts.append(p & (np.arange(k) != i) & (np.arange(k) != j))
        need = 1 if rigid_only else 2
        if parts[0].sum() >= need and parts[1].sum() >= need:
            pairs.append((i, j, parts[0], parts[1]))
    if not pairs:
        return ()
    swapped = np.zeros((n, len(pairs)), dtype=bool)
    gains = np.zeros((n, len(pairs)), dtype=np.float32)
    rows, part_cols, n_cols, own = _error_terms(pairs)
    for a in range(0, n, BLOCK_FRAMES):
        P = np.ascontiguousarray(traj.positions_m[a:a + BLOCK_FRAMES][:, cols])
        with np.errstate(invalid="ignore"):
            e = _partner_rms(P, ref, rows, part_cols, n_cols, own).reshape(P.shape[0], len(pairs), 4)
            e0i, e0j, e1i, e1j = e[..., 0], e[..., 1], e[..., 2], e[..., 3]
            g = (e0i + e0j - e1i - e1j) * 1000.0
            # an exchange puts BOTH labels back among their partners: each side must gain (one side
            # alone gaining is a marker far from partners whose distances move with the posture)
            both = (e0i > e1i) & (e0j > e1j)
            gains[a:a + BLOCK_FRAMES] = np.nan_to_num(g, nan=0.0)
            swapped[a:a + BLOCK_FRAMES] = (np.nan_to_num(g, nan=-np.inf) > gain_mm) & both
    found = []
    for c, (i, j, _, _) in enumerate(pairs):
        runs = [r for r in _runs(swapped[:, c]) if r[1] - r[0] >= MIN_RUN_FRAMES]
        total = sum(b - a for a, b in runs)
        if runs and total <= MAX_SHARE * n:
            sel = np.concatenate([np.arange(a, b) for a, b in runs])
            found.append(PartialSwap(markers[i].name, markers[j].name, tuple(runs), float(np.median(gains[sel, c]))))
    found.sort(key=lambda s: -s.gain_mm * s.n_frames)
    out, taken = [], set()
    for s in found:
        if s.a in taken or s.b in taken:
            continue
        out.append(s)
        taken |= {s.a, s.b}
    return tuple(out)


def _error_terms(pairs: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The four RMS errors of every pair (i, j, partners of i, partners of j), in this order: e0i (i to
    its partners, as labelled), e0j, e1i (j to i's partners: exchanged), e1j; as terms (4 per pair):
    the marker measured (T,), its partners (T, most partners; -1 after a term's own), their number
    (T,), the marker whose reference distances they are compared with (T,)."""
    terms = [(row, np.flatnonzero(part), ref_row) for i, j, pi, pj in pairs
             for row, part, ref_row in ((i, pi, i), (j, pj, j), (j, pi, i), (i, pj, j))]
    n_cols = np.array([len(c) for _, c, _ in terms])
    cols = np.full((len(terms), max(int(n_cols.max()), 1)), -1)
    for t, (_, c, _) in enumerate(terms):
        cols[t, :len(c)] = c
    return np.array([r for r, _, _ in terms]), cols, n_cols, np.array([o for _, _, o in terms])


def _partner_rms(P: np.ndarray, ref: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_cols: np.ndarray,
                 own: np.ndarray) -> np.ndarray:
    """(frames, T): per frame of P (frames, k, 3) and term, the RMS over the term's partners of its
    marker's distance to them minus the reference distances ``ref`` (k, k) of marker ``own``, missing
    values left out: the compiled kernel exubio.model.batch_kernels.partner_rms (bit for bit
    :func:`_partner_rms_numpy`, about 10 times faster)."""
    from exubio.model import batch_kernels as kernels  # numba: imported where used

    out = np.empty((P.shape[0], len(rows)))
    kernels.partner_rms(P, np.ascontiguousarray(ref, dtype=float), rows, cols, n_cols, own, out)
    return out


def _partner_rms_numpy(P: np.ndarray, ref: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_cols: np.ndarray,
                       own: np.ndarray) -> np.ndarray:
    """The numpy reference of :func:`_partner_rms`: every distance of the frames, then each term's
    RMS error over its partners (np.nanmean), term by term."""
    out = np.empty((P.shape[0], len(rows)))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames where a marker is missing: NaN
        D = np.linalg.norm(P[:, :, None] - P[:, None], axis=-1)
        for t, (r, o, p) in enumerate(zip(rows, own, n_cols)):
            part = cols[t, :p]
            out[:, t] = np.sqrt(np.nanmean((D[:, r, part] - ref[o, part]) ** 2, axis=1))
    return out


def repair_partial_swaps(traj: Trajectories, protocol: Protocol, swaps: Sequence[PartialSwap], /) -> Trajectories:
    """The trial with each partial swap's two markers exchanged back in its frames (a copy)."""
    import dataclasses

    if not swaps:
        return traj
    match = resolve_labels(protocol, traj.labels, source=traj.source)
    pos = traj.positions_m.copy()
    for s in swaps:
        ca, cb = match.columns[s.a], match.columns[s.b]
        for a, b in s.ranges:
            pos[a:b, [ca, cb]] = pos[a:b, [cb, ca]]
        log.info("%s: repaired: %s", traj.source or "trial", s.describe())
    return dataclasses.replace(traj, positions_m=pos)
