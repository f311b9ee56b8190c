"""The verdict's checks are one list (exubio.trust.checks.CHECKS), used offline and live alike: each
check gives its reasons from the evidence it reads and nothing when that evidence is absent; a
check added to the list changes the verdict; the docs name every check."""
from __future__ import annotations

from pathlib import Path


from exubio.trust import quality as Q
from exubio.trust.checks import CHECKS, Check, Evidence, LiveCounts, judge

DOCS = Path(__file__).resolve().parents[2] / "docs" / "verdict.md"


def test_no_evidence_no_reason_and_an_ok():
    q = judge(Evidence(n_frames=100, rate_hz=100.0))
    assert q.verdict == "ok" and q.reasons == ()


def test_each_threshold_gives_its_level_from_the_evidence():
    e = Evidence(n_frames=1000, rate_hz=100.0,
                 residual_mm={"mean": Q.RESIDUAL_MEAN_MM[0] + 1.0, "per_marker_rmse": {"EPI_lat": Q.MARKER_RMSE_MM[1] + 1}},
                 frames={"not_converged": 5, "too_few_markers": 0},  # 0.5 % < 1 %: nothing
                 agreement_deg={"GH_X_elevation": Q.AGREEMENT_DEG[0] + 0.5})
    q = judge(e)
    codes = {(r.code, r.level.value) for r in q.reasons}
    assert codes == {("residual", "check"), ("marker_residual", "fail"), ("pf_ls_agreement", "check")}
    assert q.verdict == "fail"
    assert judge(Evidence(n_frames=1000, rate_hz=100.0, frames={"not_converged": 200})).verdict == "fail"  # 20 % > 10 %


def test_live_only_evidence_is_judged_by_the_same_list():
    live = LiveCounts(skipped=12, max_behind_s=0.5, swapped=(("RADIUS", "ULNA", 3.25),))
    q = judge(Evidence(n_frames=500, rate_hz=200.0, live=live))
    assert q.verdict == "fail"
    assert [r.code for r in q.reasons] == ["label", "live_skip"]
    assert "RADIUS and ULNA look swapped since t = 3.25 s" in q.reasons[0].message


def test_a_check_added_to_the_list_changes_the_verdict():
    extra = Check("wobble", "nothing", "none", lambda e: [Q.Reason("wobble", "check", "a check added in a test")])
    assert judge(Evidence(n_frames=10, rate_hz=10.0), (*CHECKS, extra)).verdict == "check"


def test_the_docs_name_every_check():
    text = " ".join(DOCS.read_text(encoding="utf-8").lower().split())
    missing = [c.name for c in CHECKS if c.name.lower() not in text]
    assert not missing, missing
    assert len({c.name for c in CHECKS}) == len(CHECKS)
