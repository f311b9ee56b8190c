"""Labels exchanged in part of a trial are found per frame range and, with --repair-labels,
exchanged back and reported (exubio.trust.label_ranges); the trials as recorded have none. Built from
the real trials of ../shared/data (skipped when absent)."""
import json
from pathlib import Path

import numpy as np
import pytest

from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.io.trial import read_trial
from exubio.trust.label_ranges import find_partial_swaps, repair_partial_swaps
from exubio.run.inputs import load_model_and_protocol

C3D = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d"
pytestmark = pytest.mark.skipif(not C3D.is_dir(), reason=f"real data folder {C3D} is absent")
TRIAL = C3D / "bioptim_exo_martin_dynamique.c3d"


def _exchanged(traj, a, b, start, stop):
    import dataclasses

    pos = traj.positions_m.copy()
    i, j = traj.labels.index(a), traj.labels.index(b)
    pos[start:stop, [i, j]] = pos[start:stop, [j, i]]
    return dataclasses.replace(traj, positions_m=pos)


def test_a_swap_in_a_frame_range_is_found_there_and_repaired_exactly():
    model, protocol = load_model_and_protocol()
    traj = read_trial(TRIAL)
    assert find_partial_swaps(traj, protocol, model) == ()
    bad = _exchanged(traj, "EPI_lat", "EPI_med", 200, 380)
    (s,) = find_partial_swaps(bad, protocol, model)
    assert {s.a, s.b} == {"EPI_lat", "EPI_med"} and s.ranges == ((200, 380),)
    fixed = repair_partial_swaps(bad, protocol, [s])
    np.testing.assert_array_equal(fixed.positions_m, traj.positions_m)


@pytest.mark.slow  # reconstructions end to end (about 3-4 s)
def test_the_verdict_fails_on_a_partial_swap_and_repair_labels_reports_the_frames(tmp_path):
    traj = read_trial(TRIAL)
    path = write_c3d(tmp_path / "jump.c3d", _exchanged(traj, "ARM", "DELT", 100, 260))
    base = ["-q", "reconstruct", str(path), "--static", str(C3D / "bioptim_exo_martin_statique.c3d"),
            "--method", "ls", "--no-report"]
    assert main([*base, "--out", str(tmp_path / "as_is")]) == 1
    s = json.loads((tmp_path / "as_is" / "jump.ls.summary.json").read_text(encoding="utf-8"))
    r = [x for x in s["quality"]["reasons"] if x["code"] == "partial_swap"]
    assert r and r[0]["level"] == "fail" and "frames 100-259" in r[0]["message"] and "--repair-labels" in r[0]["message"]
    main([*base, "--repair-labels", "--out", str(tmp_path / "repaired")])
    s = json.loads((tmp_path / "repaired" / "jump.ls.summary.json").read_text(encoding="utf-8"))
    codes = {x["code"]: x for x in s["quality"]["reasons"]}
    assert "partial_swap" not in codes and "frames 100-259" in codes["label_repaired"]["message"]


def test_three_scapula_markers_raise_no_false_exchange_on_a_short_trial(tmp_path):
    """The ISB-name set has three scapula markers: two of them were judged against the humerus's
    epicondyles, whose distances move with the arm, and a correctly labelled 3-s abduction failed
    with R_AA/R_AI "exchanged in frames 0-30". With the third scapula marker as the only partner
    (rigid with both) nothing is found; a real exchange of two scapula markers still is."""
    import dataclasses

    import numpy as np

    from exubio.cli import main
    from exubio.io.trial import read_trial
    from exubio.run.inputs import load_model_and_protocol, protocol_for_model
    from exubio.trust.label_ranges import find_partial_swaps

    c3d = tmp_path / "isb.c3d"
    assert main(["-q", "simulate", "--motion", "abduction", "--duration", "3", "--rate", "50", "--protocol",
                 "isb_landmarks", "--protocol", "isb_landmarks_left", "--out", str(c3d)]) == 0
    model, _ = load_model_and_protocol()
    protocol = protocol_for_model(model, "isb_landmarks")
    traj = read_trial(c3d)
    assert find_partial_swaps(traj, protocol, model) == ()
    pos = traj.positions_m.copy()
    i, j = traj.labels.index("R_AA"), traj.labels.index("R_TS")
    pos[60:110, [i, j]] = pos[60:110, [j, i]]
    found = find_partial_swaps(dataclasses.replace(traj, positions_m=pos), protocol, model)
    assert [(s.a, s.b) for s in found] in ([("R_AA", "R_TS")], [("R_TS", "R_AA")])
    assert np.isclose(sum(b - a for a, b in found[0].ranges), 50, atol=5)
