"""Numpy forward kinematics of a Model: segment poses, model points, their Jacobians, the
ellipsoid constraint g, its Jacobian G and velocity term eta (paper Eq. 1-3), and the inverse map
from segment rotations / angular velocities / accelerations back to joint coordinates.

This is the single truth of the model's geometry: the Exudyn system is checked against it.
Every function accepts a leading batch of frames: q has shape (..., m).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.errors import ModelError
from exubio.model.ranges import violation, wrap_into_range
from exubio.types import JointKind, Model


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (broadcasting); faster than np.cross for small batches."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)))  # written in place: no stacking copy
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about a fixed unit ``axis`` by ``angle`` (...) (Rodrigues)."""
    k = _skew(axis)
    k2 = k @ k
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * k + (1.0 - c) * k2


@dataclass(frozen=True)
class PointSet:
    """Model points to evaluate: the segment index and the local position (m) of each."""

    segment_index: np.ndarray  # (k,) int
    local_m: np.ndarray  # (k, 3)
    names: tuple[str, ...] = ()


@dataclass(frozen=True)
class Frames:
    """Everything forward kinematics computes for q (batch dims ... in front).

    R: (..., n_seg, 3, 3) segment orientations, p: (..., n_seg, 3) segment origins,
    axes: (..., m, 3) world rotation axis of each coordinate, pivots: (..., m, 3) the joint centre
    each coordinate rotates about.
    """

    R: np.ndarray
    p: np.ndarray
    axes: np.ndarray
    pivots: np.ndarray


class Kinematics:
    """Compiled kinematic structure of a Model (a tree rooted at the fixed first segment)."""

    def __init__(self, model: Model):
        self.model = model
        self.n_segments = len(model.segments)
        self.n_coordinates = model.n_coordinates
        names = model.segment_names
        self.parent_index = np.array([-1 if s.parent is None else names.index(s.parent) for s in model.segments])
        self._joint_coords: list[np.ndarray] = []  # coordinate indices of each segment's joint
        self._axis_skews: list[list[tuple[np.ndarray, np.ndarray]]] = []
        self.coordinate_segment = np.zeros(self.n_coordinates, dtype=int)
        start = 0
        for i, seg in enumerate(model.segments):
            if seg.joint is None:
                self._joint_coords.append(np.zeros(0, dtype=int))
                self._axis_skews.append([])
                continue
            k = seg.joint.kind.n_coordinates
            idx = np.arange(start, start + k)
            self._joint_coords.append(idx)
            self.coordinate_segment[idx] = i
            skews = []
            for a in seg.joint.axes:
                sk = _skew(a)
                skews.append((sk, sk @ sk))
            self._axis_skews.append(skews)
            if seg.joint.kind in (JointKind.SPHERICAL, JointKind.CARDAN):
                ax = seg.joint.axes
                for u in range(len(ax)):
                    for v in range(u + 1, len(ax)):
                        if abs(ax[u] @ ax[v]) > 1e-9:
                            raise ModelError(
                                f"{model.source}: joint '{seg.joint.name}' must have mutually orthogonal axes "
                                f"(axes {u} and {v} are not)"
                            )
            start += k
        # affects[s, j]: coordinate j moves segment s (j belongs to s or to one of its ancestors).
        self.affects = np.zeros((self.n_segments, self.n_coordinates), dtype=bool)
        for s in range(self.n_segments):
            a = s
            while a >= 0:
                self.affects[s, self._joint_coords[a]] = True
                a = self.parent_index[a]
        self._affects_f = self.affects.astype(float)
        self._sk = np.array([sk for skews in self._axis_skews for sk, _ in skews]).reshape(-1, 3, 3)
        self._sk2 = np.array([sk2 for skews in self._axis_skews for _, sk2 in skews]).reshape(-1, 3, 3)
        self._chain = [(i, int(self.parent_index[i]), self._joint_coords[i], seg.joint.centre_m, seg.joint.axes)
                       for i, seg in enumerate(model.segments) if seg.joint is not None]
        if self.parent_index[0] != -1 or any(par < 0 for _, par, *_ in self._chain):
            raise ModelError(f"{model.source}: the first segment must be the fixed root, and only it")
        # precedes[j, k]: coordinate k comes before j on the chain from the root to j.
        self.precedes = np.zeros((self.n_coordinates, self.n_coordinates), dtype=bool)
        for j in range(self.n_coordinates):
            s = self.coordinate_segment[j]
            self.precedes[j] = self.affects[s] & (np.arange(self.n_coordinates) < j)
            own = self._joint_coords[s]
            self.precedes[j, own[own >= j]] = False
        self._precedes_f = self.precedes.astype(float)
        ell = model.ellipsoid
        self.contacts = self.point_set([(seg, pt) for seg, pt in ell.contact_points])
        self.a_diag = ell.a_diag
        self.centre = np.asarray(ell.centre_m, dtype=float)

    # ---------------------------------------------------------------- points
    @property
    def _inverse(self) -> "_InverseTable":
        t = self.__dict__.get("_inverse_table")
        if t is None:
            t = self.__dict__["_inverse_table"] = _InverseTable(self)
        return t

    def point_set(self, items, /) -> PointSet:
        """PointSet from (segment name, point name or local position (3,) in m) pairs."""
        seg_idx, local, names = [], [], []
        for seg_name, point in items:
            seg = self.model.segment(seg_name)
            seg_idx.append(self.model.segment_index(seg_name))
            if isinstance(point, str):
                if point not in seg.points:
                    raise ModelError(f"{self.model.source}: segment '{seg_name}' has no point '{point}'; it has {sorted(seg.points)}")
                local.append(seg.points[point])
                names.append(point)
            else:
                local.append(np.asarray(point, dtype=float))
                names.append(f"{seg_name}_point{len(names)}")
        return PointSet(np.array(seg_idx, dtype=int), np.array(local, dtype=float).reshape(-1, 3), tuple(names))

    # ---------------------------------------------------------------- forward
    def kernel_tables(self) -> tuple[np.ndarray, ...]:
        """The chain as flat arrays for the compiled kernels (exubio.model.kernels): parent of each
        segment, joint centre in the parent (m), first coordinate and number of coordinates of each
        joint, each coordinate's axis, and its Rodrigues skew matrices K and K^2."""
        t = self.__dict__.get("_kernel_tables")
        if t is None:
            n_seg = self.n_segments
            centre, axes = np.zeros((n_seg, 3)), np.zeros((self.n_coordinates, 3))
            first, count = np.zeros(n_seg, dtype=np.int64), np.zeros(n_seg, dtype=np.int64)
            for i, _, idx, c, ax in self._chain:  # a joint's coordinates are consecutive (see __init__)
                centre[i], first[i], count[i] = c, idx[0], len(idx)
                axes[idx] = np.asarray(ax, dtype=float).reshape(-1, 3)
            t = self.__dict__["_kernel_tables"] = (np.asarray(self.parent_index, dtype=np.int64), centre, first, count,
                                                   axes, np.ascontiguousarray(self._sk), np.ascontiguousarray(self._sk2))
        return t

    def frames(self, q: np.ndarray) -> Frames:
        """Forward kinematics for q (..., m): the compiled kernel (exubio.model.kernels.forward,
        a frame at a time; imported here, on first use), equal to ``frames_numpy`` to round-off."""
        from exubio.model import kernels  # numba: imported where used

        q = np.asarray(q, dtype=float)
        batch = q.shape[:-1]
        flat = np.ascontiguousarray(q.reshape(-1, self.n_coordinates))
        B, n_seg, m = flat.shape[0], self.n_segments, self.n_coordinates
        R, p = np.empty((B, n_seg, 3, 3)), np.empty((B, n_seg, 3))
        axes, pivots = np.empty((B, m, 3)), np.empty((B, m, 3))
        kernels.forward(flat, *self.kernel_tables(), R, p, axes, pivots)
        return Frames(R.reshape(batch + (n_seg, 3, 3)), p.reshape(batch + (n_seg, 3)), axes.reshape(batch + (m, 3)),
                      pivots.reshape(batch + (m, 3)))

    def frames_numpy(self, q: np.ndarray) -> Frames:
        """Forward kinematics for q (..., m) in numpy: the reference of the compiled ``frames``."""
        q = np.asarray(q, dtype=float)
        batch = q.shape[:-1]
        R = np.empty(batch + (self.n_segments, 3, 3))
        p = np.empty(batch + (self.n_segments, 3))
        axes = np.empty(batch + (self.n_coordinates, 3))
        pivots = np.empty(batch + (self.n_coordinates, 3))
        # every elementary rotation at once (Rodrigues): (..., m, 3, 3)
        elem = np.eye(3) + np.sin(q)[..., None, None] * self._sk + (1.0 - np.cos(q))[..., None, None] * self._sk2
        R[..., 0, :, :] = np.eye(3)
        p[..., 0, :] = 0.0
        for i, par, idx, centre, ax in self._chain:
            Rp = R[..., par, :, :]
            pos = p[..., par, :] + Rp @ centre
            Rc = Rp
            for j, a in zip(idx, ax):
                axes[..., j, :] = Rc @ a
                Rc = Rc @ elem[..., j, :, :]
            pivots[..., idx, :] = pos[..., None, :]
            R[..., i, :, :] = Rc
            p[..., i, :] = pos
        return Frames(R, p, axes, pivots)

    def poses(self, q: np.ndarray):
        """(R (..., n_seg, 3, 3), p (..., n_seg, 3)) for q (..., m)."""
        fr = self.frames(q)
        return fr.R, fr.p

    def points(self, q: np.ndarray, points: PointSet, *, frames: Frames | None = None) -> np.ndarray:
        """Global positions (..., k, 3) of the model points (the compiled kernel, exubio.model.kernels;
        ``points_numpy`` is its reference)."""
        from exubio.model import kernels  # numba: imported where used

        fr = self.frames(q) if frames is None else frames
        batch, n_seg, k = fr.R.shape[:-3], fr.R.shape[-3], len(points.segment_index)
        B = int(np.prod(batch, dtype=int))
        out = np.empty((B, k, 3))
        kernels.points(np.ascontiguousarray(fr.R, dtype=float).reshape(B, n_seg, 3, 3),
                       np.ascontiguousarray(fr.p, dtype=float).reshape(B, n_seg, 3),
                       np.asarray(points.segment_index, dtype=np.int64), np.ascontiguousarray(points.local_m, dtype=float), out)
        return out.reshape(batch + (k, 3))

    def points_numpy(self, q: np.ndarray, points: PointSet, *, frames: Frames | None = None) -> np.ndarray:
        """``points`` in numpy: the kernel's reference."""
        fr = self.frames(q) if frames is None else frames
        Rs = fr.R[..., points.segment_index, :, :]
        return (Rs @ points.local_m[:, :, None])[..., 0] + fr.p[..., points.segment_index, :]

    def point_jacobian(self, q: np.ndarray, points: PointSet, *, frames: Frames | None = None,
                       positions: np.ndarray | None = None) -> np.ndarray:
        """d r_k / d q: (..., k, 3, m), C-contiguous. Column j is w_j x (r_k - c_j) = w_j x r_k - w_j x c_j
        where coordinate j moves r_k (the second term is the same for every point: computed once)."""
        fr = self.frames(q) if frames is None else frames
        r = self.points(q, points, frames=fr) if positions is None else positions
        wc = np.swapaxes(cross(fr.axes, fr.pivots), -1, -2)[..., None, :, :]  # (..., 1, 3, m)
        w = np.swapaxes(fr.axes, -1, -2)[..., None, :, :]  # (..., 1, 3, m)
        x, y, z = r[..., 0:1], r[..., 1:2], r[..., 2:3]  # (..., k, 1)
        out = np.empty(r.shape[:-1] + (3, self.n_coordinates))
        np.subtract(w[..., 1, :] * z - w[..., 2, :] * y, wc[..., 0, :], out=out[..., 0, :])
        np.subtract(w[..., 2, :] * x - w[..., 0, :] * z, wc[..., 1, :], out=out[..., 1, :])
        np.subtract(w[..., 0, :] * y - w[..., 1, :] * x, wc[..., 2, :], out=out[..., 2, :])
        out *= self._affects_f[points.segment_index][..., None, :]
        return out

    def point_bias_acceleration(self, q: np.ndarray, qd: np.ndarray, points: PointSet, *,
                                frames: Frames | None = None, positions: np.ndarray | None = None,
                                jacobian: np.ndarray | None = None) -> np.ndarray:
        """(dJ/dt) q̇ of each point: its acceleration when q̈ = 0, (..., k, 3); ``frames`` and ``positions``:
        those of q and the points where the caller has them (``jacobian`` is accepted and not needed).

        With a_j the axis, c_j the pivot of coordinate j, Omega_j the angular velocity of the frame
        that carries axis j, adot_j = Omega_j x a_j and cdot_j the pivot's velocity, a point moved
        by the coordinates j in S_k has (dJ/dt q̇)_k = sum_{j in S_k} q̇_j [adot_j x (r_k - c_j) +
        a_j x (ṙ_k - cdot_j)]; the sums over j split into per-segment sums (S_k is the set of
        its segment), so the cost is one pass over the coordinates plus one over the points."""
        fr = self.frames(q) if frames is None else frames
        r = self.points(q, points, frames=fr) if positions is None else positions
        qd = np.asarray(qd, dtype=float)
        prec = self._precedes_f
        wq = fr.axes * qd[..., None]  # (..., m, 3): q̇_j a_j
        omega = prec @ wq  # frame rate of axis j
        u = cross(omega, wq)  # q̇_j adot_j
        cdot = cross(omega, fr.pivots) - prec @ cross(wq, fr.pivots)
        wqc = cross(wq, fr.pivots)
        aff = self._affects_f  # (n_seg, m)
        seg = points.segment_index
        om_s = (aff @ wq)[..., seg, :]  # the segment's angular velocity, per point
        rd = cross(om_s, r) - (aff @ wqc)[..., seg, :]  # the point's velocity J q̇
        z = cross(u, fr.pivots) + cross(wq, cdot)
        return cross((aff @ u)[..., seg, :], r) + cross(om_s, rd) - (aff @ z)[..., seg, :]

    # ---------------------------------------------------------------- constraints
    def g(self, q: np.ndarray, *, frames: Frames | None = None) -> np.ndarray:
        """Ellipsoid constraints g_j = e_j^T A e_j - 1 (..., 2) (paper Eq. 1)."""
        e = self.points(q, self.contacts, frames=frames) - self.centre
        return np.einsum("...kc,c->...k", e * e, self.a_diag) - 1.0

    def G(self, q: np.ndarray, *, frames: Frames | None = None) -> np.ndarray:
        """Constraint Jacobian G_j = 2 e_j^T A J_Pj (..., 2, m) (paper Eq. 2)."""
        fr = self.frames(q) if frames is None else frames
        r = self.points(q, self.contacts, frames=fr)
        J = self.point_jacobian(q, self.contacts, frames=fr, positions=r)
        return 2.0 * np.einsum("...kc,...kcm->...km", (r - self.centre) * self.a_diag, J)

    def eta(self, q: np.ndarray, qd: np.ndarray, *, frames: Frames | None = None) -> np.ndarray:
        """Velocity term of the constraint acceleration: g̈ = G q̈ + eta (..., 2) (paper Eq. 3)."""
        fr = self.frames(q) if frames is None else frames
        r = self.points(q, self.contacts, frames=fr)
        J = self.point_jacobian(q, self.contacts, frames=fr, positions=r)
        v = np.einsum("...kcm,...m->...kc", J, np.asarray(qd, dtype=float))
        bias = self.point_bias_acceleration(q, qd, self.contacts, frames=fr, positions=r, jacobian=J)
        e = r - self.centre
        return 2.0 * np.einsum("...kc,c->...k", v * v + e * bias, self.a_diag)

    # ---------------------------------------------------------------- inverse maps
    def joint_coordinate_indices(self, segment_index: int) -> np.ndarray:
        """Indices of the coordinates of the joint that moves this segment."""
        return self._joint_coords[segment_index]

    def joint_frames(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """(segment index, parent index, coordinate indices, axes) of every joint."""
        out = []
        for i, seg in enumerate(self.model.segments):
            if seg.joint is not None:
                out.append((i, int(self.parent_index[i]), self._joint_coords[i], seg.joint.axes))
        return out

    def coordinates_from_rotations(self, R: np.ndarray, *, q_previous: np.ndarray | None = None) -> np.ndarray:
        """Joint coordinates (..., m) from segment orientations R (..., n_seg, 3, 3), over the full
        range of every joint type.

        A spherical joint's rotation has two angle triples, (q1, q2, q3) and (q1 + pi, pi - q2,
        q3 + pi); a cardan joint's and a revolute joint's are unique up to 2 pi. Of the candidates
        (and their 2 pi shifts) the one inside the coordinates' ranges of motion (the model's
        ``range_deg``), or nearest to them, is returned; among equally good ones, the one nearest
        ``q_previous`` when it is given, otherwise the principal branch (|q2| <= 90 deg, angles
        nearest the middle of their ranges). Where the middle angle of a spherical joint comes
        within 1e-6 rad of +-90 deg the split between first and last angle is undetermined: the
        first angle then keeps ``q_previous`` (or 0).

        The compiled kernel (exubio.model.kernels.coordinates_from_rotations, frame by frame);
        ``coordinates_from_rotations_numpy`` is its reference.
        """
        from exubio.model import kernels  # numba: imported where used

        R = np.asarray(R, dtype=float)
        batch, m = R.shape[:-3], self.n_coordinates
        flat = np.ascontiguousarray(R.reshape((-1,) + R.shape[-3:]))
        if q_previous is None:
            lo, hi = self.model.coordinate_ranges_rad.T
            bounded = np.isfinite(lo) & np.isfinite(hi)
            ref = np.where(bounded, 0.5 * (np.where(bounded, lo, 0.0) + np.where(bounded, hi, 0.0)), 0.0)
        else:
            ref = np.asarray(q_previous, dtype=float)
        ref = np.ascontiguousarray(np.broadcast_to(ref, batch + (m,))).reshape(-1, m)
        out = np.empty((flat.shape[0], m))
        kernels.coordinates_from_rotations(flat, ref, q_previous is not None,
                                           *self._inverse.kernel_tables(self.model.coordinate_ranges_rad), out)
        return out.reshape(batch + (m,))

    def coordinates_from_rotations_numpy(self, R: np.ndarray, *, q_previous: np.ndarray | None = None) -> np.ndarray:
        """``coordinates_from_rotations`` in numpy, every frame at once: the kernel's reference."""
        R = np.asarray(R, dtype=float)
        t = self._inverse
        ranges = self.model.coordinate_ranges_rad
        prev = None if q_previous is None else np.broadcast_to(np.asarray(q_previous, dtype=float),
                                                               R.shape[:-3] + (self.n_coordinates,))
        # every joint's rotation relative to its parent, in its axes' basis B: Rs = B^T R_par^T R_s B
        Rrel = np.swapaxes(R[..., t.parents, :, :], -1, -2) @ R[..., t.children, :, :]
        Rs = t.Bt @ Rrel @ t.B
        qa = np.empty(R.shape[:-3] + (self.n_coordinates,))
        qb = qa  # the second angle triple of the spherical joints (the others have one)
        for j, a, P, i in zip(t.rev, t.rev_axes, t.rev_proj, t.rev_q):  # revolute: the angle about the axis
            Rr = Rrel[..., j, :, :]
            vee = np.stack([Rr[..., 2, 1] - Rr[..., 1, 2], Rr[..., 0, 2] - Rr[..., 2, 0], Rr[..., 1, 0] - Rr[..., 0, 1]],
                           axis=-1)
            # cos from the part of R orthogonal to the axis: trace of (I - aa^T) R (I - aa^T) = 2 cos
            qa[..., i] = np.arctan2(0.5 * vee @ a, 0.5 * np.einsum("ij,...jk,ki->...", P, Rr, P))
        if t.card.size:  # cardan: Rx(q1) Ry(q2) = [[c2, 0, s2], [s1 s2, c1, -s1 c2], [-c1 s2, s1, c1 c2]]
            Rc = Rs[..., t.card, :, :]
            qa[..., t.card_q[:, 0]] = np.arctan2(Rc[..., 2, 1], Rc[..., 1, 1])
            qa[..., t.card_q[:, 1]] = np.arctan2(Rc[..., 0, 2], Rc[..., 0, 0])
        if t.sph.size:  # spherical: Rx(q1) Ry(q2) Rz(sign * q3), two triples
            Rp = Rs[..., t.sph, :, :]
            q2 = np.arctan2(Rp[..., 0, 2], np.hypot(Rp[..., 0, 0], Rp[..., 0, 1]))
            q1 = np.arctan2(-Rp[..., 1, 2], Rp[..., 2, 2])
            q3 = np.arctan2(-Rp[..., 0, 1], Rp[..., 0, 0])
            lock = np.cos(q2) < 1e-6
            if np.any(lock):
                # Rx(q1) Ry(+-90) Rz(q3): only q1 +- q3 is defined; keep q1 and solve q3.
                first = np.zeros_like(q1) if prev is None else prev[..., t.sph_q[:, 0]]
                q1 = np.where(lock, first, q1)
                # R[1,0] = cos q1 sin q3 + sin q1 sin q2 cos q3 ; R[1,1] = cos q1 cos q3 - sin q1 sin q2 sin q3
                s2 = np.sign(Rp[..., 0, 2])
                phi = np.arctan2(Rp[..., 1, 0], Rp[..., 1, 1])  # = q3 + s2*q1 at lock
                q3 = np.where(lock, phi - s2 * q1, q3)
            qb = qa.copy()
            qa[..., t.sph_q[:, 0]], qa[..., t.sph_q[:, 1]], qa[..., t.sph_q[:, 2]] = q1, q2, t.sph_sign * q3
            qb[..., t.sph_q[:, 0]], qb[..., t.sph_q[:, 1]] = q1 + np.pi, np.pi - q2
            qb[..., t.sph_q[:, 2]] = t.sph_sign * (q3 + np.pi)
        a_sol = wrap_into_range(qa, ranges, prev)
        if not t.sph.size:
            return a_sol
        b_sol = wrap_into_range(qb, ranges, prev)
        cost_a = np.abs(violation(a_sol, ranges))[..., t.sph_q].sum(axis=-1)
        cost_b = np.abs(violation(b_sol, ranges))[..., t.sph_q].sum(axis=-1)
        take_b = cost_b < cost_a - 1e-12
        if prev is not None:
            tie = np.abs(cost_b - cost_a) <= 1e-12
            ref = prev[..., t.sph_q]
            near_b = np.abs(b_sol[..., t.sph_q] - ref).sum(axis=-1) < np.abs(a_sol[..., t.sph_q] - ref).sum(axis=-1)
            take_b |= tie & near_b
        a_sol[..., t.sph_q] = np.where(take_b[..., None], b_sol[..., t.sph_q], a_sol[..., t.sph_q])
        return a_sol

    def coordinate_rates(self, q: np.ndarray, omega: np.ndarray, alpha: np.ndarray | None = None):
        """q̇ (and q̈) from segment angular velocities omega and accelerations alpha (..., n_seg, 3),
        global frame, at coordinates q (..., m). Solves, per joint, the relative angular velocity
        W q̇_joint = omega_child - omega_parent (least squares for k < 3 coordinates): the compiled
        kernel (exubio.model.kernels.coordinate_rates); ``coordinate_rates_numpy`` is its reference."""
        from exubio.model import kernels  # numba: imported where used

        q = np.asarray(q, dtype=float)
        m, n_seg = self.n_coordinates, self.n_segments
        flat = np.ascontiguousarray(q.reshape(-1, m))
        om = np.ascontiguousarray(np.broadcast_to(omega, q.shape[:-1] + (n_seg, 3)), dtype=float).reshape(-1, n_seg, 3)
        al = om if alpha is None else np.ascontiguousarray(
            np.broadcast_to(alpha, q.shape[:-1] + (n_seg, 3)), dtype=float).reshape(-1, n_seg, 3)
        qd, qdd = np.zeros(flat.shape), np.zeros(flat.shape)
        kernels.coordinate_rates(flat, om, al, alpha is not None, *self.kernel_tables(), qd, qdd)
        qd = qd.reshape(q.shape)
        return (qd, qdd.reshape(q.shape)) if alpha is not None else qd

    def coordinate_rates_numpy(self, q: np.ndarray, omega: np.ndarray, alpha: np.ndarray | None = None):
        """``coordinate_rates`` in numpy: the reference of the compiled kernel."""
        fr = self.frames(q)
        omega = np.asarray(omega, dtype=float)
        qd = np.zeros(q.shape)
        qdd = np.zeros(q.shape) if alpha is not None else None
        for s, par, idx, _ in self.joint_frames():
            W = np.swapaxes(fr.axes[..., idx, :], -1, -2)  # (..., 3, k)
            WtW_inv = np.linalg.inv(np.swapaxes(W, -1, -2) @ W)
            pinv = WtW_inv @ np.swapaxes(W, -1, -2)  # (..., k, 3)
            dw = omega[..., s, :] - omega[..., par, :]
            qd_j = np.einsum("...kc,...c->...k", pinv, dw)
            qd[..., idx] = qd_j
            if alpha is not None:
                # alpha_rel = sum_j w_j q̈_j + sum_j (Omega_j x w_j) q̇_j, Omega_j = frame rate of axis j
                Om = np.repeat(omega[..., par, None, :], len(idx), axis=-2).copy()
                for n in range(1, len(idx)):
                    Om[..., n, :] = Om[..., n - 1, :] + fr.axes[..., idx[n - 1], :] * qd_j[..., n - 1, None]
                bias = np.einsum("...kc,...k->...c", cross(Om, fr.axes[..., idx, :]), qd_j)
                da = np.asarray(alpha)[..., s, :] - np.asarray(alpha)[..., par, :] - bias
                qdd[..., idx] = np.einsum("...kc,...c->...k", pinv, da)
        return (qd, qdd) if alpha is not None else qd

    def segment_angular_velocities(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Global angular velocity of each segment (..., n_seg, 3)."""
        fr = self.frames(q)
        wq = fr.axes * np.asarray(qd, dtype=float)[..., None]
        return np.einsum("sm,...mc->...sc", self.affects.astype(float), wq)


class _InverseTable:
    """The joints of a Kinematics grouped by kind, as index arrays and stacked constants, so that
    coordinates_from_rotations treats every joint of a kind in one array operation (a frame at a
    time, as the live loop asks, the cost is the number of operations, not of joints)."""

    def __init__(self, kin: "Kinematics"):
        joints = kin.joint_frames()
        if sorted(int(j) for _, _, idx, _ in joints for j in idx) != list(range(kin.n_coordinates)):
            raise ModelError(f"{kin.model.source}: every coordinate must belong to one joint")
        self.children = np.array([s for s, *_ in joints], dtype=int)
        self.parents = np.array([p for _, p, *_ in joints], dtype=int)
        B = np.tile(np.eye(3), (len(joints), 1, 1))
        rev, card, sph, signs = [], [], [], []
        for n, (_, _, idx, axes) in enumerate(joints):
            if len(idx) == 1:
                rev.append(n)
                continue
            B[n] = np.column_stack([axes[0], axes[1], cross(axes[0], axes[1])])
            if len(idx) == 2:
                card.append(n)
            else:
                sph.append(n)
                signs.append(float(np.sign(axes[2] @ B[n][:, 2])))
        self.B, self.Bt = B, np.swapaxes(B, -1, -2).copy()
        self.rev, self.card, self.sph = (np.array(v, dtype=int) for v in (rev, card, sph))
        self.rev_q = np.array([joints[n][2][0] for n in rev], dtype=int)
        self.rev_axes = np.array([joints[n][3][0] for n in rev], dtype=float).reshape(-1, 3)
        self.rev_proj = [np.eye(3) - np.outer(a, a) for a in self.rev_axes]
        self.card_q = np.array([joints[n][2] for n in card], dtype=int).reshape(-1, 2)
        self.sph_q = np.array([joints[n][2] for n in sph], dtype=int).reshape(-1, 3)
        self.sph_sign = np.array(signs, dtype=float)

    def kernel_tables(self, ranges_rad: np.ndarray) -> tuple:
        """The tables of exubio.model.kernels.coordinates_from_rotations (after R and the reference)."""
        t = self.__dict__.get("_kernel")
        if t is None:
            i64, c = np.int64, np.ascontiguousarray
            t = self.__dict__["_kernel"] = (
                self.parents.astype(i64), self.children.astype(i64), c(self.B), self.rev.astype(i64), self.rev_q.astype(i64),
                c(self.rev_axes), c(np.array(self.rev_proj).reshape(-1, 3, 3)), self.card.astype(i64),
                c(self.card_q, dtype=i64), self.sph.astype(i64), c(self.sph_q, dtype=i64), c(self.sph_sign),
                c(ranges_rad, dtype=float))
        return t
