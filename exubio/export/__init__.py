"""Export an exubio Model to other tools' model files: OpenSim ``.osim`` (:func:`write_osim`) and
biorbd ``.bioMod`` (:func:`write_biomod`).

Both are plain text writers (no opensim or biorbd import). They reproduce exubio's forward
kinematics exactly (joint centres, rotation axes and sequence, segment frames, model points as
markers, mass, centre of mass and inertia), so that marker positions agree with
``exubio.model.kinematics.Kinematics`` for any posture. What neither format can express, the
scapulothoracic ellipsoid constraint, is stated in a comment at the top of each file: the exported
model is an open chain (13 free coordinates); postures reconstructed by exubio already satisfy the
constraint and replay exactly.

The pieces both writers share are in exubio.export.common. The thorax of the exported models (its
mass and the .osim's free joint to the ground, exubio's .mot carrying its six coordinates) is
exubio.export.thorax; a reconstruction's generalized forces as OpenSim's inverse dynamics tool
writes them (``<stem>.<method>.moments.sto``) are exubio.export.sto.
"""
from __future__ import annotations

from exubio.export.biomod import write_biomod
from exubio.export.common import marker_table
from exubio.export.osim import write_osim

__all__ = ["marker_table", "write_biomod", "write_osim"]
