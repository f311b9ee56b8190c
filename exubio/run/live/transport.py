"""Lab Streaming Layer transport: the only module that imports pylsl.

Network. liblsl reads its configuration (``lsl_api.cfg``) once, when it is first used; the file
named by the ``LSLAPICFG`` environment variable comes first. ``use_config`` sets it before pylsl is
imported. ``LOOPBACK_CONFIG`` keeps every packet on this machine: IPv6 off, the ``machine``
resolve scope (its only multicast "address" is 127.0.0.1, TTL 0), 127.0.0.1 as the only address
and known peer, the multicast listener on 127.0.0.1. ``exubio live`` and ``exubio stream`` use it by
default (``--lsl-config loopback``); a lab whose camera PC streams over the network passes
``--lsl-config system`` (liblsl's own search: ./lsl_api.cfg, ~/lsl_api/lsl_api.cfg,
/etc/lsl_api/lsl_api.cfg) or the path of its own file. liblsl still *listens* on 0.0.0.0 (its
stream server's TCP and UDP ports 16572+): it accepts connections from elsewhere but, with this
configuration, sends nothing anywhere but 127.0.0.1.

Marker streams as the field sends them: one channel per coordinate, three per marker; the label of
a marker from its channels' labels (``LASI_X``, ``LASI.y``, ``LASI:Z``, ``LASIx``) or from a channel's
``marker``/``name`` field; the units from the channels' ``unit`` field (millimeters, mm, meters, m,
centimeters, cm; mm when absent, as Vicon, Qualisys and OptiTrack send).
"""
from __future__ import annotations

import json
import logging
import os
import re
import tempfile
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.io.records import to_json
from exubio.run.live.sources import StreamInfo

log = logging.getLogger(__name__)

__all__ = ["LOOPBACK_CONFIG", "use_config", "load_pylsl", "LSLSource", "LSLPublisher", "marker_stream_info",
           "LiveUnavailable", "ReplayOutlet"]

LOOPBACK_CONFIG = """\
; exubio: Lab Streaming Layer held to this machine (127.0.0.1 only)
[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
MachineAddresses = {127.0.0.1}
AddressesOverride = {127.0.0.1}
ListenAddress = 127.0.0.1
TTLOverride = 0
[lab]
KnownPeers = {127.0.0.1}
[log]
level = -3
"""

_pylsl: Any = None


class LiveUnavailable(InputError):
    """pylsl or its liblsl cannot be loaded (the live commands need it)."""


def use_config(config: str = "loopback", /) -> Path | None:
    """Point liblsl at a configuration before pylsl is imported: "loopback" (LOOPBACK_CONFIG, written
    to a per-user temporary file), "system" (liblsl's own search), or the path of a file. Returns
    the file used (None for "system"). Too late once pylsl is loaded with another file: InputError."""
    if config == "system":
        path = None
    elif config == "loopback":
        folder = Path(tempfile.gettempdir()) / f"exubio-lsl-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
        folder.mkdir(mode=0o700, exist_ok=True)
        path = folder / "lsl_api.cfg"
        if not path.is_file() or path.read_text() != LOOPBACK_CONFIG:
            tmp = folder / f".lsl_api.cfg.{os.getpid()}.tmp"
            tmp.write_text(LOOPBACK_CONFIG)
            os.replace(tmp, path)
    else:
        path = Path(config)
        if not path.is_file():
            raise InputError(f"{path}: no such LSL configuration file (--lsl-config: loopback, system or a path)")
    want = None if path is None else str(path)
    if _pylsl is not None:
        if os.environ.get("LSLAPICFG") != want:
            raise InputError("pylsl is already loaded with another LSL configuration; start a new process")
        return path
    if want is None:
        os.environ.pop("LSLAPICFG", None)
    else:
        os.environ["LSLAPICFG"] = want
    return path


def load_pylsl(config: str | None = None):
    """pylsl, imported once the configuration is set (``use_config``; default: loopback)."""
    global _pylsl
    if _pylsl is None:
        if config is not None or "LSLAPICFG" not in os.environ:
            use_config(config or "loopback")
        try:
            import pylsl
            pylsl.library_version()
        except Exception as exc:  # ImportError, or RuntimeError when its liblsl cannot be loaded
            raise LiveUnavailable(f"the live commands need pylsl with its liblsl ({type(exc).__name__}: {exc}); "
                                  "install it with: pip install 'exubio[live]'") from None
        _pylsl = pylsl
    return _pylsl


_UNITS = {"mm": "mm", "millimeters": "mm", "millimetres": "mm", "millimeter": "mm", "m": "m", "meters": "m",
          "metres": "m", "meter": "m", "cm": "cm", "centimeters": "cm", "centimetres": "cm"}
_AXIS = re.compile(r"^(?P<name>.+?)[_.:\- ]?(?P<axis>[xyzXYZ])$")


def _channels(info) -> list[dict[str, str]]:
    out = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        out.append({key: ch.child_value(key) for key in ("label", "unit", "marker", "name", "type")})
        ch = ch.next_sibling("channel")
    return out


def marker_labels(channels: Sequence[dict[str, str]], n_channels: int, stream: str, /) -> tuple[tuple[str, ...], str]:
    """Marker labels and units of a stream's channel descriptions (see the module docstring)."""
    if n_channels % 3:
        raise InputError(f"stream '{stream}': {n_channels} channels; a marker stream has three (x, y, z) per marker")
    if len(channels) != n_channels:
        raise InputError(f"stream '{stream}': its metadata describes {len(channels)} of {n_channels} channels; "
                         "the marker labels must be in desc/channels/channel/label")
    labels = []
    for m in range(n_channels // 3):
        names, axes = set(), []
        for c in channels[3 * m:3 * m + 3]:
            lab = c.get("marker") or c.get("name") or ""
            hit = _AXIS.match(c.get("label") or "")
            if hit:
                axes.append(hit.group("axis").lower())
                names.add(lab or hit.group("name"))
            else:
                names.add(lab or (c.get("label") or ""))
                axes.append("?")
        if len(names) != 1 or "" in names or axes not in (["x", "y", "z"], ["?", "?", "?"]):
            got = [c.get("label") for c in channels[3 * m:3 * m + 3]]
            raise InputError(f"stream '{stream}': channels {3 * m}-{3 * m + 2} ({got}) are not the x, y, z of one "
                             "marker (expected labels such as LASI_X, LASI_Y, LASI_Z)")
        labels.append(names.pop())
    units = {_UNITS.get((c.get("unit") or "").strip().lower()) for c in channels} - {None}
    if len(units) > 1:
        raise InputError(f"stream '{stream}': channels in different units {sorted(units)}")
    unknown = {(c.get("unit") or "").strip() for c in channels} - set(_UNITS) - {""}
    if unknown:
        raise InputError(f"stream '{stream}': unknown position units {sorted(unknown)}; allowed values are "
                         f"{sorted(set(_UNITS))}")
    return tuple(labels), (units.pop() if units else "mm")


def marker_stream_info(name: str, labels: Sequence[str], rate_hz: float, /, *, units: str = "mm", source_id: str = ""):
    """A pylsl StreamInfo of a marker stream as the field sends it (type Mocap, double64 channels
    LABEL_X, LABEL_Y, LABEL_Z with their unit)."""
    lsl = load_pylsl()
    info = lsl.StreamInfo(name, "Mocap", 3 * len(labels), float(rate_hz), lsl.cf_double64, source_id or name)
    chans = info.desc().append_child("channels")
    unit = {"mm": "millimeters", "m": "meters", "cm": "centimeters"}[units]
    for lab in labels:
        for axis in "XYZ":
            c = chans.append_child("channel")
            c.append_child_value("label", f"{lab}_{axis}")
            c.append_child_value("marker", lab)
            c.append_child_value("type", f"Position{axis}")
            c.append_child_value("unit", unit)
    info.desc().append_child_value("manufacturer", "exubio")
    return info


class LSLSource:
    """A marker stream read from LSL (resolved by name or source id, the first one if neither is
    given), as a MarkerSource (exubio.run.live.sources). Timestamps are the sender's, corrected to
    this machine's clock (LSL's clock sync); the inlet recovers a sender that restarts with the
    same source id."""

    def __init__(self, *, name: str | None = None, source_id: str | None = None, max_buffer_s: int = 30):
        self.name, self.source_id, self.max_buffer_s = name, source_id, max_buffer_s
        self.inlet = None
        self.lsl = load_pylsl()

    @property
    def clock(self):
        return self.lsl.local_clock

    def open(self, timeout_s: float) -> StreamInfo:
        lsl = self.lsl
        if self.source_id:
            found = lsl.resolve_byprop("source_id", self.source_id, minimum=1, timeout=timeout_s)
        elif self.name:
            found = lsl.resolve_byprop("name", self.name, minimum=1, timeout=timeout_s)
        else:
            found = lsl.resolve_byprop("type", "Mocap", minimum=1, timeout=timeout_s)
        what = (f"source id '{self.source_id}'" if self.source_id else f"name '{self.name}'" if self.name
                else "type Mocap")
        if not found:
            raise InputError(f"no LSL marker stream with {what} within {timeout_s:g} s (is the sender running, "
                             "with the same --lsl-config?)")
        self.inlet = lsl.StreamInlet(found[0], max_buflen=self.max_buffer_s, recover=True,
                                     processing_flags=lsl.proc_clocksync)
        full = self.inlet.info(timeout=timeout_s)
        try:  # the first clock-offset estimate takes LSL ~0.5 s of probes: done now, before the data flows
            self.inlet.time_correction(timeout=timeout_s)
        except Exception as exc:  # noqa: BLE001 - a timeout here leaves the correction to the first samples
            log.info("LSL time correction not estimated yet: %s", exc)
        labels, units = marker_labels(_channels(full), full.channel_count(), full.name())
        if not full.nominal_srate() > 0:
            raise InputError(f"stream '{full.name()}': irregular rate; a marker stream needs its nominal rate")
        self._opened = False  # the data connection opens at the first pull: a sender that waits for its
        # consumer starts only once this side is ready
        self._open_timeout = timeout_s
        self.info = StreamInfo(name=full.name(), labels=labels, rate_hz=float(full.nominal_srate()), units=units,
                               source_id=full.source_id())
        return self.info

    def pull(self, timeout_s: float) -> list[tuple[float, np.ndarray]] | None:
        if not self._opened:
            self.inlet.open_stream(timeout=self._open_timeout)
            self._opened = True
        sample, ts = self.inlet.pull_sample(timeout=timeout_s)
        if sample is None:
            return []
        out = [(float(ts), np.asarray(sample, dtype=float))]
        if self.inlet.samples_available():  # (an empty pull_chunk costs as much as the sample's)
            more, times = self.inlet.pull_chunk(timeout=0.0)
            out.extend((float(t), np.asarray(s, dtype=float)) for s, t in zip(more, times))
        return out

    def wake(self) -> None:  # pulls time out within their (short) timeout
        pass

    def close(self) -> None:
        if self.inlet is not None:
            self.inlet.close_stream()
            self.inlet = None


class LSLPublisher:
    """The live output as two LSL outlets: ``<name>`` (one double64 sample per frame, channels
    exubio.run.live.outputs.OUTPUT_CHANNELS with their units, the input sample's timestamp) and
    ``<name>_events`` (irregular, one string channel: each Event as JSON)."""

    def __init__(self, name: str, channels: Sequence[tuple[str, str]], rate_hz: float, /, *,
                 metadata: dict[str, str] | None = None, source_id: str = ""):
        lsl = self.lsl = load_pylsl()
        info = lsl.StreamInfo(name, "Kinematics", len(channels), float(rate_hz), lsl.cf_double64, source_id or name)
        chans = info.desc().append_child("channels")
        for label, unit in channels:
            c = chans.append_child("channel")
            c.append_child_value("label", label)
            c.append_child_value("unit", unit)
        meta = info.desc().append_child("exubio")
        for key, value in (metadata or {}).items():
            meta.append_child_value(key, str(value))
        self.outlet = lsl.StreamOutlet(info)
        ev = lsl.StreamInfo(f"{name}_events", "Markers", 1, lsl.IRREGULAR_RATE, lsl.cf_string, f"{source_id or name}_events")
        self.events = lsl.StreamOutlet(ev)

    def __call__(self, row: np.ndarray, timestamp: float) -> None:
        if np.isfinite(timestamp):
            self.outlet.push_sample(row.tolist(), timestamp)
        else:
            self.outlet.push_sample(row.tolist())

    def event(self, event) -> None:
        self.events.push_sample([json.dumps(to_json(event))])

    def close(self) -> None:
        self.outlet = self.events = None


class ReplayOutlet:
    """A trial sent as an LSL marker stream (``exubio stream``): frame i at start + i / (rate speed)
    on this machine's LSL clock, with that timestamp (so a receiver places it on the trial's grid)."""

    def __init__(self, labels: Sequence[str], rate_hz: float, /, *, name: str, units: str = "mm", source_id: str = ""):
        self.lsl = load_pylsl()
        self.units, self.scale = units, {"mm": 1e3, "m": 1.0, "cm": 1e2}[units]
        self.outlet = self.lsl.StreamOutlet(marker_stream_info(name, labels, rate_hz, units=units, source_id=source_id))
        self.rate = float(rate_hz)

    def wait_for_consumer(self, timeout_s: float) -> bool:
        return bool(self.outlet.wait_for_consumers(timeout_s))

    def send(self, positions_m: np.ndarray, /, *, speed: float = 1.0, stop=None, on_sample=None,
             drop: Sequence[int] = ()) -> int:
        """Send frames (n, k, 3) m at their times (speed x real time); returns the frames sent.
        ``stop()`` True ends early; ``on_sample(i, push_clock)`` after each push."""
        lsl = self.lsl
        period = 1.0 / (self.rate * speed)
        data = np.asarray(positions_m, dtype=float) * self.scale
        flat = data.reshape(data.shape[0], -1)
        skip = set(drop)
        start = lsl.local_clock() + 0.05
        sent = 0
        for i in range(flat.shape[0]):
            due = start + i * period
            while True:
                wait = due - lsl.local_clock()
                if wait <= 0:
                    break
                time.sleep(min(wait, 0.05))
                if stop is not None and stop():
                    return sent
            if i in skip:
                continue
            self.outlet.push_sample(flat[i].tolist(), start + i / self.rate)
            sent += 1
            if on_sample is not None:
                on_sample(i, lsl.local_clock())
        return sent

    def close(self) -> None:
        self.outlet = None
