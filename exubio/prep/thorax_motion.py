"""The thorax's pose and motion in the lab from its markers (exubio.dynamics.thorax_motion.ThoraxMotion),
for the inverse dynamics of a thorax-fixed model.

The thorax landmarks (IJ, PX, C7, T8, or the protocol's midpoints) are taken from the trial in lab
coordinates, their short gaps bridged as exubio.prep.targets bridges them, low-pass filtered with
the protocol's filter (exubio.prep.filtering.filter_markers: the same cut-off and order as the
markers, "auto" included) and differentiated by the same cubic splines
(exubio.prep.targets.spline_derivatives). The ISB frame (exubio.prep.thorax.thorax_frame) and its
first and second time derivatives follow analytically from the landmarks' positions, velocities
and accelerations (unit vector u = v/|v|: u' = (v' - u s')/s, u'' = (v'' - 2 u' s' - u s'')/s with
s = |v|, s' = u.v', s'' = u'.v' + u.v''; products by the product rule); then
[w] = skew(R' R^T), [w'] = skew(R'' R^T), exact for the filtered landmarks.

Gravity: 9.80665 m/s^2 along the lab's downward axis, ``lab_up`` ("+x" ... "-z"), or with "auto"
the lab axis nearest the thorax's mean +Y over the trial (a seated or standing subject's thorax is
within 45 deg of upright; a trial where no lab axis is within 45 deg of it is refused: give
``--lab-up``).
"""
from __future__ import annotations

import numpy as np

from exubio.dynamics.thorax_motion import STANDARD_GRAVITY_M_S2, ThoraxMotion
from exubio.errors import InputError
from exubio.model.kinematics import cross
from exubio.prep.filtering import filter_markers
from exubio.prep.moment_options import LAB_UP_CHOICES
from exubio.prep.thorax import MAX_THORAX_GAP_S, isb_landmarks, lab_landmarks, thorax_frame
from exubio.protocol.labels import resolve_labels
from exubio.types import Protocol, Trajectories

__all__ = ["LAB_UP_CHOICES", "frame_derivatives", "lab_gravity", "measure_thorax_motion"]

MAX_TILT_DEG = 45.0


def _unit_derivatives(v, vd, vdd):
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    u = v / s
    sd = np.sum(u * vd, axis=-1, keepdims=True)
    ud = (vd - u * sd) / s
    sdd = np.sum(ud * vd, axis=-1, keepdims=True) + np.sum(u * vdd, axis=-1, keepdims=True)
    udd = (vdd - 2.0 * ud * sd - u * sdd) / s
    return u, ud, udd


def _vee_skew(M: np.ndarray) -> np.ndarray:
    A = 0.5 * (M - np.swapaxes(M, -1, -2))
    return np.stack([A[..., 2, 1], A[..., 0, 2], A[..., 1, 0]], axis=-1)


def frame_derivatives(landmarks: tuple, rates: tuple, accelerations: tuple):
    """(R (n, 3, 3), w (n, 3), w' (n, 3)) of the ISB thorax frame of (IJ, PX, C7, T8) positions,
    velocities and accelerations (each a 4-tuple of (n, 3)), lab coordinates (module docstring)."""
    def parts(ij, px, c7, t8):
        return 0.5 * (ij + c7) - 0.5 * (px + t8), ij - c7

    (y0, d0), (y1, d1), (y2, d2) = parts(*landmarks), parts(*rates), parts(*accelerations)
    z0 = cross(d0, y0)
    z1 = cross(d1, y0) + cross(d0, y1)
    z2 = cross(d2, y0) + 2.0 * cross(d1, y1) + cross(d0, y2)
    y, yd, ydd = _unit_derivatives(y0, y1, y2)
    z, zd, zdd = _unit_derivatives(z0, z1, z2)
    x, xd, xdd = cross(y, z), cross(yd, z) + cross(y, zd), cross(ydd, z) + 2.0 * cross(yd, zd) + cross(y, zdd)
    R, Rd, Rdd = (np.stack(c, axis=-1) for c in ((x, y, z), (xd, yd, zd), (xdd, ydd, zdd)))
    Rt = np.swapaxes(R, -1, -2)
    return R, _vee_skew(Rd @ Rt), _vee_skew(Rdd @ Rt)


def lab_gravity(rotation: np.ndarray, lab_up: str = "auto", /, *, source: str = "") -> tuple[np.ndarray, str]:
    """Gravity (3,) in the lab (module docstring) and how its direction was chosen."""
    choice = str(lab_up).strip().lower()
    if choice not in LAB_UP_CHOICES:
        raise InputError(f"--lab-up '{lab_up}': expected one of {list(LAB_UP_CHOICES)}")
    mean_y = np.nanmean(rotation[:, :, 1], axis=0)
    if choice == "auto":
        k = int(np.nanargmax(np.abs(mean_y)))
        up = np.zeros(3)
        up[k] = np.sign(mean_y[k])
        label = ("+" if up[k] > 0 else "-") + "xyz"[k]
        how = f"lab up {label}: the lab axis nearest the thorax's mean +Y (--lab-up auto)"
    else:
        up = np.zeros(3)
        up["xyz".index(choice[1])] = 1.0 if choice[0] == "+" else -1.0
        how = f"lab up {choice} (--lab-up)"
    norm = float(np.linalg.norm(mean_y))
    tilt = float(np.degrees(np.arccos(np.clip(mean_y @ up / norm, -1.0, 1.0)))) if norm > 0 else 180.0
    if tilt > MAX_TILT_DEG:
        raise InputError(f"{source}: the thorax's mean +Y is {tilt:.0f} deg from the lab's up axis ({how}); a seated or "
                         f"standing thorax is within {MAX_TILT_DEG:g} deg of upright: give the lab's vertical with "
                         f"--lab-up (one of {list(LAB_UP_CHOICES[1:])})")
    return -STANDARD_GRAVITY_M_S2 * up, how


def measure_thorax_motion(trajectories: Trajectories, protocol: Protocol, /, *, lab_up: str = "auto",
                          max_thorax_gap_s: float = MAX_THORAX_GAP_S) -> ThoraxMotion | None:
    """The thorax's motion in the lab from the trial's thorax landmarks (module docstring); None
    when the protocol has none (the data are already thorax-fixed: the thorax is assumed still)."""
    from exubio.prep.targets import spline_derivatives

    if protocol.thorax_frame.is_identity:
        return None
    src = trajectories.source or "trajectories"
    match = resolve_labels(protocol, trajectories.labels, source=trajectories.source)
    landmarks = lab_landmarks(trajectories, protocol, match, max_thorax_gap_s=max_thorax_gap_s)
    keys = list(landmarks)
    pos = np.stack([landmarks[k] for k in keys], axis=1)
    labels = [getattr(protocol.thorax_frame, k) for k in keys]
    applied = {}
    if protocol.cutoff_hz is not None:
        pos, applied = filter_markers(pos, labels, protocol, trajectories.rate_hz, src)
    try:
        p, v, a = spline_derivatives(trajectories.time_s, pos)
    except InputError as exc:
        raise InputError(f"{src}: {exc}") from None
    split = [{k: arr[:, j] for j, k in enumerate(keys)} for arr in (p, v, a)]
    try:
        R, origin = thorax_frame(*isb_landmarks(split[0]))
    except InputError as exc:
        raise InputError(f"{src}: {exc}") from None
    R, w, wd = frame_derivatives(isb_landmarks(split[0]), isb_landmarks(split[1]), isb_landmarks(split[2]))
    gravity, how = lab_gravity(R, lab_up, source=src)
    cut = ", ".join(f"{n} {c:g}" for n, c in applied.items()) or "none"
    source = (f"measured from the thorax landmarks {labels} of {src} (low-pass as the markers: {cut} Hz; cubic-spline "
              f"derivatives); {how}")
    return ThoraxMotion(time_s=np.asarray(trajectories.time_s, dtype=float), rotation=R, origin_m=origin,
                        velocity_m_s=isb_landmarks(split[1])[0], acceleration_m_s2=isb_landmarks(split[2])[0],
                        angular_velocity_rad_s=w, angular_acceleration_rad_s2=wd, gravity_m_s2=gravity, source=source,
                        mirrored=protocol.side == "left")
