"""Net joint moments of a reconstruction, named like the angles: the table exubio writes as
``<stem>.<method>.moments.csv`` and returns from ``exubio.moments``.

Columns (SI; the net moment is the one the proximal segment applies to the distal one about the
joint centre, muscles and ligaments together; positive about the axis by the right-hand rule):
- ``<joint>_<X|Y|Z>_moment_Nm`` for GH, elbow, forearm, wrist: the 3D net moment in the distal
  segment's ISB frame (GH: the humerus, Wu et al. 2005 option 1; elbow: the forearm frame on the
  ulna; forearm: that frame carried by the radius; wrist: the hand frame; X anterior, Y along the
  segment towards the proximal joint, Z right in the anatomical posture);
- ``elbow_flexion_moment_Nm``, ``forearm_pronation_moment_Nm``, ``wrist_flexion_moment_Nm``,
  ``wrist_radial_deviation_moment_Nm``: about the joint's own anatomical axis (the model's
  coordinate: these are its generalized forces), positive in the direction of the named motion;
- every moment column above again as ``..._Nm_per_kg`` (divided by the body mass);
- ``<coordinate>_generalized_force_Nm``: every coordinate of the open chain (what biorbd's and
  OpenSim's inverse dynamics give for the same q, q', q'');
- ``<girdle coordinate>_joint_torque_Nm``: the SC and AC coordinates once the scapulothoracic
  contact has taken its share (exubio.dynamics.newton_euler.girdle_split);
- ``<point>_contact_normal_N``: the thorax's push on the scapula at each ellipsoid contact point
  (TS, AI), along the ellipsoid's outward normal, > 0 compression.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from exubio.dynamics.inertia import INERTIA_SOURCE, dynamics_model, isb_segment_frames
from exubio.dynamics.loads import ExternalLoad, load_wrenches
from exubio.dynamics.newton_euler import girdle_split, inverse_dynamics
from exubio.dynamics.thorax_motion import ThoraxMotion
from exubio.model.kinematics import Kinematics
from exubio.types import Model

__all__ = ["JOINTS", "AXIS_MOMENTS", "THORAX_STILL", "Moments", "joint_moments", "moments_summary",
           "reconstruction_moments", "thorax_statement"]

JOINTS: dict[str, tuple[str, str]] = {"GH": ("humerus", "humerus"), "elbow": ("ulna", "ulna"),
                                      "forearm": ("radius", "ulna"), "wrist": ("hand", "hand")}
"""Joint -> (distal segment, the segment whose ISB frame (reference posture) the moment is in)."""

AXIS_MOMENTS: dict[str, str] = {"elbow_flexion": "elbow_flexion", "forearm_pronation": "pronation",
                                "wrist_flexion": "wrist_flexion", "wrist_radial_deviation": "wrist_radial_deviation"}
"""Anatomical moment -> the model coordinate whose axis it is about."""

GIRDLE_SEGMENTS = ("clavicle", "scapula")

THORAX_STILL = ("thorax assumed still in the lab and upright (gravity -Y of the thorax frame): no thorax motion was "
                "given (a trial without thorax markers placing it in the lab, or a simulation whose trunk does not move)")


def thorax_statement(thorax: ThoraxMotion | None, /) -> str:
    """The line the moments file and summary give of the thorax's motion."""
    if thorax is None:
        return THORAX_STILL
    return ("thorax motion in the lab included: its origin's acceleration, angular velocity and acceleration and gravity, "
            f"in the thorax frame, enter every segment's acceleration; {thorax.source}")


@dataclass(frozen=True)
class Moments:
    """The moment table of one reconstruction: time (n,), columns, values (n, k) SI, and what
    they rest on (body mass, hand load, inertia source, PF's inertia scale where PF made q'')."""

    time_s: np.ndarray
    columns: tuple[str, ...]
    values: np.ndarray
    body_mass_kg: float
    hand_load_kg: float
    inertia_source: str = INERTIA_SOURCE
    info: dict = field(default_factory=dict)
    thorax: ThoraxMotion | None = None  # the thorax's motion in the lab the moments include (None: assumed still)
    loads: tuple[ExternalLoad, ...] = ()  # external loads the moments include

    def column(self, name: str) -> np.ndarray:
        return self.values[:, self.columns.index(name)]

    def peaks(self) -> dict[str, float]:
        """Largest |value| of every N m and N column (NaN frames left out)."""
        return {c: float(np.nanmax(np.abs(self.values[:, j]))) if np.isfinite(self.values[:, j]).any() else float("nan")
                for j, c in enumerate(self.columns) if c.endswith(("_Nm", "_N"))}


def joint_moments(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, /, *, time_s: np.ndarray | None = None,
                  hand_load_kg: float = 0.0, dynamic_model: Model | None = None, thorax: ThoraxMotion | None = None,
                  loads: tuple[ExternalLoad, ...] | list[ExternalLoad] = ()) -> Moments:
    """The moment table (module docstring) of q, q', q'' (n, m) on ``model`` (its lengths and body
    mass; the inertia is Dumas et al. 2007's, exubio.dynamics.inertia, or ``dynamic_model``'s);
    ``thorax``: the thorax's motion in the lab on the same frames (None: still and upright);
    ``loads``: external loads on the same frames (exubio.dynamics.loads)."""
    dyn = dynamics_model(model, hand_load_kg=hand_load_kg) if dynamic_model is None else dynamic_model
    kin = Kinematics(dyn)
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    external = None
    if loads:
        fr = kin.frames(q)
        external = load_wrenches(loads, dyn.segment_names, fr.R, fr.p, None if thorax is None else thorax.rotation,
                                 mirrored=bool(thorax is not None and thorax.mirrored))
    res = inverse_dynamics(kin, q, qd, qdd, frame=None if thorax is None else thorax.frame_terms(), external=external)
    frames = isb_segment_frames(model)
    cols: list[str] = []
    vals: list[np.ndarray] = []
    for joint, (seg, frame_of) in JOINTS.items():
        i = dyn.segment_index(seg)
        A = frames[frame_of][1]
        local = np.einsum("nji,nj->ni", res.R[:, i] @ A, res.joint_moment[:, i])  # (R A)^T M
        for k, axis in enumerate("XYZ"):
            cols.append(f"{joint}_{axis}_moment_Nm")
            vals.append(local[:, k])
    names = list(dyn.coordinate_names)
    for label, coord in AXIS_MOMENTS.items():
        cols.append(f"{label}_moment_Nm")
        vals.append(res.tau[:, names.index(coord)])
    n_moment = len(cols)
    mass = float(model.body_mass_kg)
    cols += [c + "_per_kg" for c in cols[:n_moment]]
    vals += [v / mass for v in vals[:n_moment]]
    for j, name in enumerate(names):
        cols.append(f"{name}_generalized_force_Nm")
        vals.append(res.tau[:, j])
    tau_joint, _, normal = girdle_split(kin, q, res.tau)
    girdle = [j for j in range(len(names)) if dyn.segments[kin.coordinate_segment[j]].name in GIRDLE_SEGMENTS]
    for j in girdle:
        cols.append(f"{names[j]}_joint_torque_Nm")
        vals.append(tau_joint[:, j])
    for k, point in enumerate(kin.contacts.names):
        cols.append(f"{point}_contact_normal_N")
        vals.append(normal[:, k])
    t = np.arange(q.shape[0], dtype=float) if time_s is None else np.asarray(time_s, dtype=float)
    return Moments(time_s=t, columns=tuple(cols), values=np.column_stack(vals), body_mass_kg=mass,
                   hand_load_kg=float(hand_load_kg), inertia_source=str(dyn.metadata.get("inertia_source", INERTIA_SOURCE)),
                   info={"thorax": thorax_statement(thorax)}, thorax=thorax, loads=tuple(loads))


def reconstruction_moments(model: Model, recon, /, *, hand_load_kg: float = 0.0, thorax: ThoraxMotion | None = None,
                           loads: tuple[ExternalLoad, ...] | list[ExternalLoad] = ()) -> Moments:
    """The moment table of a Reconstruction (its q, q', q'': PF's integrated ones, LS's from its
    smoothed marker derivatives), with what its q'' rests on in ``info``: the method and, for PF,
    the inertia scale of the segments the springs drove (never the inverse dynamics' inertia);
    ``thorax`` and ``loads`` as joint_moments."""
    moments = joint_moments(model, recon.q_rad, recon.qd_rad_s, recon.qdd_rad_s2, time_s=recon.time_s,
                            hand_load_kg=hand_load_kg, thorax=thorax, loads=loads)
    info: dict = {"method": recon.method, **moments.info}
    options = dict((recon.info or {}).get("options") or {})
    if "inertia_scale" in options:
        info["pf_inertia_scale"] = options["inertia_scale"]
        fallback = (recon.info or {}).get("fallback")
        if fallback:
            info["pf_inertia_scale"] = fallback.get("options", {}).get("inertia_scale", options["inertia_scale"])
            info["pf_fallback"] = "PF's first run stopped; its q'' comes from the fallback run with inertia x "
            info["pf_fallback"] += f"{info['pf_inertia_scale']:g}"
    return Moments(time_s=moments.time_s, columns=moments.columns, values=moments.values,
                   body_mass_kg=moments.body_mass_kg, hand_load_kg=moments.hand_load_kg,
                   inertia_source=moments.inertia_source, info=info, thorax=thorax, loads=moments.loads)


def moments_summary(moments: Moments, /) -> dict:
    """summary.json's "moments": peaks of the joint moments (N m) and contact forces (N), body
    mass, hand load, inertia source and where q'' came from."""
    peaks = moments.peaks()
    keep = {c: round(v, 4) for c, v in peaks.items()
            if c.endswith("_moment_Nm") or c.endswith("_contact_normal_N")}
    out = {"peak_abs": keep, "body_mass_kg": moments.body_mass_kg, "hand_load_kg": moments.hand_load_kg,
           "inertia_source": moments.inertia_source, **moments.info}
    if moments.loads:
        out["external_loads"] = [load.describe() for load in moments.loads]
    return out
