"""What ``exubio live`` and ``exubio stream`` do, on loaded objects and plain arguments (the CLI
parses and prints; these functions log and return)."""
from __future__ import annotations

import logging
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from exubio.errors import InputError
from exubio.run.live.loop import LiveSession, SessionHooks
from exubio.run.live.options import LiveOptions
from exubio.run.live.outputs import OUTPUT_CHANNELS, Event, LiveRecording
from exubio.types import Model, Protocol, Trajectories

log = logging.getLogger(__name__)

__all__ = ["LiveRun", "calibrator", "run_live", "stream_file", "LINGER_S"]

LINGER_S = 1.0
"""``exubio stream`` keeps its outlet this long after the last frame (destroyed at once, the last
samples may never leave it)."""


@dataclass(frozen=True)
class LiveRun:
    recording: LiveRecording
    folder: Path | None


def calibrator(model: Model, protocol: Protocol, /) -> Callable[[Trajectories, slice], tuple[Model, Protocol, Any]]:
    """The calibration of the stream's first frames (``--static-frames``): exubio.calibration on
    those frames, the protocol rebound to the calibrated model."""
    def calibrate(traj: Trajectories, frames: slice):
        from exubio.calibration import calibrate_model, calibrated_protocol

        calibrated, report = calibrate_model(model, protocol, traj, frames=frames)
        return calibrated, calibrated_protocol(protocol, calibrated), report

    return calibrate


@dataclass(frozen=True)
class LiveOutput:
    """Where a live session goes: the recording into ``out_dir/name`` (None: kept in memory only),
    replaced only with ``overwrite``, with its trial ``report``; the angles published on LSL as
    ``publish_name`` (None: no output stream)."""

    out_dir: str | Path | None
    name: str
    publish_name: str | None = "exubio_angles"
    overwrite: bool = False
    report: bool = True


@dataclass(frozen=True)
class LiveControl:
    """How a live session is watched and ended: ``on_event`` / ``on_status`` callbacks (the console
    display), ``duration_s`` (stop after; None: when the stream ends), ``handle_sigint`` (the first
    Ctrl-C ends the session cleanly, a second one aborts)."""

    on_event: Callable[[Event], None] | None = None
    on_status: Callable[[dict], None] | None = None
    duration_s: float | None = None
    handle_sigint: bool = True


def run_live(model: Model, protocol: Protocol, source, output: LiveOutput, /, *, options: LiveOptions = LiveOptions(),
             static_frames: slice | None = None, control: LiveControl = LiveControl()) -> LiveRun:
    """Reconstruct ``source`` live, publish on LSL, and write the recording when the stream ends or
    on Ctrl-C (LiveOutput, LiveControl)."""
    out_dir, name, publish_name = output.out_dir, output.name, output.publish_name
    on_event, on_status = control.on_event, control.on_status
    publisher = None
    publisher_box: dict[str, Any] = {}

    def ready(session: LiveSession) -> None:
        if not publish_name:
            return
        from exubio.run.live.transport import LSLPublisher

        publisher_box["pub"] = LSLPublisher(
            publish_name, OUTPUT_CHANNELS(session.marker_names), session.rate,
            metadata={"model": session.model.source or session.model.name,
                      "protocol": session.protocol.source or session.protocol.name,
                      "input_stream": session.info.name,
                      "angles": "ISB (Wu et al. 2005) SC, AC, ST Y-X'-Z''; GH X-Z'-Y''; HT Y-X'-Y''; degrees",
                      "signs": session.protocol.signs,
                      "rates": "backward differences of the published angles (their sign flips with the angle's)",
                      "processing": options.causal.describe()},
            source_id=f"exubio-{session.info.source_id or session.info.name}")

    if publish_name:
        def publisher(row, ts):
            publisher_box["pub"](row, ts)

    def event(e: Event) -> None:
        pub = publisher_box.get("pub")
        if pub is not None:
            pub.event(e)
        if on_event is not None:
            on_event(e)

    clock = getattr(source, "clock", None)
    kwargs = {"clock": clock} if callable(clock) else {}
    hooks = SessionHooks(publish=publisher, on_event=event, on_status=on_status, on_ready=ready,
                         calibrate=calibrator(model, protocol) if static_frames is not None else None, **kwargs)
    session = LiveSession(model, protocol, source, options=options, hooks=hooks, static_frames=static_frames)
    timer = None
    if control.duration_s is not None:
        timer = threading.Timer(control.duration_s, session.stop)
        timer.daemon = True
        timer.start()
    previous = None
    if control.handle_sigint and threading.current_thread() is threading.main_thread():
        def on_sigint(signum, frame):  # noqa: ARG001
            if session._stop.is_set():
                raise KeyboardInterrupt
            session.stop()

        previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        rec = session.run()
    finally:
        if timer is not None:
            timer.cancel()
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        source.close()
    folder = None
    if out_dir is not None:
        from exubio.run.live.record import write_recording

        folder = write_recording(rec, out_dir, name, overwrite=output.overwrite, report=output.report)
    return LiveRun(rec, folder)


def stream_file(trial: Trajectories, /, *, name: str, speed: float = 1.0, units: str = "mm",
                source_id: str = "", wait_s: float = 10.0, stop: Callable[[], bool] | None = None) -> int:
    """Send a trial as an LSL marker stream at ``speed`` times its own rate; waits up to ``wait_s``
    for a consumer first. Returns the frames sent."""
    from exubio.run.live.transport import ReplayOutlet

    if not speed > 0:
        raise InputError(f"--speed must be > 0, got {speed}")
    out = ReplayOutlet(trial.labels, trial.rate_hz, name=name, units=units, source_id=source_id or f"exubio-replay-{name}")
    try:
        if wait_s > 0 and not out.wait_for_consumer(wait_s):
            log.warning("no consumer of stream '%s' after %g s; sending anyway", name, wait_s)
        sent = out.send(trial.positions_m, speed=speed, stop=stop)
        time.sleep(LINGER_S)  # the last samples reach the consumers before the outlet goes
        return sent
    finally:
        out.close()
