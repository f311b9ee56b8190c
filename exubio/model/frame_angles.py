"""The ISB angles of one frame at a time (the live loop's): ``FrameAngles``, the arithmetic of
exubio.model.angles.isb_table with everything that does not depend on the frame (segment indices,
the anatomical frames stacked, the joints' frame pairs, the parsed sequences) done once. A call
runs the compiled kernel exubio.model.kernels.isb_angles (about 5 us); ``FrameAngles.numpy`` is the
same in numpy, bitwise isb_table's angles (tests/model/test_frame_angles.py holds the three equal)."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from exubio.model.angles import _JOINTS, _SEQUENCE_GROUPS, _parse_sequence, euler_unwrapped
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
        # the Tait-Bryan joints (any sequence) in one pass, indexed row by row; proper Euler ones by group
        tb, self.groups = [], []
        for (sequence, negative), joints in _SEQUENCE_GROUPS.items():
            i, j, k = _parse_sequence(sequence)
            if i != k:
                tb += [(row, i, j, k) for row in joints]
            else:
                self.groups.append((np.array(joints, dtype=int), i, j, k, negative))
        rows, i, j, k = (np.array(x, dtype=int) for x in zip(*tb)) if tb else (np.zeros(0, dtype=int),) * 4
        self.tb = rows
        self.tb_ijk = (i, j, k)
        self.tb_sign = np.where((j - i) % 3 == 1, 1.0, -1.0)
        self.tb_r = np.arange(len(rows))
        self.tb_i_uv = ((i + 1) % 3, (i + 2) % 3)
        self.tb_j_uv = ((j + 1) % 3, (j + 2) % 3)
        self.tb_k_uv = ((k + 1) % 3, (k + 2) % 3)
        # the compiled kernel's tables: each joint's sequence axes and whether its middle angle is negative
        self.seq = np.zeros((len(self.prox), 3), dtype=np.int64)
        self.negative = np.zeros(len(self.prox), dtype=np.bool_)
        for (sequence, negative), joints in _SEQUENCE_GROUPS.items():
            self.seq[joints] = _parse_sequence(sequence)
            self.negative[joints] = negative
        from exubio.model import kernels  # numba: imported where used

        self.kernel = kernels.isb_angles
        self.tables = (self.segments.astype(np.int64), np.ascontiguousarray(self.A), self.prox.astype(np.int64),
                       self.dist.astype(np.int64), self.seq, self.negative)

    def __call__(self, R: np.ndarray, /) -> np.ndarray:
        """The angles (15,) by the compiled kernel (exubio.model.kernels.isb_angles)."""
        out = np.empty((len(self.prox), 3))
        self.kernel(np.ascontiguousarray(R, dtype=float), *self.tables, out)
        return out.reshape(-1)

    def numpy(self, R: np.ndarray, /) -> np.ndarray:
        """The same in numpy (isb_table's operations on one frame, bitwise): the kernel's reference."""
        Rg = R[self.segments] @ self.A  # every anatomical frame (thorax frame)
        Rrel = np.swapaxes(Rg[self.prox], -1, -2) @ Rg[self.dist]  # (joints, 3, 3)
        out = np.empty((len(self.prox), 3))  # rows in the joints' order: isb_table's columns
        if self.tb.size:
            self._tait_bryan(Rrel[self.tb], out)
        for joints, i, j, k, negative in self.groups:
            _euler_rows(Rrel[joints], i, j, k, negative, out, joints)
        two_pi = 2.0 * np.pi
        return (np.pi - np.mod(np.pi - out, two_pi)).reshape(-1)  # angles._wrap

    def _tait_bryan(self, R: np.ndarray, out: np.ndarray) -> None:
        """euler_angles' Tait-Bryan branch for rows of different sequences at once (each row's axes
        by index: the same operations on the same numbers); unwrapped into out[self.tb]."""
        r, (i, j, k), s = self.tb_r, self.tb_ijk, self.tb_sign
        b = np.arctan2(s * R[r, i, k], np.hypot(R[r, i, i], R[r, i, j]))
        a = np.arctan2(-s * R[r, j, k], R[r, k, k])
        a = np.where(np.cos(b) < 1e-9, 0.0, a)  # euler_angles' gimbal_tol
        M = np.swapaxes(_rotations(r, i, self.tb_i_uv, a) @ _rotations(r, j, self.tb_j_uv, b), -1, -2) @ R
        u, v = self.tb_k_uv
        c = np.arctan2(M[r, v, u] - M[r, u, v], M[r, u, u] + M[r, v, v])
        out[self.tb, 0], out[self.tb, 1], out[self.tb, 2] = a, b, c


def _rotations(r: np.ndarray, axis: np.ndarray, uv: tuple[np.ndarray, np.ndarray], angle: np.ndarray) -> np.ndarray:
    """angles._basic_rotation with each row about its own coordinate axis."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (3, 3))
    u, v = uv
    R[r, axis, axis] = 1.0
    R[r, u, u] = c
    R[r, v, v] = c
    R[r, v, u] = s
    R[r, u, v] = -s
    return R


def _euler_rows(R: np.ndarray, i: int, j: int, k: int, negative_middle: bool, out: np.ndarray, rows: np.ndarray,
                gimbal_tol: float = 1e-9) -> None:
    """exubio.model.angles.euler_angles of R (n, 3, 3) for the parsed sequence (i, j, k), written
    unwrapped into out[rows] (the same operations in the same order)."""
    a, b, c = euler_unwrapped(R, i, j, k, negative_middle, gimbal_tol)
    out[rows, 0], out[rows, 1], out[rows, 2] = a, b, c  # wrapped by the caller
