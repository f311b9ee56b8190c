"""Once the methods are done a trial's targets keep their positions only (issue 38's memory bound):
``without_rates`` leaves every other field as it is and puts read-only NaN views of no memory where
the velocities and accelerations were, so a reader of them after the methods gets NaN or an error,
never stale numbers; the streamed sink holds no rates either."""
from __future__ import annotations

import numpy as np
import pytest

from exubio.io.streamed import StreamedReconstruction, without_rates
from exubio.types import MarkerTargets


def _targets(n: int = 50) -> MarkerTargets:
    rng = np.random.default_rng(1)
    return MarkerTargets(time_s=np.arange(n) / 100.0, marker_names=("a", "b"), positions_m=rng.normal(size=(n, 2, 3)),
                         velocities_m_s=rng.normal(size=(n, 2, 3)), accelerations_m_s2=rng.normal(size=(n, 2, 3)),
                         source="x.c3d", cutoff_hz={"a": 6.0})


def test_without_rates_keeps_the_rest_and_holds_no_rates():
    tg = _targets()
    out = without_rates(tg)
    assert out.positions_m is tg.positions_m and out.time_s is tg.time_s
    assert (out.marker_names, out.gaps, out.source, dict(out.cutoff_hz)) == (tg.marker_names, tg.gaps, tg.source,
                                                                            dict(tg.cutoff_hz))
    for rates in (out.velocities_m_s, out.accelerations_m_s2):
        assert rates.shape == tg.positions_m.shape and np.isnan(rates).all()
        assert rates.strides == (0, 0, 0)  # a view of one number: no memory
        with pytest.raises(ValueError):
            rates[0, 0, 0] = 1.0  # read-only
    assert np.array_equal(out.present, tg.present)


def test_the_sink_keeps_no_rates(tmp_path):
    tg = _targets()
    with StreamedReconstruction(tmp_path, "x.pf", tg, ("q1", "q2")) as sink:
        assert sink.targets.positions_m is tg.positions_m
        assert sink.targets.velocities_m_s.strides == (0, 0, 0)
