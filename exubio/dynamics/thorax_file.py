"""``<stem>.<method>.thorax.csv``: the thorax's pose and motion in the lab, frame by frame, that the
joint moments of the same result set include (written beside ``<stem>.<method>.moments.csv`` when
the trial has thorax markers): ``#`` lines defining the columns, then ``time_s`` and

- ``thorax_Z_flexion_deg, thorax_X_lateral_flexion_deg, thorax_Y_axial_rotation_deg``: the ISB
  thorax-to-lab angles (exubio.dynamics.thorax_motion.thorax_angles), degrees;
- ``origin_{x,y,z}_m``, ``origin_acceleration_{x,y,z}_m_s2``: IJ (the thorax frame's origin) and
  its acceleration, lab axes;
- ``angular_velocity_{x,y,z}_rad_s``, ``angular_acceleration_{x,y,z}_rad_s2``: the thorax frame's,
  lab axes."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from exubio.dynamics.thorax_motion import THORAX_ANGLE_COLUMNS, ThoraxMotion, thorax_angles
from exubio.io.results import atomic_write

__all__ = ["thorax_columns", "write_thorax_csv"]


def thorax_columns() -> tuple[str, ...]:
    xyz = "xyz"
    return (*THORAX_ANGLE_COLUMNS, *(f"origin_{a}_m" for a in xyz), *(f"origin_acceleration_{a}_m_s2" for a in xyz),
            *(f"angular_velocity_{a}_rad_s" for a in xyz), *(f"angular_acceleration_{a}_rad_s2" for a in xyz))


def write_thorax_csv(path: str | os.PathLike, motion: ThoraxMotion, /) -> Path:
    path = Path(path)
    g = np.asarray(motion.gravity_m_s2, dtype=float)
    head = [
        "the thorax in the lab (ISB thorax frame, Wu et al. 2005; origin IJ); lab axes are the trial file's",
        "thorax_*_deg: thorax relative to the global frame, ISB sequence Z-X'-Y'' (flexion + about Z, lateral flexion "
        "about X', axial rotation about Y''); global frame: Y up (against gravity), X the horizontal direction of the "
        "thorax's mean anterior axis over the trial, Z = X x Y",
        f"gravity in the lab: [{g[0]:.6g}, {g[1]:.6g}, {g[2]:.6g}] m/s^2; {motion.source}",
    ]
    table = np.column_stack([motion.time_s, np.degrees(thorax_angles(motion)), motion.origin_m, motion.acceleration_m_s2,
                             motion.angular_velocity_rad_s, motion.angular_acceleration_rad_s2])
    text = "".join(f"# {c}\n" for c in head) + ",".join(("time_s",) + thorax_columns()) + "\n"

    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
            np.savetxt(f, table, fmt="%.9g", delimiter=",")

    return atomic_write(path, writer)
