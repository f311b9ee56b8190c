"""A static trial of another session is named (exubio.trust.session_check), the same session's is not:
built from the real trials of ../shared/data (skipped when absent), the two martin sessions, whose
markers were placed anew between them (../shared/data/SOURCES.md)."""
import json
from pathlib import Path

import pytest

from exubio.cli import main
from exubio.io.trial import read_trial
from exubio.trust.labels import pair_distances
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.trust.session_check import placed_anew, static_consistency

C3D = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d"
pytestmark = [pytest.mark.slow, pytest.mark.skipif(not C3D.is_dir(), reason=f"real data folder {C3D} is absent")]

KINOVA_STATIC = "bioptim_exo_kinova_martin_statique.c3d"
MARTIN_STATIC = "bioptim_exo_martin_statique.c3d"
SESSIONS = {KINOVA_STATIC: [f"bioptim_exo_kinova_martin_{n}_f3_1.c3d" for n in ("aisselle", "dent", "manger", "tete")],
            MARTIN_STATIC: ["bioptim_exo_martin_dynamique.c3d"]}


@pytest.fixture(scope="module")
def distances():
    _, protocol = load_model_and_protocol()
    out = {}
    for name in [*SESSIONS, *(t for ts in SESSIONS.values() for t in ts)]:
        targets = prepare_targets(read_trial(C3D / name), protocol)
        out[name] = pair_distances(targets.positions_m, targets.marker_names, source=name)
    return protocol, out


@pytest.mark.parametrize("static", list(SESSIONS))
def test_every_task_trial_is_matched_to_its_own_session(distances, static):
    protocol, pd = distances
    for own, trials in SESSIONS.items():
        for trial in trials:
            flagged = placed_anew(static_consistency(pd[static], pd[trial], protocol))
            if own == static:
                assert not flagged, (trial, [s.describe() for s in flagged])
            else:  # markers re-placed: the scapula cluster and the humerus both moved
                assert {s.segment for s in flagged} >= {"scapula", "humerus"}, trial


def test_the_other_sessions_static_is_named_in_the_verdict(tmp_path):
    """`exubio reconstruct` of the martin dynamic trial calibrated on the kinova session's static:
    the verdict is at least a check and names that static with the segments' evidence; with its own
    session's static there is no such reason."""
    trial = C3D / "bioptim_exo_martin_dynamique.c3d"
    for static, expect in ((KINOVA_STATIC, True), (MARTIN_STATIC, False)):
        out = tmp_path / static
        code = main(["-q", "reconstruct", str(trial), "--static", str(C3D / static), "--method", "ls", "--no-report",
                     "--out", str(out)])
        summ = json.loads((out / "bioptim_exo_martin_dynamique.ls.summary.json").read_text(encoding="utf-8"))
        session = [r for r in summ["quality"]["reasons"] if r["code"] == "session"]
        assert bool(session) == expect, session
        if expect:
            assert summ["quality"]["verdict"] in ("check", "fail") and code in (0, 1)
            assert session[0]["level"] == "check" and static in session[0]["message"]
            assert "scapula" in session[0]["message"] and "humerus" in session[0]["message"]
