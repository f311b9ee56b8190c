"""The thorax of the exported models: its mass and a free (6-DOF) joint to the ground, so that
OpenSim's inverse dynamics tool (and biorbd) run on exubio's .mot with the trunk's own motion.

Free joint (OpenSim's gait models' names for a free root): ``thorax_tilt`` about Z, then
``thorax_list`` about the once-turned X, then ``thorax_rotation`` about the twice-turned Y (rad;
ISB's thorax-to-global sequence Z-X'-Y'', Wu et al. 2005), ``thorax_tx``, ``thorax_ty``,
``thorax_tz`` (m, along the ground's axes): the thorax frame (ISB, origin IJ) in the ground is
R = Rz(tilt) Rx(list) Ry(rotation), origin (tx, ty, tz). The ground's gravity is -Y: with every
thorax coordinate 0 the ground is exubio's thorax frame, upright, exactly the thorax-fixed model
exubio's own inverse dynamics assumes (a trial without the trunk's motion: the .mot's thorax
columns are 0, constant).

Thorax inertia, when the model gives the thorax none (the shipped model: its thorax is fixed and
massless): Seth et al. (2019) thoracoscapular model (the subject model the model file cites, ../shared/
data/models/rmr_TSM_subject_noWeight.osim), scaled the way the model file scales that model's
clavicle and scapula (by the humerus: mass fraction 0.028 x 20.8666 / 1.7650 kg = 0.3310 of body
mass); its centre of mass and tensor expressed in the ISB thorax frame
of that model's IJ, C7, PX, T8 (computed with models/sources/tsm_geometry.py's forward kinematics
and isb_thorax_frame: centre of mass (-86.2, -138.3, 0.4) mm from IJ), the tensor scaled by mass.
The arm's generalized forces do not depend on it; the thorax's six do (they are the whole body's
residual wrench at the thorax: what the lower body and the chair must supply).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from exubio.model.angles import euler_angles
from exubio.types import Model

__all__ = ["THORAX_COORDINATES", "THORAX_ROTATION_AXES", "THORAX_TRANSLATIONS", "thorax_coordinates",
           "thorax_mot_columns", "thorax_pose", "with_thorax_inertia"]

THORAX_COORDINATES = ("thorax_tilt", "thorax_list", "thorax_rotation", "thorax_tx", "thorax_ty", "thorax_tz")
THORAX_ROTATION_AXES = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # Z, X', Y''
THORAX_TRANSLATIONS = THORAX_COORDINATES[3:]
THORAX_SEQUENCE = "ZXY"

THORAX_MASS_FRACTION = 0.028 * 20.866630055554726 / 1.7650184258291826
"""Seth et al. 2019's thorax mass scaled by the humerus, as the model file scales their clavicle and scapula."""
THORAX_COM_M = np.array([-0.08624, -0.13826, 0.00039])
"""Centre of mass in the ISB thorax frame (origin IJ), Seth et al. 2019's subject model."""
THORAX_INERTIA_PER_KG = np.array([[1.00434, -0.07528, 0.0003], [-0.07528, 0.44147, 0.0023],
                                  [0.0003, 0.0023, 1.01422]]) / 20.866630055554726
"""Tensor about the centre of mass, ISB thorax axes, per kg of thorax (Seth et al. 2019: kg m^2 / 20.8666 kg)."""


def with_thorax_inertia(model: Model, /) -> Model:
    """``model`` with the thorax's mass, centre of mass and tensor of the module docstring when it
    gives the thorax none (mass 0); as it is otherwise."""
    root = model.segments[0]
    if root.mass_kg > 0:
        return model
    mass = THORAX_MASS_FRACTION * float(model.body_mass_kg)
    root = dataclasses.replace(root, mass_kg=mass, com_m=THORAX_COM_M.copy(), inertia_kgm2=mass * THORAX_INERTIA_PER_KG)
    metadata = {**dict(model.metadata), "thorax_inertia_source": "Seth et al. 2019 thoracoscapular model, scaled "
                "(exubio.export.thorax)"}
    return dataclasses.replace(model, segments=(root, *model.segments[1:]), metadata=metadata)


def thorax_coordinates(R: np.ndarray, origin: np.ndarray, /) -> np.ndarray:
    """(n, 6) free-joint coordinates (tilt, list, rotation rad; tx, ty, tz m) of thorax poses in the
    ground: ``R`` (n, 3, 3) columns the thorax's ISB axes, ``origin`` (n, 3) IJ, both in a ground
    frame whose Y is up (the .osim's gravity is -Y: a lab with Z up is turned onto it first)."""
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    return np.column_stack([euler_angles(R, THORAX_SEQUENCE), np.asarray(origin, dtype=float).reshape(-1, 3)])


def lab_thorax_coordinates(R_lab: np.ndarray, origin_lab: np.ndarray, gravity_lab: np.ndarray, /) -> np.ndarray:
    """(n, 6) free-joint coordinates of a thorax measured in a lab (``R_lab`` (n, 3, 3) its ISB axes,
    ``origin_lab`` (n, 3) m, ``gravity_lab`` (3,) m/s^2, all in lab coordinates): the lab is first
    turned onto a ground whose Y is up (-gravity) and whose X is the lab X (or Y, when X is
    vertical) made horizontal, as the exported .osim's gravity (-Y) wants."""
    up = -np.asarray(gravity_lab, dtype=float)
    up /= np.linalg.norm(up)
    first = np.eye(3)[0] if abs(up[0]) < 0.9 else np.eye(3)[1]
    x = first - up * (first @ up)
    x /= np.linalg.norm(x)
    G = np.stack([x, up, np.cross(x, up)])  # rows: the ground's axes in lab coordinates
    R = np.einsum("ij,njk->nik", G, np.asarray(R_lab, dtype=float).reshape(-1, 3, 3))
    return thorax_coordinates(R, np.asarray(origin_lab, dtype=float).reshape(-1, 3) @ G.T)


def thorax_pose(coordinates: np.ndarray, /) -> tuple[np.ndarray, np.ndarray]:
    """(R (n, 3, 3), origin (n, 3)) of free-joint coordinates (n, 6): the inverse of thorax_coordinates."""
    c = np.atleast_2d(np.asarray(coordinates, dtype=float))

    def rot(axis: np.ndarray, a: np.ndarray) -> np.ndarray:
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        s, co = np.sin(a)[:, None, None], np.cos(a)[:, None, None]
        return np.eye(3) + s * K + (1 - co) * (K @ K)

    R = rot(THORAX_ROTATION_AXES[0], c[:, 0]) @ rot(THORAX_ROTATION_AXES[1], c[:, 1]) @ rot(THORAX_ROTATION_AXES[2], c[:, 2])
    return R, c[:, 3:6].copy()


def thorax_mot_columns(n_frames: int, coordinates: np.ndarray | None = None, /) -> tuple[tuple[str, ...], np.ndarray]:
    """(names, values (n, 6)) of the .mot's thorax columns: ``coordinates`` (thorax_coordinates of
    the trunk's motion in the lab) or, without them, 0 (constant: the thorax-fixed model)."""
    values = np.zeros((n_frames, 6)) if coordinates is None else np.asarray(coordinates, dtype=float).reshape(n_frames, 6)
    return THORAX_COORDINATES, values
