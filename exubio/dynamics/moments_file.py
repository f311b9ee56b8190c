"""The joint-moment files: ``<stem>.<method>.moments.csv`` (a reconstruction's) and
``<stem>.truth_moments.csv`` (a simulated trial's exact ones), one format: ``#`` lines stating the
frames, the sign, the inertia source, body mass, hand load and where q'' came from, then
``time_s,<columns of exubio.dynamics.moments>``, one row per frame, SI units (N m, N m/kg, N)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from exubio.dynamics.moments import Moments
from exubio.errors import InputError
from exubio.io.results import atomic_write

__all__ = ["HEADER", "write_moments_csv", "read_moments_csv"]

HEADER = (
    "net joint moments: the moment the proximal segment applies to the distal one about the joint centre "
    "(muscles and ligaments together), N m; positive about each axis by the right-hand rule",
    "<joint>_<X|Y|Z>_moment_Nm: in the distal segment's ISB frame (GH: humerus, Wu et al. 2005 option 1; elbow: "
    "forearm frame on the ulna; forearm: that frame on the radius; wrist: hand frame), X anterior, Y towards the "
    "proximal joint, Z right in the anatomical posture",
    "elbow_flexion/forearm_pronation/wrist_flexion/wrist_radial_deviation_moment_Nm: about the joint's own axis, "
    "positive towards the named motion; *_per_kg: divided by the body mass",
    "<coordinate>_generalized_force_Nm: the open chain's generalized forces; <sc|ac coordinate>_joint_torque_Nm: "
    "after the scapulothoracic contact's least-squares share; <point>_contact_normal_N: the thorax's push on the "
    "scapula along the ellipsoid's outward normal (> 0 compression)",
)


def write_moments_csv(path: str | os.PathLike, moments: Moments, /, *, comments: Sequence[str] = ()) -> Path:
    """Write ``moments`` at ``path`` (atomically), the header lines of HEADER, the inertia source,
    body mass, hand load and ``comments`` first."""
    path = Path(path)
    lines = [*HEADER, f"inertia: {moments.inertia_source}",
             f"body mass {moments.body_mass_kg:g} kg; hand load {moments.hand_load_kg:g} kg (a point mass at the "
             f"hand's centre of mass)", *comments]
    head = "".join(f"# {c}\n" for c in lines) + ",".join(("time_s",) + tuple(moments.columns)) + "\n"
    table = np.column_stack([moments.time_s, moments.values])

    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as f:
            f.write(head)
            np.savetxt(f, table, fmt="%.9g", delimiter=",")

    return atomic_write(path, writer)


def read_moments_csv(path: str | os.PathLike, /) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """(time_s (n,), columns, values (n, k)) of a file of ``write_moments_csv``."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the moments file ({exc.strerror or exc})") from None
    body = [line for line in lines if not line.startswith("#")]
    if not body or body[0].split(",")[0] != "time_s":
        raise InputError(f"{path}: expected a header line starting with 'time_s' after the '#' lines")
    columns = tuple(body[0].split(",")[1:])
    try:
        table = np.array([[float(x) for x in line.split(",")] for line in body[1:] if line.strip()], dtype=float)
    except ValueError as exc:
        raise InputError(f"{path}: a row is not numbers: {exc}") from None
    table = table.reshape(-1, len(columns) + 1)
    return table[:, 0], columns, table[:, 1:]
