"""Second moments tabulated against a driver, the humerus's rotation angle from its start (theta,
rad): the frames binned by theta (``BIN_EDGES_DEG``; a bin with fewer than ``MIN_BIN_FRAMES`` frames
merged into its neighbour), each bin's second moment at the bin's mean theta (its node), the table
interpolated linearly between nodes and held constant beyond them (``interpolate``: a convex
combination of two positive semi-definite matrices is one).

The unseen trunk's motion of the uncertainty's amplitude model (exubio.trust.sta_amplitude) is
stored in this form (one node, a constant, as shipped: exubio.truth.trunk_amplitude), and
studies/trunk_motion.py compares a table of several nodes with it on held-out trials.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["BIN_EDGES_DEG", "MIN_BIN_FRAMES", "driver_bins", "binned_second_moment", "nearest_psd", "interpolate"]

BIN_EDGES_DEG = (0.0, 5.0, 10.0, 20.0, 30.0, 45.0, 60.0, 80.0, 100.0, 120.0, 150.0, 180.0)
"""The driver's bins (deg of the humerus's rotation from its start)."""
MIN_BIN_FRAMES = 100
"""A bin with fewer frames than this is merged into its neighbour (a 6 x 6 second moment needs many)."""


def driver_bins(theta: np.ndarray, /, *, edges_deg: Sequence[float] = BIN_EDGES_DEG,
                min_frames: int = MIN_BIN_FRAMES) -> tuple[np.ndarray, np.ndarray]:
    """(the bin of every frame (n,), -1 where theta is NaN; the bins' nodes (nb,): their mean theta,
    rad) with the bins of ``edges_deg``, a bin of fewer than ``min_frames`` frames merged into the one
    above it (the highest into the one below); ValueError when the frames do not fill one bin."""
    th = np.asarray(theta, dtype=float)
    ok = np.isfinite(th)
    edges = np.radians(np.asarray(edges_deg, dtype=float))
    raw = np.clip(np.searchsorted(edges, np.where(ok, th, 0.0), side="right") - 1, 0, edges.size - 2)
    count = lambda g: int(np.sum(ok & np.isin(raw, g)))
    merged: list[list[int]] = []
    for i in range(edges.size - 1):
        if not count([i]):
            continue
        if merged and count(merged[-1]) < min_frames:
            merged[-1] = merged[-1] + [i]
        else:
            merged.append([i])
    if len(merged) > 1 and count(merged[-1]) < min_frames:
        merged[-2] = merged[-2] + merged.pop()
    if not merged or count(merged[0]) < min_frames:
        raise ValueError(f"fewer than {min_frames} frames with a driver: no table")
    out = np.full(th.shape, -1)
    for j, g in enumerate(merged):
        out[ok & np.isin(raw, g)] = j
    return out, np.array([th[out == j].mean() for j in range(len(merged))])


def binned_second_moment(x: np.ndarray, y: np.ndarray, bins: np.ndarray, nb: int, /) -> np.ndarray:
    """(nb, p, q): per bin the mean of x y^T over its frames where both are finite (x (n, p), y (n, q),
    ``bins`` (n,) from ``driver_bins``); zero for a bin without such a frame."""
    out = np.zeros((nb, x.shape[1], y.shape[1]))
    ok = np.isfinite(x).all(axis=1) & np.isfinite(y).all(axis=1)
    for j in range(nb):
        sel = ok & (bins == j)
        if sel.any():
            out[j] = x[sel].T @ y[sel] / sel.sum()
    return out


def nearest_psd(C: np.ndarray, /) -> np.ndarray:
    """Each symmetric (..., n, n) with its negative eigenvalues set to zero."""
    C = (C + np.swapaxes(C, -1, -2)) / 2.0
    w, V = np.linalg.eigh(C)
    return (V * np.maximum(w, 0.0)[..., None, :]) @ np.swapaxes(V, -1, -2)


def interpolate(nodes: np.ndarray, table: np.ndarray, theta: np.ndarray, /) -> np.ndarray:
    """table (nb, ...) at ``nodes`` (nb,), increasing, interpolated linearly at theta (b,) (NaN: the
    first node), constant beyond the first and last node: (b, ...)."""
    nodes = np.asarray(nodes, dtype=float)
    table = np.asarray(table, dtype=float)
    t = np.clip(np.nan_to_num(np.asarray(theta, dtype=float), nan=nodes[0]), nodes[0], nodes[-1])
    if nodes.size == 1:
        return np.broadcast_to(table[0], t.shape + table.shape[1:]).copy()
    i = np.clip(np.searchsorted(nodes, t, side="right") - 1, 0, nodes.size - 2)
    w = (t - nodes[i]) / (nodes[i + 1] - nodes[i])
    w = w.reshape(w.shape + (1,) * (table.ndim - 1))
    return (1.0 - w) * table[i] + w * table[i + 1]
