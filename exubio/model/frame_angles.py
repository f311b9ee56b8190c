"""The ISB angles of one frame at a time (the live loop's): ``FrameAngles``, the arithmetic of
exubio.model.angles.isb_table with everything that does not depend on the frame (segment indices,
the anatomical frames stacked, the joints' frame pairs, the parsed sequences) done once, so a frame
costs the operations on its numbers only (about a third of isb_table's time for one frame; the same
operations on the same numbers: bitwise the same angles, tests/test_frame_angles.py)."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from exubio.model.angles import _JOINTS, _SEQUENCE_GROUPS, _basic_rotation, _parse_sequence
from exubio.types import Model

__all__ = ["FrameAngles"]


class FrameAngles:
    """``angles(R)``: the ISB angles (15,) rad of one frame from its segment rotations R (n_seg, 3, 3),
    in the columns of isb_table (not unwrapped: one frame); ``frames``: anatomical_frames(model)."""

    def __init__(self, model: Model, frames: Mapping[str, np.ndarray], /):
        names = list(frames)
        self.segments = np.array([model.segment_index(n) for n in names], dtype=int)
        self.A = np.stack([np.asarray(frames[n], dtype=float) for n in names])
        where = {n: i for i, n in enumerate(names)}
        self.prox = np.array([where[p] for p, _ in _JOINTS.values()], dtype=int)
        self.dist = np.array([where[d] for _, d in _JOINTS.values()], dtype=int)
        self.groups = []
        for (sequence, negative), joints in _SEQUENCE_GROUPS.items():
            i, j, k = _parse_sequence(sequence)
            self.groups.append((np.array(joints, dtype=int), i, j, k, negative))

    def __call__(self, R: np.ndarray, /) -> np.ndarray:
        Rg = R[self.segments] @ self.A  # every anatomical frame (thorax frame)
        Rrel = np.swapaxes(Rg[self.prox], -1, -2) @ Rg[self.dist]  # (joints, 3, 3)
        out = np.empty((len(self.prox), 3))  # rows in the joints' order: isb_table's columns
        for joints, i, j, k, negative in self.groups:
            _euler_rows(Rrel[joints], i, j, k, negative, out, joints)
        return out.reshape(-1)


def _euler_rows(R: np.ndarray, i: int, j: int, k: int, negative_middle: bool, out: np.ndarray, rows: np.ndarray,
                gimbal_tol: float = 1e-9) -> None:
    """exubio.model.angles.euler_angles of R (n, 3, 3) for the parsed sequence (i, j, k), written into
    out[rows] (the same operations in the same order)."""
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    if i != k:  # Tait-Bryan
        b = np.arctan2(s * R[..., i, k], np.hypot(R[..., i, i], R[..., i, j]))
        a = np.arctan2(-s * R[..., j, k], R[..., k, k])
        locked = np.cos(b) < gimbal_tol
    else:  # proper Euler
        m = 3 - i - j
        sb = np.hypot(R[..., i, j], R[..., i, m])
        b = np.arctan2(sb, R[..., i, i])
        a = np.arctan2(R[..., j, i], -s * R[..., m, i])
        if negative_middle:
            b, a = -b, a + np.pi
        locked = sb < gimbal_tol
    a = np.where(locked, 0.0, a)
    M = np.swapaxes(_basic_rotation(i, a) @ _basic_rotation(j, b), -1, -2) @ R
    u, v = (k + 1) % 3, (k + 2) % 3
    c = np.arctan2(M[..., v, u] - M[..., u, v], M[..., u, u] + M[..., v, v])
    two_pi = 2.0 * np.pi
    out[rows, 0] = np.pi - np.mod(np.pi - a, two_pi)  # angles._wrap
    out[rows, 1] = np.pi - np.mod(np.pi - b, two_pi)
    out[rows, 2] = np.pi - np.mod(np.pi - c, two_pi)
