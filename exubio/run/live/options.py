"""The settings of a live session (LiveOptions); what it calls out to is exubio.run.live.loop's
SessionHooks."""
from __future__ import annotations

from dataclasses import dataclass

from exubio.run.live.causal import CausalOptions
from exubio.methods.pf import PFOptions

__all__ = ["LiveOptions"]


@dataclass(frozen=True)
class LiveOptions:
    """Settings of the live loop (see exubio.run.live.loop's module docstring).

    causal: the causal preprocessing (filter, rates). pf: the PF settings; the live run takes one
        step per frame whatever ``pf.step_s`` says. The final projection on the constraints is off by
        default (it moves angles by < 1e-5 deg and costs ~0.6 ms per frame, a third of the latency
        budget): the recording's constraint residuals are Exudyn's own (|g| ~ 1e-7).
    max_coast_s: a stretch of frames with no active spring (a hole in the stream, every marker
        gone) longer than this ends the PF run; a new one starts from the LS pose.
    stall_s: no sample for this long is reported as a stall.
    end_after_s: no sample for this long ends the stream (None: wait for ever, end with Ctrl-C).
    max_behind_s: a backlog longer than this is skipped (see exubio.run.live.loop's docstring), except
        during the first ``catch_up_s`` seconds after the session's first frame is solved, in which the
        start's backlog (the stream opened, the LS pose, the system built, the first solve with its
        kernels compiled on a first run) is worked off.
    verdict_every_s: the running verdict is re-evaluated this often.
    open_timeout_s: how long to wait for the stream to appear.
    """

    causal: CausalOptions = CausalOptions()
    pf: PFOptions = PFOptions(step_s=None, project_constraints=False)
    max_coast_s: float = 0.1
    stall_s: float = 0.1
    end_after_s: float | None = 5.0
    max_behind_s: float = 0.5
    catch_up_s: float = 2.0
    verdict_every_s: float = 0.5
    open_timeout_s: float = 10.0

