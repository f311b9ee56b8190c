"""The binding of a model and a protocol: what is computed from the two alone, once per session
(per calibrated model) and carried by it (exubio.run.inputs.Session) to every trial, method and
check: the model's kinematics, the tracked model points of the protocol's markers, the coordinates
the protocol holds, the segments no marker observes and the coordinates neither method solves.

The facts an upper layer derives from the pair alone (the reference postures of exubio.synth, the
structural angle status and the label expectations of exubio.trust) are kept on the binding too
(:meth:`Binding.fact`, :meth:`Binding.keep`): computed by their own module on first use, which
then leaves them on this binding for its life (no content-hash cache: the object that carries
them is the one they belong to; and the binding never calls up into the module that computes them).

It sits in the protocol layer, the lowest that holds both a Model and a Protocol, so that the
Exudyn backend and the methods below the trust layer take it (exubio.backend.exudyn_system.PFSystem,
exubio.methods.pf and .ls) without climbing. Frozen and picklable: it travels to pool and Dask
workers inside the Session, with the facts computed so far (the kinematics, rebuilt in well under a
millisecond, is not pickled)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Hashable, TypeVar

import numpy as np

from exubio.model.kinematics import Kinematics, PointSet
from exubio.types import Model, Protocol

__all__ = ["Binding", "bind", "held_mask", "tracked_points", "unobserved_segments"]

T = TypeVar("T")

_REBUILT = ("kin", "points")  # cheap to rebuild: left out of the pickle


def tracked_points(kin: Kinematics, protocol: Protocol, /) -> PointSet:
    """The segment-fixed model point R_i of every protocol marker, in protocol order (on ``kin``'s
    model: a scaled model during a calibration, else the binding's, :attr:`Binding.points`)."""
    return PointSet(
        segment_index=np.array([kin.model.segment_index(m.segment) for m in protocol.markers], dtype=int),
        local_m=np.array([np.asarray(m.local_position_m, dtype=float) for m in protocol.markers]).reshape(-1, 3),
        names=protocol.marker_names,
    )


def held_mask(model: Model, protocol: Protocol, /) -> np.ndarray:
    """(m,) True for the coordinates the protocol holds at 0 (not observable with its markers)."""
    names = model.coordinate_names
    return np.array([n in protocol.held_coordinates for n in names], dtype=bool)


def unobserved_segments(kin: Kinematics, points: PointSet, /) -> tuple[int, ...]:
    """Segments with no tracked marker on them or on any segment they carry: no spring can move
    them, so their joints are locked at the start posture (a marker set without forearm or hand
    markers, e.g. the thoracoscapular TRC set, leaves elbow, forearm and wrist unobserved)."""
    observed = set()
    for s in set(int(i) for i in points.segment_index):
        while s >= 0 and s not in observed:
            observed.add(s)
            s = int(kin.parent_index[s])
    return tuple(i for i in range(1, kin.n_segments) if i not in observed)


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)  # shared by every trial of the session: a caller copies before it changes one
    return a


@dataclass(frozen=True, eq=False)
class Binding:
    """A model and the protocol bound to it (its markers' local positions are the model's points),
    with what follows from the two alone, each computed on first use and then held (module
    docstring). Two bindings are equal only when they are the same object."""

    model: Model
    protocol: Protocol
    _facts: dict = dataclasses.field(default_factory=dict, init=False, repr=False, compare=False)
    _model_facts: dict = dataclasses.field(default_factory=dict, init=False, repr=False, compare=False)

    @cached_property
    def kin(self) -> Kinematics:
        """The model's numpy kinematics (exubio.model.kinematics)."""
        return Kinematics(self.model)

    @cached_property
    def points(self) -> PointSet:
        """The tracked model point of every protocol marker, in protocol order."""
        return tracked_points(self.kin, self.protocol)

    @cached_property
    def held(self) -> np.ndarray:
        """(m,) read-only: True for the coordinates the protocol holds at 0."""
        return _read_only(held_mask(self.model, self.protocol))

    @cached_property
    def unobserved(self) -> tuple[int, ...]:
        """The segments no marker observes (their joints are locked at the start posture)."""
        return unobserved_segments(self.kin, self.points)

    @cached_property
    def not_solved(self) -> np.ndarray:
        """(m,) read-only: True for the coordinates neither method solves: held by the protocol, or
        of a segment no marker observes (locked)."""
        mask = self.held.copy()
        for s in self.unobserved:
            mask[self.kin.joint_coordinate_indices(s)] = True
        return _read_only(mask)

    @property
    def locked(self) -> np.ndarray:
        """(m,) the coordinates of unobserved segments that the protocol does not hold."""
        return self.not_solved & ~self.held

    @property
    def not_solved_names(self) -> tuple[str, ...]:
        return tuple(n for n, e in zip(self.model.coordinate_names, self.not_solved) if e)

    def fact(self, key: Hashable, /, *, of_model: bool = False) -> Any:
        """The fact ``key`` an upper layer left on this binding (:meth:`keep`), or None (not yet).
        ``of_model``: a fact of the model alone (the reference postures), shared with the bindings of
        the same model to other protocols (:meth:`rebound`)."""
        return (self._model_facts if of_model else self._facts).get(key)

    def keep(self, key: Hashable, value: T, /, *, of_model: bool = False) -> T:
        """Leave ``value``, a fact of the model and protocol alone that an upper layer computed
        (exubio.trust.assess, .label_expectations), on this binding under ``key``; returns it."""
        (self._model_facts if of_model else self._facts)[key] = value
        return value

    def rebound(self, protocol: Protocol, /) -> "Binding":
        """The same model bound to ``protocol`` (e.g. with a marker the trial lacks made optional):
        it shares the facts of the model alone (:meth:`keep` with ``of_model``)."""
        if protocol is self.protocol:
            return self
        out = Binding(self.model, protocol)
        object.__setattr__(out, "_model_facts", self._model_facts)
        return out

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in _REBUILT}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)


def bind(model: Model, protocol: Protocol, /) -> Binding:
    """The binding of ``model`` and ``protocol`` (a protocol loaded against that model:
    exubio.run.inputs.protocol_for_model)."""
    return Binding(model, protocol)
