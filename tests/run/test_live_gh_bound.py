"""The live running verdict holds the glenohumeral bound the offline verdict holds (GH elevation at most
exubio.trust.quality.GH_ELEVATION_MAX_DEG; the solver's gh_abduction and gh_flexion have no range):
the same frames, the same excess, the same reason."""
import numpy as np
import pytest

from exubio.model.angles import anatomical_table
from exubio.model.load import load_model
from exubio.protocol.bind import bind
from exubio.run.inputs import protocol_for_model
from exubio.run.live.frame import LiveFrame
from exubio.run.live.monitor import LiveMonitor
from exubio.run.live.options import LiveOptions
from exubio.trust.assess import gh_elevation_limit

pytestmark = pytest.mark.exudyn  # the live options hold PF's

COUNTS = {"dropped": 0, "late": 0, "skipped": 0, "failed": 0, "no_state": 0}


def test_the_live_verdict_names_a_humerus_past_the_gh_bound_as_the_offline_one_does():
    model = load_model()
    binding = bind(model, protocol_for_model(model))
    monitor = LiveMonitor(binding, 100.0, LiveOptions(), np.ones(len(binding.protocol.marker_names), bool),
                          lambda *args: None)
    q = np.zeros((6, model.n_coordinates))
    q[3:, model.coordinate_names.index("gh_abduction")] = np.radians([120.0, 178.0, 178.0])  # 120: inside
    frame = LiveFrame(model, binding.kin, binding.points, 100.0, monitor.gh_axes)  # the live loop's, from q
    measured = np.zeros((len(binding.protocol.marker_names), 3))
    for g in range(len(q)):
        monitor.gh_elevation(g, frame.outputs(q[g], measured).gh_elevation)
    monitor.verdict(len(q) - 1, COUNTS, [])
    (offline,) = gh_elevation_limit(*anatomical_table(model, q))
    (reason,) = [r for r in monitor.quality.reasons if r.code == "limit"]
    assert monitor.quality.verdict == "fail" and reason.level == "fail"
    assert (f"GH_X_elevation at its range limit [-150, 150] deg in {offline.frames_at_limit} of 6 frames "
            f"(first: frame {offline.first_frame}; at most {offline.max_beyond_deg:.1f} deg beyond)") in reason.message
    assert (offline.frames_at_limit, offline.first_frame) == (2, 4)
