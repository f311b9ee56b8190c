"""The offline causal run of a trial (reconstruct_causal): the live loop (exubio.run.live.loop) on
an in-process replay, so that a trial's causal angles can be computed, and checked, without a
stream."""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

from exubio.run.live.loop import LiveSession, SessionHooks
from exubio.run.live.options import LiveOptions
from exubio.run.live.outputs import LiveRecording
from exubio.run.live.sources import ReplaySource
from exubio.types import Model, Protocol, Trajectories

__all__ = ["reconstruct_causal"]


def reconstruct_causal(trial: Trajectories, model: Model, protocol: Protocol, /, *,
                       options: LiveOptions = LiveOptions(), static_frames: slice | None = None,
                       calibrate: Callable | None = None, faults=None) -> LiveRecording:
    """The offline causal PF reconstruction of a trial: the live loop itself, fed by an in-process
    replay of the trial as fast as it goes (no network, no clock), so ``exubio live`` on a replay of
    the same trial gives the same angles (to round-off: the same operations on the same numbers)."""
    from exubio.run.live.sources import Faults

    source = ReplaySource(trial, speed=None, faults=faults or Faults())
    opts = dataclasses.replace(options, end_after_s=None, max_behind_s=math.inf, stall_s=math.inf)  # no clock
    return LiveSession(model, protocol, source, options=opts, static_frames=static_frames,
                       hooks=SessionHooks(calibrate=calibrate)).run()
