"""The thorax's own motion in the lab, as the inverse dynamics needs it: the model is thorax-fixed
(every q, q', q'' is relative to the thorax), so a trunk that leans, turns or walks is a moving,
rotating reference frame. exubio.prep.thorax_motion measures it from the thorax markers;
exubio.synth makes it exactly.

``ThoraxMotion`` holds, per frame and in the lab: the thorax frame's rotation R (columns: the ISB
thorax X, Y, Z axes), its origin (IJ), the origin's velocity and acceleration, the frame's angular
velocity and acceleration, and gravity. ``frame_terms`` expresses what the dynamics needs in the
thorax frame (the model's world), for a right arm as it is and for a left arm mirrored as its
markers are (Z -> -Z of the thorax frame; an axial vector w becomes -S w there, S = diag(1, 1, -1)):

    g_T = R^T g,   a_O,T = R^T a_O,   w_T = R^T w,   w'_T = R^T w'   (d/dt in the thorax frame of w_T
    is R^T w', since w x w = 0).

``thorax_angles`` gives the ISB thorax-to-lab angles (Wu et al. 2005: thorax relative to the global
frame, Z-X'-Y'': flexion (+) / extension about Z, lateral flexion about X', axial rotation about
Y''), in a global frame with Y up (against gravity), X the horizontal direction of the thorax's
mean anterior axis over the trial, Z = X x Y.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.model.angles import euler_angles
from exubio.model.kinematics import cross

__all__ = ["FrameTerms", "ThoraxMotion", "THORAX_ANGLE_COLUMNS", "thorax_angles"]

STANDARD_GRAVITY_M_S2 = 9.80665

THORAX_ANGLE_COLUMNS = ("thorax_Z_flexion_deg", "thorax_X_lateral_flexion_deg", "thorax_Y_axial_rotation_deg")
"""The thorax-to-lab angle columns of ``<stem>.<method>.thorax.csv`` (degrees)."""


@dataclass(frozen=True)
class FrameTerms:
    """The thorax frame's motion in its own coordinates (n, 3) each: gravity (m/s^2), the origin's
    acceleration (m/s^2), angular velocity (rad/s) and angular acceleration (rad/s^2)."""

    gravity: np.ndarray
    origin_acceleration: np.ndarray
    angular_velocity: np.ndarray
    angular_acceleration: np.ndarray


@dataclass(frozen=True)
class ThoraxMotion:
    """The thorax frame in the lab per frame (module docstring). rotation (n, 3, 3); origin_m,
    velocity_m_s, acceleration_m_s2, angular_velocity_rad_s, angular_acceleration_rad_s2 (n, 3),
    lab coordinates; gravity_m_s2 (3,) lab; ``mirrored``: a left arm (frame_terms mirrors);
    ``source``: how it was obtained (said in the moments file's header)."""

    time_s: np.ndarray
    rotation: np.ndarray
    origin_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray
    angular_velocity_rad_s: np.ndarray
    angular_acceleration_rad_s2: np.ndarray
    gravity_m_s2: np.ndarray
    source: str = ""
    mirrored: bool = False

    def frame_terms(self) -> FrameTerms:
        Rt = np.swapaxes(self.rotation, -1, -2)

        def rot(v):
            return np.einsum("nij,nj->ni", Rt, np.broadcast_to(v, self.origin_m.shape))

        g, a, w, wd = (rot(self.gravity_m_s2), rot(self.acceleration_m_s2), rot(self.angular_velocity_rad_s),
                       rot(self.angular_acceleration_rad_s2))
        if self.mirrored:
            polar, axial = np.array([1.0, 1.0, -1.0]), np.array([-1.0, -1.0, 1.0])
            g, a, w, wd = g * polar, a * polar, w * axial, wd * axial
        return FrameTerms(g, a, w, wd)

    def point_acceleration(self, r_thorax: np.ndarray) -> np.ndarray:
        """Lab acceleration (n, 3) of a point fixed in the thorax at r_thorax (3,) (unmirrored)."""
        r = np.einsum("nij,j->ni", self.rotation, np.asarray(r_thorax, dtype=float))
        w, wd = self.angular_velocity_rad_s, self.angular_acceleration_rad_s2
        return self.acceleration_m_s2 + cross(wd, r) + cross(w, cross(w, r))


def global_frame(motion: ThoraxMotion, /) -> np.ndarray:
    """The ISB global frame (3, 3), columns X, Y, Z in lab coordinates (module docstring)."""
    up = -np.asarray(motion.gravity_m_s2, dtype=float)
    up = up / np.linalg.norm(up)
    x = np.nanmean(motion.rotation[:, :, 0], axis=0)
    x = x - up * (x @ up)
    x = x / np.linalg.norm(x)
    return np.column_stack([x, up, np.cross(x, up)])


def thorax_angles(motion: ThoraxMotion, /) -> np.ndarray:
    """(n, 3) radians: the ISB thorax-to-lab angles of THORAX_ANGLE_COLUMNS (module docstring)."""
    G = global_frame(motion)
    return euler_angles(G.T @ motion.rotation, "ZXY")
