"""A live run of the PF system (exubio.backend.exudyn_system.PFSystem.run_live): one step per
frame through marker frames fetched as the steps need them, every frame handed on as soon as a
step reaches it; the steps, targets, limit switching and solver of a trial's run
(exubio.backend.exudyn_integrate), so a live run through the same frames gives the same motion.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from exubio.backend.exudyn_integrate import BuiltSystem, Integration, solver_settings
from exubio.backend.pf_numerics import hermite, quintic
from exubio.backend.pf_types import IntegratorOptions, PFRun

__all__ = ["integrate_live"]


def integrate_live(system: BuiltSystem, next_frame: Callable[[int], tuple | None],
                   on_frame: Callable[[int, PFRun], None], /, *, frame_dt_s: float, options: IntegratorOptions,
                   interrupt: Callable[[], None] | None) -> PFRun:
    """``PFSystem.run_live`` (see there)."""
    if not frame_dt_s > 0:
        raise ValueError(f"run_live: frame_dt_s must be > 0, got {frame_dt_s}")
    return _LiveRun(system, next_frame, on_frame, frame_dt_s, interrupt).run(options)


class _LiveRun(Integration):
    """A run of one step per frame through frames fetched from ``next_frame`` as the steps need
    them; every frame a step reaches goes to ``on_frame``."""

    EPS = 1e-6  # of a frame interval: a time on a frame

    def __init__(self, system: BuiltSystem, next_frame, on_frame, frame_dt_s: float, interrupt):
        super().__init__(system, frame_dt_s, interrupt)
        self.next_frame, self.on_frame = next_frame, on_frame
        self.frames: dict[int, tuple] = {}  # the last frames received: i -> (pos, vel, active)
        self.received = 0  # the last frame received
        self.last_t = 0.0  # the last accepted time
        self.done = 0  # frames handed to on_frame
        self.previous: tuple | None = None  # (t, X, Xt, Xtt) of the last accepted step

    def fetch(self, i: int) -> bool:
        got = self.next_frame(i)
        if got is None:
            return False
        k = self.targets.k
        p, v, a = np.asarray(got[0]), np.asarray(got[1]), np.asarray(got[2])
        a = a if a.dtype == np.bool_ else a.astype(bool)
        if p.shape != (k, 3) or v.shape != (k, 3) or a.shape != (k,):
            raise ValueError(f"run_live: frame {i} must be positions ({k}, 3), velocities ({k}, 3), active ({k},); "
                             f"got {p.shape}, {v.shape}, {a.shape}")
        if not a.all():  # the inactive markers' rows zero (NaN where missing)
            on = a[:, None]
            p, v = np.where(on, p, 0.0), np.where(on, v, 0.0)
        if not (np.isfinite(p).all() and np.isfinite(v).all()):
            raise ValueError(f"run_live: a marker is active but not finite at frame {i}")
        self.frames[i] = (p, v, a)
        self.frames.pop(i - 8, None)  # a rejected step may be retried over earlier frames: keep a few
        return True

    def pre_step(self, mbs, t: float) -> bool:
        if self.interrupted or self.failure is not None or self.ended:
            return False
        eps, dt, frames = self.EPS, self.frame_dt_s, self.frames
        try:
            limits = self.limits
            if limits.elements and self.last_t >= limits.next_check:
                limits.check(self.last_t)
            x = t / dt
            i = int(math.ceil(x - eps))
            while self.received < i:  # the frame this step ends on (or lies before)
                if not self.fetch(self.received + 1):
                    self.ended = True
                    return False
                self.received += 1
            lo = int(math.floor(self.last_t / dt + eps))
            now = frames[i][2] & frames[max(lo, i - 1)][2] if i - 1 >= lo else frames[i][2]
            self.targets.switch(now, self.state)
            if abs(x - i) < eps:
                self.targets.set_to(frames[i][0], frames[i][1])
            else:  # a reduced step between frames i - 1 and i
                (p0, v0, _), (p1, v1, _) = frames[i - 1], frames[i]
                self.targets.set_to(*hermite(p0, v0, p1, v1, x - (i - 1), dt))
        except BaseException as exc:
            self.failure = exc
            return False
        return True

    def post_step(self, mbs, t: float) -> bool:
        self.last_t = t
        if t > 0.0:
            self.accepted += 1
        if self.failure is not None or self.ended:  # (Exudyn may finish a step after a pre-step said stop)
            return True
        sd, eps, dt = self.sd, self.EPS, self.frame_dt_s
        cur = (t, np.asarray(sd.GetODE2Coordinates()), np.asarray(sd.GetODE2Coordinates_t()),
               np.asarray(sd.GetODE2Coordinates_tt()))
        try:  # every frame this step reached: its state, or inside the step (after a reduced step)
            # the quintic Hermite of the two step states, as a trial run's frames_from_steps
            while self.done <= self.received and self.done * dt <= t + eps * dt:
                i = self.done
                ti = i * dt
                if abs(ti - t) <= eps * dt or self.previous is None:
                    X, Xt, Xtt = cur[1], cur[2], cur[3]
                else:
                    t0_, X0, V0, A0 = self.previous
                    h = t - t0_
                    X, Xt, Xtt = quintic(X0, V0, A0, cur[1], cur[2], cur[3], (ti - t0_) / h, h)
                self.on_frame(i, self.system.decode_frame(X, Xt, Xtt))
                self.done = i + 1
        except BaseException as exc:
            self.failure = exc
            return False
        self.previous = cur
        return True

    def run(self, options: IntegratorOptions) -> PFRun:
        dt = self.frame_dt_s
        if not self.fetch(0):
            return self.no_frames(0)
        p0, v0, a0 = self.frames[0]
        self.start(self.targets.rows(p0, v0), a0, dt)
        horizon = 1e9  # steps: the run ends when next_frame says so
        solver, success, message = self.solve(solver_settings(int(horizon), horizon * dt, options), dt)
        it = solver.it
        return dataclasses.replace(
            self.no_frames(self.done), completed_frames=int(self.done), success=bool(self.ended and not message),
            message=message, wall_time_s=float(self.wall_time_s), newton_iterations=int(it.newtonStepsCount),
            jacobian_updates=int(it.newtonJacobiCount), steps=self.accepted, step_s=float(dt),
            limit_active_s=self.limits.active_time_s(self.last_t))
