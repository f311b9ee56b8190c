"""The terminal display of ``exubio live``: one status line rewritten in place (latency, frames
behind, mean residual, the running verdict, a few key angles, dropped frames, open gaps) and one
line per event above it. It writes to the stream it is given (the CLI passes stderr); ``quiet``
shows nothing but the verdict changes and the end."""
from __future__ import annotations

import math
from typing import TextIO

from exubio.run.live.outputs import Event

_SHORT = {"HT_X_elevation": "HT elev", "GH_X_elevation": "GH elev", "ST_X_upward_rotation": "ST upward",
          "GH_Y_internal_rotation": "GH int rot"}


def _num(x: float, fmt: str) -> str:
    return "--" if x is None or not math.isfinite(x) else format(x, fmt)


class Display:
    """A status line rewritten in place on a terminal; on a file or pipe one line every
    ``PIPE_EVERY_S`` seconds of the stream."""

    PIPE_EVERY_S = 2.0

    def __init__(self, out: TextIO, /, *, quiet: bool = False):
        self.out, self.quiet, self.line = out, quiet, False
        self.tty = bool(getattr(out, "isatty", lambda: False)())
        self.next_t = 0.0

    def status(self, s: dict) -> None:
        if self.quiet:
            return
        if not self.tty:
            if s["time_s"] < self.next_t:
                return
            self.next_t = s["time_s"] + self.PIPE_EVERY_S
        angles = "  ".join(f"{_SHORT[k]} {_num(v, '6.1f')}" for k, v in s["angles_deg"].items())
        text = (f"t {s['time_s']:7.2f} s | latency {_num(s['latency_ms_p50'], '.2f')} ms (max {_num(s['latency_ms_max'], '.1f')})"
                f" | behind {s['frames_behind']:3d} | residual {_num(s['residual_mean_mm'], '5.1f')} mm"
                f" | {s['verdict'].upper():5s} | {angles} deg"
                + (f" | dropped {s['dropped']}" if s["dropped"] else "")
                + (f" | gaps: {', '.join(s['gaps'])}" if s["gaps"] else "")
                + ("" if s["tracking"] else " | NOT TRACKING"))
        if self.tty:
            self.out.write("\r\x1b[2K" + text)
            self.line = True
        else:
            self.out.write(text + "\n")
        self.out.flush()

    def event(self, e: Event) -> None:
        if self.quiet and e.kind not in ("verdict", "end", "skip", "restart", "diverged", "label_swap"):
            return
        if self.line:
            self.out.write("\r\x1b[2K")
            self.line = False
        self.out.write(f"[{e.time_s:8.2f} s] {e.kind}: {e.message}\n")
        self.out.flush()

    def close(self) -> None:
        if self.line:
            self.out.write("\n")
            self.out.flush()
            self.line = False
