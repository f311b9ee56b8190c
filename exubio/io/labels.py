"""Marker labels as the trial readers (exubio.io.c3d, exubio.io.trc) read them: one column per
label. A label that two or more columns carry keeps one column, the first that has samples (so a
file holding two marker sets under the same labels, as BTS writes them, keeps one set, not a mix
chosen by sample counts), and the reader says so in an input finding naming every column, the one
kept, and how far the others lie from it (different markers under one label, or a copy)."""
from __future__ import annotations

import numpy as np

__all__ = ["keep_one_per_label"]

DIFFERENT_MARKERS_M = 5e-3
"""Columns of one label further apart than this (m) where both have samples are different markers."""


def keep_one_per_label(labels: list[str | None], positions: np.ndarray, *, raw: list[str], field: str, name: str,
                       findings: list[str], column: str = "column") -> list[int]:
    """The columns to keep, in file order, of ``labels`` (None: a column not to read) over
    ``positions`` (n_frames, n_columns, 3): one per label, the first with samples. ``raw``: the labels as written (said in
    the findings), ``field``: where the file holds them ("POINT:LABELS", "line 4"), ``name``: the
    file's name, ``column``: what the file calls a column ("point"); a finding per repeated label is
    appended to ``findings``."""
    n_samples = np.isfinite(positions).all(axis=2).sum(axis=0)
    by_label: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        if label is not None:
            by_label.setdefault(label, []).append(i)
    keep = []
    for label, columns in by_label.items():
        best = next((c for c in columns if n_samples[c]), columns[0])
        keep.append(best)
        if len(columns) > 1:
            told = ", ".join(f"{column} {c + 1} ({raw[c]!r}, {int(n_samples[c])} samples)" for c in columns)
            why = "the first" if best == columns[0] else "the first with samples"
            findings.append(f"{name}: {field}: {len(columns)} {column}s are labelled '{label}': {told}; kept {column} "
                            f"{best + 1}, {why}{_difference(positions, best, columns)}")
    return sorted(keep)


def _difference(positions: np.ndarray, best: int, columns: list[int]) -> str:
    """How far the dropped columns of a label lie from the kept one, where both have samples."""
    gaps = [np.linalg.norm(positions[:, c] - positions[:, best], axis=1) for c in columns if c != best]
    gaps = np.concatenate([g[np.isfinite(g)] for g in gaps])
    if not gaps.size:
        return " (no frame where both have a sample)"
    if gaps.max() == 0:
        return " (the same positions wherever both have a sample)"
    far = "; different markers under one label" if gaps.max() > DIFFERENT_MARKERS_M else ""
    return f" (the others lie up to {gaps.max() * 1e3:.1f} mm from it where both have a sample{far})"
