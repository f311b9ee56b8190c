"""Live reconstruction from a marker stream (issue 22): causal preprocessing (causal), the live
loop (loop; its settings in options, what it puts out (the output channels, the events, the
recording) in outputs, the samples it takes in in intake, its running checks and verdict in
monitor), the offline causal run on it (offline), marker sources (sources: the interface and an
in-process replay; transport: Lab Streaming Layer, the only pylsl user), the recording written as
``exubio reconstruct`` writes a trial (record), the terminal display (display) and what the two
commands do (app).

``exubio.run.live.reconstruct_causal(trial, model, protocol)`` is the offline causal PF run (the live
loop fed by an in-process replay); the names below load their module on first use (importing
``exubio.run.live`` loads no solver)."""
from __future__ import annotations

_LAZY = {"reconstruct_causal": "offline", "LiveOptions": "options", "LiveSession": "loop", "LiveRecording": "outputs",
         "Event": "outputs", "CausalOptions": "causal", "ReplaySource": "sources", "Faults": "sources",
         "StreamInfo": "sources", "write_recording": "record"}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f"exubio.run.live.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'exubio.run.live' has no attribute '{name}'")


def __dir__():
    return __all__
