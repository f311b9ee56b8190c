"""The running checks of a live session (LiveMonitor), frame by frame as the loop
(exubio.run.live.loop) hands them over: the gaps of single markers, label swaps (whose springs it
switches off), which angles the markers determine (the noise gain, every DETERMINACY_PERIOD_S),
the running residual and joint-limit figures, the running verdict, a diverged PF run, and the
status summary for a display. It reports what it sees through the session's ``event``."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from exubio.trust import quality as Q
from exubio.trust.assess import DETERMINACY_PERIOD_S, angle_status_of_protocol, coordinates_not_measured_by_protocol
from exubio.trust.checks import Evidence, LiveCounts, judge
from exubio.trust.frame_determinacy import FrameDeterminacy
from exubio.model.ranges import AT_LIMIT_TOLERANCE_RAD
from exubio.run.live.outputs import ISB_NAMES, Event, angles_measured
from exubio.protocol.bind import Binding
from exubio.types import Gap

if TYPE_CHECKING:
    from exubio.run.live.options import LiveOptions

__all__ = ["LiveMonitor", "LABEL_SWAP_FRAMES", "mean_finite"]

LABEL_SWAP_FRAMES = 3
"""Frames in a row a pair must look swapped before its springs go off (one frame can be noise)."""
LABEL_SWAP_MIN_MM = Q.RESIDUAL_MEAN_MM[0]
"""A marker must be this far from its model point to be a swap candidate: the residual at which a
trial's mean residual is already a check (quality.RESIDUAL_MEAN_MM)."""
LABEL_SWAP_RATIO = 0.5
"""Swapped, the pair's residuals must sum to less than this fraction of the unswapped sum."""


def mean_finite(x: np.ndarray) -> float:
    """The mean of the finite values of x (1-D), NaN if none: ``x[ok].mean()``'s operations (a sum
    and a division), without the copy when every value is finite."""
    ok = np.isfinite(x)
    if ok.all():
        return float(np.add.reduce(x) / x.size) if x.size else np.nan
    return float(np.add.reduce(x[ok]) / ok.sum()) if ok.any() else np.nan


def _long_axes(model) -> tuple | None:
    """(segment index, its anatomical Y axis in segment coordinates) of the scapula and the humerus, or
    None for a model without both."""
    from exubio.model.angles import anatomical_frames

    names = [seg.name for seg in model.segments]
    if not {"scapula", "humerus"} <= set(names):
        return None
    A = anatomical_frames(model)
    return tuple((model.segment_index(n), A[n][:, 1].copy()) for n in ("scapula", "humerus"))


class LiveMonitor:
    """The running checks of one live session on its bound model (``kin``, tracked ``points``):
    ``measured`` (the angles the markers measure, ISB order), ``quarantine`` (the springs a label
    swap switched off) and ``quality`` (the running verdict) are what the loop reads back.
    ``in_stream``: the markers the stream carries (the others get no gap events); ``event(kind,
    frame, message, markers)``: the session's event report; ``calibration``: the report of a
    calibration on the stream's first frames (with ``scale_bounds`` and ``off_segment``), checked in
    every verdict."""

    def __init__(self, binding: Binding, rate: float, options: "LiveOptions", in_stream: np.ndarray,
                 event: Callable[..., None]):
        model, protocol = binding.model, binding.protocol
        self.binding, self.model, self.protocol, self.rate = binding, model, protocol, rate
        self.kin, self.points = binding.kin, binding.points
        self.options, self.in_stream, self._event = options, in_stream, event
        self.marker_names = protocol.marker_names
        k, m = len(self.marker_names), model.n_coordinates
        self.excluded = binding.not_solved
        self.not_solved = binding.not_solved_names
        self.unmeasurable = coordinates_not_measured_by_protocol(binding)
        self.structural = angle_status_of_protocol(binding)  # held by the binding, not computed per frame
        self.measured = angles_measured(model, self.not_solved, unmeasurable=self.unmeasurable,
                                        structural=self.structural)
        self.ranges = model.coordinate_ranges_rad
        self.calibration = None  # a calibration on the stream's first frames (its report), checked in every verdict
        self.scale_bounds: tuple[float, float] = (0.0, float("inf"))
        self.off_segment: dict[str, float] = {}
        self.quarantine = np.zeros(k, dtype=bool)
        self.swap_count: dict = {}
        self.swapped: dict = {}
        self.in_gap = np.zeros(k, dtype=bool)
        self.gap_start = np.zeros(k, dtype=int)
        self._expected = np.asarray(in_stream, dtype=bool).copy()
        self.gaps: list[Gap] = []
        self.res_sum, self.res_sq, self.res_n = np.zeros(k), np.zeros(k), np.zeros(k, dtype=int)
        self.frame_means = np.empty(4096)  # the mean residual of each frame (mm), the first n_means
        self.n_means = 0
        self.lim_count, self.lim_first, self.lim_beyond = np.zeros(m, dtype=int), np.zeros(m, dtype=int), np.zeros(m)
        self.gh_axes = _long_axes(model)  # the bound on GH elevation, as the offline limits (exubio.trust.assess)
        self.gh_count, self.gh_first, self.gh_beyond = 0, 0, 0.0
        self.gh_bound = math.radians(Q.GH_ELEVATION_MAX_DEG)
        self.undetermined_frames = np.zeros(m, dtype=int)
        self.quality = Q.Quality.of([])
        self.verdict_every = max(int(round(options.verdict_every_s * rate)), 1)
        self.verdict_due = self.verdict_every - 1
        self.det_every = max(int(round(DETERMINACY_PERIOD_S * rate)), 1)
        self.det_due = 0
        self.frame_determinacy = FrameDeterminacy(self.kin, self.points, protocol.weights, excluded=self.excluded)
        self._measured_of: dict[tuple[str, ...], np.ndarray] = {}  # angles_measured by undetermined coordinates

    def track_gaps(self, g: int, present: np.ndarray, dropped: bool) -> None:
        """Gaps of single markers (not whole missing frames) reported by marker name."""
        names = self.marker_names
        if dropped or (present == self._expected).all():  # (the usual frame: nothing to report)
            return
        for j in np.flatnonzero(~present & ~self.in_gap & self.in_stream):
            self.in_gap[j] = True
            self.gap_start[j] = g
            self._event("gap", g, f"marker {names[j]} missing: its spring is off", (names[j],))
        for j in np.flatnonzero(present & self.in_gap):
            self.in_gap[j] = False
            self.gaps.append(Gap(names[j], int(self.gap_start[j]), g))
            self._event("gap_end", g, f"marker {names[j]} back after {(g - self.gap_start[j]) / self.rate:.2f} s "
                        f"({g - self.gap_start[j]} frames)", (names[j],))
        self._expected = self.in_stream & ~self.in_gap  # present where nothing changes

    def diverged(self, g: int, q: np.ndarray, res: np.ndarray, present: np.ndarray) -> str:
        """Why the run diverged at this frame ("" if not): exubio.methods.pf's criterion, a spring
        longer than divergence_deflection_m or angles that are not finite."""
        if not np.isfinite(q).all():
            return f"the PF solution is not finite at t = {g / self.rate:.3f} s"
        limit = self.options.pf.divergence_deflection_m
        bad = present & ~(res <= limit)
        if bad.any():
            j = int(np.flatnonzero(bad)[np.argmax(res[bad])])
            return (f"the PF run diverged at t = {g / self.rate:.3f} s: spring '{self.marker_names[j]}' is "
                    f"{res[j] * 1e3:.0f} mm long (limit {limit * 1e3:.0f} mm)")
        return ""

    def determinacy(self, g: int, q: np.ndarray, active: np.ndarray) -> None:
        """Every ``det_every`` frames: the angles the springs ``active`` in frame g determine at q."""
        if g < self.det_due:
            return
        self.det_due = g + self.det_every
        undetermined, near_lock = self.frame_determinacy(q, active)
        und = tuple(n for n, u in zip(self.model.coordinate_names, undetermined & ~near_lock) if u)
        if und not in self._measured_of:  # (the same few sets again and again)
            self._measured_of[und] = angles_measured(self.model, self.not_solved, und, unmeasurable=self.unmeasurable,
                                                     structural=self.structural)
        self.measured = self._measured_of[und]
        self.undetermined_frames += undetermined

    def label_check(self, g: int, res: np.ndarray, pts: np.ndarray, meas: np.ndarray) -> None:
        """A swapped pair: both far from their own model points, each close to the other's (residuals
        res (k,), model points and measured positions (k, 3) of this frame)."""
        far = np.flatnonzero(res > LABEL_SWAP_MIN_MM * 1e-3)
        if far.size < 2 and not self.swap_count and not self.swapped:  # (the usual frame: no pair, none to follow)
            return
        seen = set()
        for a_i, a in enumerate(far):
            for b in far[a_i + 1:]:
                swapped = np.linalg.norm(pts[a] - meas[b]) + np.linalg.norm(pts[b] - meas[a])
                if swapped < LABEL_SWAP_RATIO * (res[a] + res[b]):
                    seen.add((int(a), int(b)))
        for pair in list(self.swap_count):
            if pair not in seen and pair not in self.swapped:
                del self.swap_count[pair]
        names = self.marker_names
        for pair in seen:
            self.swap_count[pair] = self.swap_count.get(pair, 0) + 1
            if self.swap_count[pair] >= LABEL_SWAP_FRAMES and pair not in self.swapped:
                self.swapped[pair] = g
                self.quarantine[list(pair)] = True
                self._event("label_swap", g, f"markers {names[pair[0]]} and {names[pair[1]]} look swapped "
                            f"({res[pair[0]] * 1e3:.0f} and {res[pair[1]] * 1e3:.0f} mm from their model points, "
                            f"{LABEL_SWAP_FRAMES} frames in a row): both springs off", (names[pair[0]], names[pair[1]]))
        for pair, since in list(self.swapped.items()):
            a, b = pair
            if res[a] < LABEL_SWAP_MIN_MM * 1e-3 and res[b] < LABEL_SWAP_MIN_MM * 1e-3:
                del self.swapped[pair]
                self.swap_count.pop(pair, None)
                self.quarantine[[a, b]] = False
                self._event("label_swap_end", g, f"markers {names[a]} and {names[b]} fit their model points again "
                            f"(swapped for {(g - since) / self.rate:.2f} s): springs on", (names[a], names[b]))

    def running(self, g0: int, q: np.ndarray, res: np.ndarray) -> None:
        """The running residual figures and the frames at a joint limit, with the q (n, m) and residuals
        (n, k) of frames g0 ... g0 + n - 1: the sums added frame after frame and each frame's mean summed
        as numpy sums one frame's (bit for bit a frame at a time; tests/run/test_live_costs.py)."""
        ok = np.isfinite(res)
        vals = np.where(ok, res, 0.0)
        self.res_sum = np.add.reduce(np.concatenate([self.res_sum[None], vals]), axis=0)  # row after row
        self.res_sq = np.add.reduce(np.concatenate([self.res_sq[None], vals * vals]), axis=0)
        self.res_n += ok.sum(axis=0)
        n = res.shape[0]
        while self.n_means + n > self.frame_means.size:  # an array, not a list: the verdict reads it without a copy
            self.frame_means = np.concatenate([self.frame_means, np.empty(self.frame_means.size)])
        means = self.frame_means[self.n_means:self.n_means + n]
        same = (ok == ok[0]).all(axis=1)  # the frames missing the first one's markers (usually all): at once,
        if ok[0].any():  # each row's finite values summed as a 1-D sum of them (x[ok].mean()'s operations)
            rows = np.ascontiguousarray(res[same][:, ok[0]])  # (the indexing gives columns in Fortran order)
            means[same] = np.add.reduce(rows, axis=1) / ok[0].sum() * 1e3
        else:
            means[same] = np.nan
        for i in np.flatnonzero(~same):
            means[i] = mean_finite(res[i]) * 1e3
        self.n_means += n
        lo, hi = self.ranges[:, 0], self.ranges[:, 1]
        at = ((q >= hi - AT_LIMIT_TOLERANCE_RAD) | (q <= lo + AT_LIMIT_TOLERANCE_RAD)) & ~self.excluded
        if at.any():
            beyond = np.maximum(np.maximum(q - hi, lo - q), 0.0)
            for i, j in zip(*np.nonzero(at)):  # frame by frame, in order
                if self.lim_count[j] == 0:
                    self.lim_first[j] = g0 + i
                self.lim_count[j] += 1
                self.lim_beyond[j] = max(self.lim_beyond[j], beyond[i, j])

    def gh_elevation(self, g: int, e: float) -> None:
        """Frame g's GH elevation e (rad: the angle between the scapula's and the humerus's long axes,
        ``gh_axes``; NaN without them) against its bound (exubio.trust.quality.GH_ELEVATION_MAX_DEG)."""
        if e >= self.gh_bound - AT_LIMIT_TOLERANCE_RAD:
            if self.gh_count == 0:
                self.gh_first = g
            self.gh_count += 1
            self.gh_beyond = max(self.gh_beyond, e - self.gh_bound)

    def verdict(self, g: int, counts: Mapping[str, int], events: Sequence[Event]) -> None:
        """The running verdict: the criteria of exubio.trust.quality on the frames so far, plus what the
        live loop saw (stalls, restarts, skips, label swaps). ``counts``: the session's frames
        "dropped", "late", "skipped", "failed" and "no_state" so far; ``events``: its events so far."""
        self.verdict_due = g + self.verdict_every
        n = g + 1
        residual = per_frame = None
        if self.res_n.any():
            with np.errstate(all="ignore"):
                rmse = np.sqrt(self.res_sq / self.res_n) * 1e3
            residual = {"mean": float(self.res_sum.sum() / self.res_n.sum()) * 1e3,
                        "per_marker_rmse": {m: (None if self.res_n[j] == 0 else float(rmse[j]))
                                            for j, m in enumerate(self.marker_names)}}
            per_frame = self.frame_means[:self.n_means]
        names = self.model.coordinate_names
        lims = [{"coordinate": names[j], "range_deg": [float(np.degrees(self.ranges[j, 0])), float(np.degrees(self.ranges[j, 1]))],
                 "frames_at_limit": int(self.lim_count[j]), "first_frame": int(self.lim_first[j]),
                 "max_beyond_deg": float(np.degrees(self.lim_beyond[j]))} for j in np.flatnonzero(self.lim_count)]
        if self.gh_count:
            lims.append({"coordinate": "GH_X_elevation", "range_deg": [-Q.GH_ELEVATION_MAX_DEG, Q.GH_ELEVATION_MAX_DEG],
                         "frames_at_limit": self.gh_count, "first_frame": self.gh_first,
                         "max_beyond_deg": math.degrees(max(self.gh_beyond, 0.0))})
        open_gaps = [Gap(self.marker_names[j], int(self.gap_start[j]), n) for j in np.flatnonzero(self.in_gap)]
        names_m = self.marker_names
        live = LiveCounts(dropped=counts["dropped"], late=counts["late"], skipped=counts["skipped"],
                          restarts=sum(1 for e in events if e.kind in ("restart", "diverged")),
                          max_behind_s=self.options.max_behind_s,
                          swapped=tuple((names_m[a], names_m[b], since / self.rate)
                                        for (a, b), since in self.swapped.items()))
        # the same checks as the offline verdict (exubio.trust.checks) on what a live session knows so far
        quality = judge(Evidence(
            n_frames=n, rate_hz=self.rate, calibration=self.calibration, scale_bounds=self.scale_bounds,
            off_segment=self.off_segment, not_measured=tuple(self.unmeasurable),
            accepted_offsets_mm={m.name: m.landmark_offset_mm for m in self.protocol.markers
                                 if m.landmark_offset_mm is not None},
            residual_mm=residual, per_frame_residual_mm=per_frame, limits=lims, gaps=self.gaps + open_gaps,
            frames={"not_converged": counts["failed"], "too_few_markers": counts["no_state"]}, live=live))
        if quality.verdict != self.quality.verdict:
            self._event("verdict", g, f"{quality.verdict}" + (f": {quality.reasons[0].message}" if quality.reasons else ""))
        self.quality = quality

    def status(self, g: int, isb: np.ndarray, mean_res: float, behind: int, *, latency: Sequence[float],
               counts: Mapping[str, int], tracking: bool) -> dict:
        """The summary for a display at frame g (``latency``: the session's loop latencies, s)."""
        lat = np.asarray(latency[-200:]) * 1e3
        key = {n: float(np.degrees(isb[ISB_NAMES.index(n)])) for n in ("HT_X_elevation", "GH_X_elevation",
                                                                      "ST_X_upward_rotation", "GH_Y_internal_rotation")}
        return {"frame": g, "time_s": g / self.rate, "latency_ms_p50": float(np.median(lat)) if lat.size else np.nan,
                "latency_ms_max": float(lat.max()) if lat.size else np.nan, "frames_behind": int(behind),
                "residual_mean_mm": mean_res, "verdict": self.quality.verdict,
                "reason": self.quality.reasons[0].message if self.quality.reasons else "",
                "angles_deg": key, "dropped": counts["dropped"], "late": counts["late"], "skipped": counts["skipped"],
                "tracking": tracking, "gaps": [self.marker_names[j] for j in np.flatnonzero(self.in_gap)]}
