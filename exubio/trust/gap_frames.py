"""Which frames the per-frame trust measures (noise gains, uncertainty, status) are computed on.

They are computed every ``every``-th frame and copied to the frames between (a posture changes
little in 50 ms). A marker gap changes them at once, not gradually: a frame copied across a gap's
edge would carry the values of the other side (a one-frame gap between two computed frames would
not show at all). So the first and last frame of every run of frames with the same markers present
are computed too, and each frame takes the nearest computed frame *of its own run*.
"""
from __future__ import annotations

import numpy as np

__all__ = ["computed_frames"]


def computed_frames(present: np.ndarray, every: int, /) -> tuple[np.ndarray, np.ndarray]:
    """present: (n, k) bool (the markers present per frame). Returns (sel, idx): the frames to
    compute, increasing, and for every frame the index into ``sel`` of the frame it takes its values
    from (itself where computed; else the nearest computed frame with the same markers present)."""
    pres = np.asarray(present, dtype=bool)
    n = pres.shape[0]
    step = max(int(every), 1)
    if n == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    change = np.flatnonzero((pres[1:] != pres[:-1]).any(axis=1)) + 1  # first frame of each new run
    run = np.zeros(n, dtype=int)
    run[change] = 1
    run = np.cumsum(run)
    grid = np.arange(0, n, step)
    sel = np.unique(np.concatenate([grid, change, change - 1]))
    frames = np.arange(n)
    # a trial without gaps: the grid frame nearest (as before gaps were considered), where it lies in the frame's run
    on_grid = grid[np.clip(np.round(frames / step).astype(int), 0, len(grid) - 1)]
    # else the nearest computed frame of its run: a run's first and last frames are computed (the trial's
    # first frame is on the grid; a run ending before the last frame ends at a change), so one side is in it
    right = np.clip(np.searchsorted(sel, frames), 0, len(sel) - 1)
    left = np.clip(right - 1, 0, len(sel) - 1)
    d_left = np.where(run[sel[left]] == run, frames - sel[left], n + 1)
    d_right = np.where(run[sel[right]] == run, sel[right] - frames, n + 1)
    nearest = np.where(d_left <= d_right, sel[left], sel[right])
    pick = np.where(np.isin(frames, sel), frames, np.where(run[on_grid] == run, on_grid, nearest))
    idx = np.searchsorted(sel, pick)
    return sel, idx


def nearest_sample(values: np.ndarray, /) -> np.ndarray:
    """(n, k) with each NaN replaced by the column's nearest finite value in time (the earlier one on
    a tie); a column without any finite value stays NaN. Used for a marker's residual through its
    gap: the model's misfit its segment showed at the gap's edges does not vanish when the marker is
    hidden, so a gap frame's uncertainty keeps it (exubio.trust.observability.GAP_FLOOR)."""
    v = np.asarray(values, dtype=float)
    out = v.copy()
    n = v.shape[0]
    frames = np.arange(n)
    for j in range(v.shape[1]):
        ok = np.flatnonzero(np.isfinite(v[:, j]))
        if ok.size == 0 or ok.size == n:
            continue
        right = np.clip(np.searchsorted(ok, frames), 0, ok.size - 1)
        left = np.clip(right - 1, 0, ok.size - 1)
        pick = np.where(np.abs(ok[left] - frames) <= np.abs(ok[right] - frames), ok[left], ok[right])
        out[:, j] = v[pick, j]
    return out
