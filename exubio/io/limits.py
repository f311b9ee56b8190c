"""Bounds on what a trial file's header can ask of exubio, checked by the readers (io/c3d.py,
io/trc.py) before any work: a header is data from outside, and the work after reading (filter
padding, splines, steps) grows with what it says.

The filter pads each run of samples by a few periods of its cut-off (exubio.prep.filtering), i.e. by
about rate / cut-off samples: a rate of 1e9 Hz asks for 2e9 samples (15 GB) per marker coordinate.
Optical motion capture records at 30 Hz to about 10 kHz (high-speed modes of Qualisys and Vicon
cameras); MAX_RATE_HZ is ten times that, and at it the padding stays a few hundred thousand
samples.
"""
from __future__ import annotations

MAX_RATE_HZ = 100_000.0
"""The highest marker sampling rate a trial file may declare (Hz)."""


def rate_problem(rate: float, /) -> str | None:
    """The rate and why it is not a usable marker rate ("nan (not a finite number)"), or None when
    it is usable."""
    if rate != rate or rate in (float("inf"), float("-inf")):
        return f"{rate} (not a finite number)"
    if not rate > 0:
        return f"{rate:g} Hz (not > 0)"
    if rate > MAX_RATE_HZ:
        return (f"{rate:g} Hz (above {MAX_RATE_HZ:g} Hz, the highest marker rate exubio accepts: optical "
                f"motion capture records at most about 10 kHz)")
    return None
