"""A simulated trunk that moves in the lab: the thorax leans (or turns) about a point below IJ in
step with the arm's elevation cycles, so the thorax-fixed arm motion of exubio.synth.simulate is
carried by an accelerating, rotating thorax. Exact: the lean angle is analytic,

    phi(t) = angle (1 - cos(2 pi t / cycle_s)) / 2     (0 at rest, ``angle`` at the top of each raise)

about a thorax axis a (``axis``: lateral = +X, the trunk leaning towards the arm's side; forward =
+Z; turn = +Y) through the pivot p (thorax coordinates of the rest posture, default 0.45 m below IJ):

    R_T(t) = R_0 Rot(a, phi),   o_T(t) = o_0 + R_0 (p - Rot(a, phi) p),
    w = R_0 a phi',   w' = R_0 a phi'',   o_T'' = -R_0 ([a phi''] + [a phi']^2) Rot(a, phi) p

with (R_0, o_0) the trial's lab transform at rest. ``thorax_sta_mm``: a skin artefact of the four
thorax markers driven by the lean (each its own random direction fixed in the thorax, amplitude
thorax_sta_mm x phi/angle), for the cost of a thorax tracked by skin markers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.dynamics.thorax_motion import STANDARD_GRAVITY_M_S2, ThoraxMotion
from exubio.errors import InputError
from exubio.model.kinematics import axis_rotation

__all__ = ["LEAN_AXES", "ThoraxLean", "add_lean_arguments", "lean_from_args", "lean_motion", "thorax_skin_artefact"]

LEAN_AXES = {"lateral": np.array([1.0, 0.0, 0.0]), "forward": np.array([0.0, 0.0, 1.0]),
             "turn": np.array([0.0, 1.0, 0.0])}
PIVOT_M = (0.0, -0.45, 0.0)


@dataclass(frozen=True)
class ThoraxLean:
    angle_deg: float = 20.0
    axis: str = "lateral"
    pivot_m: tuple[float, float, float] = PIVOT_M
    thorax_sta_mm: float = 0.0

    def __post_init__(self):
        if self.axis not in LEAN_AXES:
            raise InputError(f"thorax lean axis '{self.axis}': expected one of {list(LEAN_AXES)}")
        if not (np.isfinite(self.angle_deg) and np.isfinite(self.thorax_sta_mm) and self.thorax_sta_mm >= 0):
            raise InputError(f"thorax lean: angle {self.angle_deg} deg and thorax STA {self.thorax_sta_mm} mm must be "
                             f"finite (the STA >= 0)")

    def describe(self) -> str:
        return (f"thorax leaning {self.angle_deg:g} deg ({self.axis}, about a point {-self.pivot_m[1]:g} m below IJ) "
                f"in step with the raise" + (f", thorax-marker STA {self.thorax_sta_mm:g} mm" if self.thorax_sta_mm else ""))


def _phi(lean: ThoraxLean, t: np.ndarray, cycle_s: float):
    w = 2.0 * np.pi / cycle_s
    a = np.radians(lean.angle_deg)
    return a * (1 - np.cos(w * t)) / 2, a * w * np.sin(w * t) / 2, a * w * w * np.cos(w * t) / 2


def lean_motion(lean: ThoraxLean, t: np.ndarray, cycle_s: float, R0: np.ndarray, o0: np.ndarray) -> ThoraxMotion:
    """The exact ThoraxMotion in the lab (module docstring); gravity -Z of the lab (Z up)."""
    t = np.asarray(t, dtype=float)
    axis = LEAN_AXES[lean.axis]
    phi, phid, phidd = _phi(lean, t, cycle_s)
    Rl = axis_rotation(axis, phi)
    p = np.asarray(lean.pivot_m, dtype=float)
    Rp = Rl @ p  # (n, 3)
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    v = -(phid[:, None] * (Rp @ K.T))
    acc = -(phidd[:, None] * (Rp @ K.T) + (phid ** 2)[:, None] * (Rp @ (K @ K).T))
    up = R0[:, 1]  # the thorax's Y at rest is the lab's up
    return ThoraxMotion(time_s=t, rotation=R0 @ Rl, origin_m=o0 + (p - Rp) @ R0.T, velocity_m_s=v @ R0.T,
                        acceleration_m_s2=acc @ R0.T, angular_velocity_rad_s=np.outer(phid, R0 @ axis),
                        angular_acceleration_rad_s2=np.outer(phidd, R0 @ axis),
                        gravity_m_s2=-STANDARD_GRAVITY_M_S2 * up, source=f"exact, simulated: {lean.describe()}")


def thorax_skin_artefact(lean: ThoraxLean, t: np.ndarray, cycle_s: float, segs, rng: np.random.Generator) -> np.ndarray:
    """(n, k, 3) thorax-frame artefact of the thorax markers (module docstring), zero elsewhere."""
    out = np.zeros((t.size, len(segs), 3))
    if lean.thorax_sta_mm == 0 or lean.angle_deg == 0:
        return out
    profile = _phi(lean, t, cycle_s)[0] / np.radians(lean.angle_deg)
    for i, seg in enumerate(segs):
        d = rng.normal(size=3)
        if seg == "thorax":
            out[:, i] = 1e-3 * lean.thorax_sta_mm * profile[:, None] * (d / np.linalg.norm(d))
    return out


def add_lean_arguments(parser) -> None:
    """``exubio simulate``'s options of a leaning trunk."""
    parser.add_argument("--thorax-lean-deg", type=float, default=0.0, help="the trunk leans this much (deg) in step with "
                        "each raise, about a point 0.45 m below IJ (default 0: the thorax still); with --body-mass the "
                        "truth moments include the thorax's exact motion")
    parser.add_argument("--thorax-lean-axis", default="lateral", choices=sorted(LEAN_AXES),
                        help="lateral (towards the arm's side, default), forward, or turn (about the vertical)")
    parser.add_argument("--thorax-sta-mm", type=float, default=0.0,
                        help="skin artefact of the thorax markers, mm, driven by the lean (default 0)")


def lean_from_args(args) -> ThoraxLean | None:
    angle = float(getattr(args, "thorax_lean_deg", 0.0) or 0.0)
    if angle == 0.0:
        return None
    return ThoraxLean(angle_deg=angle, axis=args.thorax_lean_axis, thorax_sta_mm=float(args.thorax_sta_mm or 0.0))
