"""What the joint moments of a trial need besides its reconstruction, prepared once with the trial
(before any method runs, so a bad loads file stops the run at once, exit 2): the thorax's motion in
the lab (exubio.prep.thorax_motion) and the external loads on the trial's frames (exubio.prep.loads),
as a MomentRequest (exubio.prep.moment_options) asks."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exubio.dynamics.loads import ExternalLoad
from exubio.dynamics.thorax_motion import ThoraxMotion
from exubio.errors import InputError
from exubio.prep.loads import analog_load, read_loads_csv, resample_load
from exubio.prep.moment_options import MomentRequest
from exubio.prep.thorax_motion import measure_thorax_motion
from exubio.types import MarkerTargets, Model, Protocol, Trajectories

__all__ = ["MomentInputs", "moment_inputs"]


@dataclass(frozen=True)
class MomentInputs:
    thorax: ThoraxMotion | None = None  # None: the thorax is assumed still
    loads: tuple[ExternalLoad, ...] = ()


def _cutoff(protocol: Protocol, targets: MarkerTargets) -> float | None:
    if protocol.cutoff_hz is None:
        return None
    if isinstance(protocol.cutoff_hz, str):  # "auto": the median of the markers' own cut-offs
        applied = list(targets.cutoff_hz.values())
        return float(np.median(applied)) if applied else None
    return float(protocol.cutoff_hz)


def moment_inputs(trajectories: Trajectories, protocol: Protocol, targets: MarkerTargets, model: Model,
                  request: MomentRequest, /) -> MomentInputs:
    thorax = measure_thorax_motion(trajectories, protocol, lab_up=request.lab_up)
    cutoff = _cutoff(protocol, targets)
    raws = [read_loads_csv(p, segments=model.segment_names[1:]) for p in request.loads]
    if protocol.analog_loads:
        src = trajectories.source or ""
        if not src.lower().endswith(".c3d"):
            raise InputError(f"{protocol.source or protocol.name}: analog_loads: the trial {src or '(in memory)'} is not "
                             f"a C3D file; its analog channels cannot be read (give the loads with --loads)")
        raws += [analog_load(spec, src, protocol_source=protocol.source) for spec in protocol.analog_loads]
    loads = tuple(resample_load(raw, targets.time_s, cutoff_hz=cutoff, order=protocol.filter_order) for raw in raws)
    return MomentInputs(thorax=thorax, loads=loads)
