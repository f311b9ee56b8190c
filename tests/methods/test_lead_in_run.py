"""PF's run reads the lead-in without a whole-trial copy (issue 38's memory bound): what
``lead_in_run`` gives the start (pf_setup) and the springs (PFSystem.run's lead_in, before the
trial's own targets) is exactly what ``with_lead_in`` gives, frame for frame."""
from __future__ import annotations

import numpy as np

from exubio.methods.pf_time import LEAD_IN_MAX_BEND_M, lead_in_frames, lead_in_run, with_lead_in
from exubio.types import MarkerTargets


def _targets(n: int = 40, accel_scale: float = 1.0) -> MarkerTargets:
    rng = np.random.default_rng(3)
    t = np.arange(n) * 0.005
    pos = rng.normal(0.0, 0.2, (n, 3, 3))
    vel = rng.normal(0.0, 0.5, (n, 3, 3))
    acc = rng.normal(0.0, 2.0, (n, 3, 3)) * accel_scale
    pos[:, 2] = vel[:, 2] = acc[:, 2] = np.nan  # a marker missing at the first frame: missing in the lead-in
    pos[10:15, 1] = vel[10:15, 1] = acc[10:15, 1] = np.nan  # a gap later on
    return MarkerTargets(time_s=t, marker_names=("a", "b", "c"), positions_m=pos, velocities_m_s=vel,
                         accelerations_m_s2=acc, source="synthetic")


def _same(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape
    assert np.array_equal(a, b, equal_nan=True)


def test_lead_in_run_reads_what_with_lead_in_gives():
    for scale in (1.0, 1e3 * LEAD_IN_MAX_BEND_M):  # quadratic, and linear after an edge spike
        tg = _targets(accel_scale=scale)
        lead = lead_in_frames(0.1, 0.005, 0.005)
        assert lead == 20
        full = with_lead_in(tg, lead, 0.005)
        start, pos, vel = lead_in_run(tg, lead, 0.005)
        assert pos.shape == vel.shape == (lead, 3, 3)
        _same(np.concatenate([pos, tg.positions_m]), full.positions_m)
        _same(np.concatenate([vel, tg.velocities_m_s]), full.velocities_m_s)
        assert start.n_frames == lead + 1 and start.marker_names == tg.marker_names
        for name in ("time_s", "positions_m", "velocities_m_s", "accelerations_m_s2"):
            _same(getattr(start, name), getattr(full, name)[: lead + 1])
        _same(start.present, full.present[: lead + 1])


def test_no_lead_in_hands_on_the_targets_themselves():
    tg = _targets()
    start, pos, vel = lead_in_run(tg, 0, 0.005)
    assert start is tg and pos.shape == vel.shape == (0, 3, 3)
