"""A session's inputs, each file parsed once: the model, the protocol bound to it and, for a
calibrated model, the generic model it was made from with the protocol bound to that (what the
label checks expect: a calibration registers every marker where the static trial had it, right or
wrong). Loaders run here, at the top of a run; everything below takes the objects."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from exubio.calibration import calibrated_protocol
from exubio.errors import ProtocolError
from exubio.io.resources import shipped_file
from exubio.model.load import DEFAULT_MODEL, load_model
from exubio.protocol.bind import Binding
from exubio.protocol.load import check_landmarks, load_protocol
from exubio.types import Model, Protocol

DEFAULT_PROTOCOL = shipped_file("exubio.protocols", "upper_limb_21.yaml", "protocols")


@dataclass(frozen=True)
class Session:
    """What a session's trials are reconstructed with (``model``, ``protocol``) and what their labels
    are checked against (``generic_model``, ``generic_protocol``; the same objects when the model is
    not calibrated). Frozen and picklable: it travels to pool and Dask workers whole, with its
    bindings (``binding``, ``generic_binding``: exubio.protocol.bind) and what they hold so far."""

    model: Model
    protocol: Protocol
    generic_model: Model
    generic_protocol: Protocol

    @cached_property
    def binding(self) -> Binding:
        """The model bound to the protocol, built once per session (per calibrated model): every
        trial, method and check of the session takes it."""
        return Binding(self.model, self.protocol)

    @cached_property
    def generic_binding(self) -> Binding:
        """What the label checks expect: the generic model bound to its protocol (``binding`` itself
        when the model is not calibrated)."""
        if self.generic_model is self.model and self.generic_protocol is self.protocol:
            return self.binding
        return Binding(self.generic_model, self.generic_protocol)

    @property
    def calibrated(self) -> bool:
        return bool(self.model.metadata.get("calibration"))

    def with_model(self, model: Model, /) -> "Session":
        """This session with ``model``, calibrated from its generic model: the protocol rebound to
        the points the calibration registered (exubio.calibration.calibrated_protocol)."""
        return self.replaced(model=model, protocol=calibrated_protocol(self.generic_protocol, model))

    def replaced(self, **changes) -> "Session":
        """dataclasses.replace of this session; when the generic model and protocol stay, the new
        session keeps this one's generic binding and what it holds (the label expectations)."""
        out = dataclasses.replace(self, **changes)
        if not {"generic_model", "generic_protocol"} & set(changes) and "generic_binding" in self.__dict__:
            out.__dict__["generic_binding"] = self.__dict__["generic_binding"]  # a cached_property's slot
        return out

    def with_signs(self, signs: str | None, /) -> "Session":
        """This session writing its angles in ``signs`` (exubio.model.signs; None: the protocol's own
        ``signs`` key): set on both protocols, so a calibration's rebound protocol keeps it."""
        if signs is None:
            return self
        return dataclasses.replace(self, protocol=dataclasses.replace(self.protocol, signs=signs),
                                   generic_protocol=dataclasses.replace(self.generic_protocol, signs=signs))


def load_session(*, model_path: str | Path | None = None, protocol_path: str | Path | None = None,
                 body_mass_kg: float | None = None, signs: str | None = None) -> Session:
    """Read the model (default: the shipped generic one) and the protocol (default: the shipped
    21-marker one) once; a calibrated model brings its generic model (its recorded file, else the
    shipped one) with it. ``signs``: the written angles' sign convention over the protocol's
    ``signs`` key (--signs; None: the protocol's)."""
    model = load_model(model_path or DEFAULT_MODEL, body_mass_kg=body_mass_kg)
    calibration = model.metadata.get("calibration")
    if not calibration:
        protocol = protocol_for_model(model, protocol_path)
        return Session(model, protocol, model, protocol).with_signs(signs)
    generic = _generic_model(model)
    protocol = protocol_for_model(generic, protocol_path)
    return Session(generic, protocol, generic, protocol).with_signs(signs).with_model(model)


def _generic_model(calibrated: Model, /) -> Model:
    """The generic model a calibration started from: its recorded file, else the shipped one."""
    path = Path(str(calibrated.metadata["calibration"].get("generic_model") or ""))
    return load_model(path if path.is_file() else DEFAULT_MODEL, body_mass_kg=calibrated.body_mass_kg)


def generic_of(model: Model, protocol: Protocol, /) -> tuple[Model, Protocol]:
    """The generic model a calibrated model was made from (its recorded file, else the shipped one)
    and the protocol bound to it; ``model`` and ``protocol`` themselves when not calibrated."""
    if not model.metadata.get("calibration"):
        return model, protocol
    generic = _generic_model(model)
    return generic, protocol_for_model(generic, protocol.source or None)


def protocol_for_model(model: Model, protocol_path: str | Path | None = None, /) -> Protocol:
    """Load a protocol against a model; a calibrated model rebinds the markers to the points the
    calibration registered for them."""
    points = {s.name: dict(s.points) for s in model.segments}
    protocol = load_protocol(protocol_path or DEFAULT_PROTOCOL, segments=model.segment_names, model_points=points,
                             coordinates=model.coordinate_names)
    check_landmarks(protocol, points)
    check_held(model, protocol)
    if model.metadata.get("calibration"):
        protocol = calibrated_protocol(protocol, model)
    return protocol


def check_held(model: Model, protocol: Protocol, /) -> None:
    """Refuse (ProtocolError naming the protocol's ``hold`` key) a hold that leaves the methods
    nothing to solve: every coordinate held, or fewer coordinates free in the chain that moves the
    ellipsoid's contact points than there are contact constraints (they could not be met: a singular
    system in both methods)."""
    held = set(protocol.held_coordinates)
    names = model.coordinate_names
    where = f"{protocol.source or protocol.name}: hold"
    if names and held >= set(names):
        raise ProtocolError(f"{where}: holds every coordinate of the model ({len(names)}); nothing is left for the "
                            f"markers to determine: hold fewer (thoracoscapular_9 holds sc_posterior_rotation only)")
    by_name = {s.name: s for s in model.segments}
    for segment in sorted({seg for seg, _ in model.ellipsoid.contact_points}):
        chain, name = [], segment
        while name in by_name:
            s = by_name[name]
            chain = list(s.joint.coordinates if s.joint else ()) + chain
            name = s.parent
        free = [c for c in chain if c not in held]
        n_constraints = sum(seg == segment for seg, _ in model.ellipsoid.contact_points)
        if chain and len(free) < n_constraints:
            raise ProtocolError(
                f"{where}: leaves {len(free)} of the coordinates that move the {segment} free ({free or 'none'} of "
                f"{chain}); its {n_constraints} points on the thorax ellipsoid need at least {n_constraints}: hold fewer")


def load_model_and_protocol(*, model_path: str | Path | None = None, protocol_path: str | Path | None = None,
                            body_mass_kg: float | None = None) -> tuple[Model, Protocol]:
    """The model and the protocol bound to it (scripts and benchmarks; a run uses load_session)."""
    session = load_session(model_path=model_path, protocol_path=protocol_path, body_mass_kg=body_mass_kg)
    return session.model, session.protocol
