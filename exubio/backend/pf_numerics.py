"""The pure-numpy side of the potential-field backend (the exudyn_* modules of exubio.backend, which
alone import Exudyn): Euler-parameter kinematics of the system coordinates, the Hermite interpolation of
targets between frames and of step states at the frame times, the record of the accepted steps, the
geometry of the range-of-motion limit elements and their switching, and a run's frames read as one
array from a lead-in and a trial's own arrays (``JoinedRows``)."""
from __future__ import annotations

import math

import numpy as np

_LIMIT_WRAP_TOLERANCE_RAD = math.pi / 6  # a limit needs this much room beyond it before its angle wraps


def wrap_pi(x: float) -> float:
    """x in (-pi, pi]."""
    return math.pi - (math.pi - x) % (2.0 * math.pi)


# --------------------------------------------------------------------------------------------
# Euler-parameter helpers (numpy, vectorised over leading axes)
# --------------------------------------------------------------------------------------------
def ep_rotation(ep: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of Euler parameters (..., 4) = [e0, e1, e2, e3] (normalised here)."""
    return ep_rotation_unit(ep / np.linalg.norm(ep, axis=-1, keepdims=True))


# R[r, c] = 1 - 2 (e_i e_j + e_k e_l) on the diagonal, 2 (e_i e_j +- e_k e_l) off it (row-major r, c)
_R_I, _R_J = np.array([2, 1, 1, 1, 1, 2, 1, 2, 1]), np.array([2, 2, 3, 2, 1, 3, 3, 3, 1])
_R_K, _R_L = np.array([3, 0, 0, 0, 3, 0, 0, 0, 2]), np.array([3, 3, 2, 3, 3, 1, 2, 1, 2])
_R_SIGN = np.array([1.0, -1.0, 1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0])
_R_DIAG = np.array([True, False, False, False, True, False, False, False, True])


def ep_rotation_unit(ep: np.ndarray) -> np.ndarray:
    """``ep_rotation`` of Euler parameters already of unit norm, its nine entries in a few array
    operations (a live run decodes one frame at a time, where every numpy call counts); the same
    products and sums as the textbook entries (a product by +-1 is exact: the same bits)."""
    s = ep[..., _R_I] * ep[..., _R_J] + ep[..., _R_K] * ep[..., _R_L] * _R_SIGN
    return np.where(_R_DIAG, 1 - 2 * s, 2 * s).reshape(ep.shape[:-1] + (3, 3))


_G_INDEX = np.array([(1, 0, 3, 2), (2, 3, 0, 1), (3, 2, 1, 0)])
_G_SIGN = np.array([(-2.0, 2.0, -2.0, 2.0), (-2.0, 2.0, 2.0, -2.0), (-2.0, -2.0, 2.0, 2.0)])


def ep_G(ep: np.ndarray) -> np.ndarray:
    """G (..., 3, 4) with omega_global = G ep_t (and alpha_global = G ep_tt, since G_t ep_t = 0):
    2 [[-e1, e0, -e3, e2], [-e2, e3, e0, -e1], [-e3, -e2, e1, e0]] (a product by +-2 is exact)."""
    ep = np.asarray(ep)
    # C order: einsum sums in the order of its operands' layout (the bits of omega depend on it)
    return np.multiply(ep[..., _G_INDEX], _G_SIGN, out=np.empty(ep.shape[:-1] + (3, 4)))


def frame_with_z(axis: np.ndarray) -> np.ndarray:
    """A rotation matrix whose third column is the unit vector ``axis``."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, a)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(a, x), a])


def hermite(p0, v0, p1, v1, s, dt):
    """Cubic Hermite position and velocity at fraction s in [0, 1] of an interval dt."""
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    pos = h00 * p0 + h10 * dt * v0 + h01 * p1 + h11 * dt * v1
    vel = (d00 * p0 + d01 * p1) / dt + d10 * v0 + d11 * v1
    return pos, vel


def quintic(x0, v0, a0, x1, v1, a1, s, h):
    """Quintic Hermite position, velocity and acceleration at fraction s in [0, 1] of an interval h
    from positions, velocities and accelerations at both ends (one polynomial: all three consistent)."""
    s2, s3, s4, s5 = s * s, s**3, s**4, s**5
    h0, h1, h2 = 1 - 10 * s3 + 15 * s4 - 6 * s5, s - 6 * s3 + 8 * s4 - 3 * s5, 0.5 * (s2 - 3 * s3 + 3 * s4 - s5)
    h3, h4, h5 = 0.5 * (s3 - 2 * s4 + s5), -4 * s3 + 7 * s4 - 3 * s5, 10 * s3 - 15 * s4 + 6 * s5
    d0, d1, d2 = -30 * s2 + 60 * s3 - 30 * s4, 1 - 18 * s2 + 32 * s3 - 15 * s4, 0.5 * (2 * s - 9 * s2 + 12 * s3 - 5 * s4)
    d3, d4, d5 = 0.5 * (3 * s2 - 8 * s3 + 5 * s4), -12 * s2 + 28 * s3 - 15 * s4, 30 * s2 - 60 * s3 + 30 * s4
    e0, e1, e2 = -60 * s + 180 * s2 - 120 * s3, -36 * s + 96 * s2 - 60 * s3, 0.5 * (2 - 18 * s + 36 * s2 - 20 * s3)
    e3, e4, e5 = 0.5 * (6 * s - 24 * s2 + 20 * s3), -24 * s + 84 * s2 - 60 * s3, 60 * s - 180 * s2 + 120 * s3
    x = h0 * x0 + h1 * h * v0 + h2 * h * h * a0 + h3 * h * h * a1 + h4 * h * v1 + h5 * x1
    v = (d0 * x0 + d5 * x1) / h + d1 * v0 + d4 * v1 + (d2 * a0 + d3 * a1) * h
    a = (e0 * x0 + e5 * x1) / (h * h) + (e1 * v0 + e4 * v1) / h + e2 * a0 + e3 * a1
    return x, v, a


class StateRecord:
    """The states (q, q̇, q̈ of the system coordinates) of the accepted steps, in preallocated rows
    that grow by doubling: a list of small arrays cost ~1.4 kB per step in object overhead on long
    trials."""

    def __init__(self, width: int, capacity: int):
        self._a = [np.empty((max(capacity, 16), width)) for _ in range(3)]
        self.n = 0

    def append(self, q, qd, qdd) -> None:
        if self.n == self._a[0].shape[0]:
            self._a = [np.concatenate([a, np.empty_like(a)]) for a in self._a]
        for a, v in zip(self._a, (q, qd, qdd)):
            a[self.n] = v
        self.n += 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(a[:self.n] for a in self._a)

    def drop_first(self, k: int) -> None:
        """Forget the first k rows (steps no frame still to come needs)."""
        k = min(max(int(k), 0), self.n)
        if k:
            for a in self._a:
                a[:self.n - k] = a[k:self.n]
            self.n -= k


def frames_from_steps(t_steps: np.ndarray, states: tuple[np.ndarray, np.ndarray, np.ndarray], n: int,
                      frame_dt_s: float, n_ode2: int, first: int = 0):
    """System coordinates, velocities and accelerations at the frame times i * frame_dt_s,
    i = first ... first + n - 1, from the states (q, q̇, q̈ rows) of the accepted steps (times
    t_steps, which must include the last step before frame ``first``): taken where a step ends on a
    frame, quintic Hermite interpolation inside a step otherwise. Frames after the last step are
    NaN. Returns (X, Xt, Xtt, completed frames)."""
    X, Xt, Xtt = (np.full((n, n_ode2), np.nan) for _ in range(3))
    if states[0].shape[0] == 0:
        return X, Xt, Xtt, 0
    S = states
    tf = (first + np.arange(n)) * frame_dt_s
    eps = 1e-6 * frame_dt_s
    completed = int(np.searchsorted(tf, t_steps[-1] + eps, side="right"))
    tf = tf[:completed]
    b = np.minimum(np.searchsorted(t_steps, tf - eps, side="left"), len(t_steps) - 1)
    on = np.abs(t_steps[b] - tf) <= eps
    X[:completed][on], Xt[:completed][on], Xtt[:completed][on] = S[0][b[on]], S[1][b[on]], S[2][b[on]]
    inside = np.flatnonzero(~on)
    if inside.size:
        bb = b[inside]
        aa = bb - 1
        h = (t_steps[bb] - t_steps[aa])[:, None]
        s = (tf[inside][:, None] - t_steps[aa][:, None]) / h
        x, v, a = quintic(S[0][aa], S[1][aa], S[2][aa], S[0][bb], S[1][bb], S[2][bb], s, h)
        X[inside], Xt[inside], Xtt[inside] = x, v, a
    return X, Xt, Xtt, completed


# --------------------------------------------------------------------------------------------
# Range-of-motion limits
# --------------------------------------------------------------------------------------------
class LimitElement:
    """The limit connector of one joint and its switching state. ``bounds``: (i, lower, upper)
    of every limited theta'_i (the connector's Tait-Bryan angle i, centred; +-inf = no side)."""

    __slots__ = ("joint", "obj", "uf", "bounds", "scalar", "branches", "branch", "active", "next_check", "on_since",
                 "active_s")

    def __init__(self, joint: str, obj, uf, bounds, *, scalar: bool = False, branch_bounds=None):
        self.joint, self.obj, self.uf, self.bounds, self.scalar = joint, obj, uf, bounds, scalar
        # a spherical joint with three free angles: (i, lower, upper) of all three centred angles,
        # to tell on which branch of the sequence it is; None: always the principal one
        self.branches = branch_bounds
        self.branch = 1.0  # +1 principal (|middle angle| <= 90 deg), -1 the other one
        self.active, self.next_check, self.on_since, self.active_s = False, -math.inf, 0.0, 0.0

    def distance(self, theta) -> float:
        """Smallest distance (rad) of a limited angle to its nearest limit (< 0 beyond it);
        ``theta``: the connector's Rotation output (a scalar for a torsional spring-damper). A
        spherical joint's angles are taken on the branch that lies within the ranges, or nearer
        them, as exubio.model.kinematics reports them (``branch``, which the torque function reads)."""
        theta = (theta,) if self.scalar else theta.tolist()  # Python floats: 3x faster than numpy scalars
        if not self.branches:
            return self._distance(theta, self.bounds)
        other = [wrap_pi(theta[0] + math.pi), math.copysign(math.pi, theta[1]) - theta[1], wrap_pi(theta[2] + math.pi)]
        self.branch = -1.0 if self._distance(other, self.branches) > self._distance(theta, self.branches) else 1.0
        return self._distance(theta if self.branch > 0 else other, self.bounds)

    @staticmethod
    def _distance(theta, bounds) -> float:
        d = math.inf
        for i, lo, hi in bounds:
            x = theta[i]
            if x - lo < d:
                d = x - lo
            if hi - x < d:
                d = hi - x
        return d


def limit_window(lo: float, hi: float, kind: str, half: float):
    """(lower, upper, centre) of a range [lo, hi] of a connector angle measured from ``centre``,
    or (None, None, 0) if it cannot be enforced. Exudyn's angles are principal values: the first
    and last (``periodic``) in (-pi, pi], a spherical joint's middle angle (``middle``) in
    [-pi/2, pi/2] (the branch exubio.model.kinematics reports), a cardan joint's middle angle
    (``window``, shiftable) within pi/2 of its centre. The centre is the middle of the range, or a
    quarter window inside a one-sided limit, so the angle wraps as far as possible beyond the
    limits; a range that leaves less than _LIMIT_WRAP_TOLERANCE_RAD beyond either end is not
    enforced (nor is a middle-angle limit at or beyond +-90 deg, which that angle never reaches)."""
    if kind == "middle":
        lo = lo if lo > -half else -math.inf
        hi = hi if hi < half else math.inf
        return (lo, hi, 0.0) if (math.isfinite(lo) or math.isfinite(hi)) else (None, None, 0.0)
    window = 4.0 * half if kind == "periodic" else 2.0 * half
    if math.isfinite(lo) and math.isfinite(hi):
        if hi - lo > window - 2.0 * _LIMIT_WRAP_TOLERANCE_RAD:
            return None, None, 0.0
        c = 0.5 * (lo + hi)
    elif math.isfinite(hi):
        c = hi - 0.25 * window
    elif math.isfinite(lo):
        c = lo + 0.25 * window
    else:
        return None, None, 0.0
    return lo - c, hi - c, c


# --------------------------------------------------------------------------------------------
# A lead-in and a trial's frames, read as one array without a copy
# --------------------------------------------------------------------------------------------
class JoinedRows:
    """The rows of ``head`` then those of ``tail`` (arrays (h, ...) and (t, ...)), read as their
    concatenation reads but without its copy: a lead-in of a few frames before a whole trial's
    marker targets (PFSystem.run's ``lead_in``; the copy was 207 MB of positions and velocities on a
    20-minute trial at 200 Hz). Indexed by one row (a view) or an integer array of rows (a copy of
    those rows); ``shape`` and ``ndim`` are the concatenation's."""

    def __init__(self, head: np.ndarray, tail: np.ndarray):
        if head.ndim != tail.ndim or head.shape[1:] != tail.shape[1:]:
            raise ValueError(f"JoinedRows: rows of shape {head.shape[1:]} cannot precede rows of shape {tail.shape[1:]}")
        self.head, self.tail, self.h = head, tail, head.shape[0]
        self.shape = (head.shape[0] + tail.shape[0],) + tail.shape[1:]
        self.ndim = tail.ndim
        self.dtype = np.result_type(head, tail)

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, i):
        n = self.shape[0]
        if np.ndim(i) == 0:
            j = int(i) + (n if int(i) < 0 else 0)
            if not 0 <= j < n:
                raise IndexError(f"JoinedRows: row {int(i)} of {n}")
            return self.head[j] if j < self.h else self.tail[j - self.h]
        j = np.asarray(i)
        if j.dtype.kind not in "iu":
            raise IndexError(f"JoinedRows: rows are indexed by integers, got {j.dtype}")
        j = np.where(j < 0, j + n, j)
        if j.size and not (0 <= j.min() and j.max() < n):
            raise IndexError(f"JoinedRows: rows {j.min()}..{j.max()} of {n}")
        out = np.empty(j.shape + self.shape[1:], dtype=self.dtype)
        first = j < self.h
        out[first] = self.head[j[first]]
        out[~first] = self.tail[j[~first] - self.h]
        return out


def finite_rows(a) -> np.ndarray:
    """(n, k) bool: the rows of an array or JoinedRows (n, k, d) whose d values are all finite."""
    if isinstance(a, JoinedRows):
        return np.concatenate([finite_rows(a.head), finite_rows(a.tail)])
    return np.isfinite(a).all(axis=-1)
