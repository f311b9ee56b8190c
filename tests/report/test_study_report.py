"""The study report (exubio.report.study_report) of a hundred trials with long subject, trial and
error texts: every name written in full and once, every text block on its page and apart from the
others (no cut name, no footer off the page), the rows in the study's order across the pages,
each page numbered, and a row never split over two pages."""
from __future__ import annotations

import json

import pytest
from page_layout import laid_out_apart

from exubio.report.study_report import _wrap, build_study_report, study_pages

LONG_ERROR = ("trial /data/lab/study/S03/day1/task.c3d: marker 'ACRO' is missing from the file in frames 0-399; "
              "the protocol upper_limb_21 needs it on the scapula; relabel it or drop it from the protocol. ")


def _study(n: int) -> dict:
    trials = []
    for i in range(n):
        failed = i % 17 == 5
        trials.append({
            "subject": ("subject_with_a_long_identifier_" if i % 11 == 0 else "") + f"S{i // 10:02d}",
            "session": f"day{i % 3}",
            "trial": f"S{i // 10:02d}_{'a_very_long_trial_name_of_many_words_' * (1 + i % 2) if i % 7 == 0 else ''}"
                     f"task_{i}.c3d",
            "status": "failed" if failed else "done",
            "pf_verdict": None if failed else ["ok", "check", "fail"][i % 3],
            "ls_verdict": None if failed else ["ok", "check"][i % 2],
            "frames": "" if failed else 400 + i, "pf_residual_mm": None if failed else 1.0 + i / 50,
            "ls_residual_mm": None if failed else 1.1 + i / 50, "pf_ls_max_rmse_deg": None if failed else i / 200,
            "wall_s": 3.0 + i, "folder": f"/x/{i}", "error": LONG_ERROR * (1 + i % 3) if failed else ""})
    return {"study": "a study of " + "many " * 8 + "trials", "source": "/data/lab/study/study.yaml", "trials": trials,
            "counts": {"done": sum(t["status"] == "done" for t in trials), "skipped (complete)": 0,
                       "failed": sum(t["status"] == "failed" for t in trials)}, "units": {}}


@pytest.mark.parametrize("width", [5, 13, 29, 60])
def test_wrapping_keeps_every_character_within_the_width(width):
    name = "S01_a_very_long_trial_name_of_many_words_and-more.dashes/and.dots_task_12.c3d"
    lines = _wrap(name, width)
    assert all(len(line) <= width for line in lines)
    assert "".join(lines) == name
    words = LONG_ERROR.strip()
    lines = _wrap(words, width)
    assert all(len(line) <= width for line in lines)
    assert "".join(lines).replace(" ", "") == words.replace(" ", "")


def test_a_hundred_trials_of_long_names_fit_their_pages_in_full_and_in_order():
    data = _study(100)
    figs = study_pages(data)
    assert len(figs) >= 3  # a hundred rows do not fit one page
    seen = []
    for k, fig in enumerate(figs):
        boxes = laid_out_apart(fig)
        texts = [t for t, _ in boxes]
        assert f"page {k + 1} of {len(figs)}" in texts
        assert any(t.startswith("verdicts: ok = nothing found") for t in texts)  # the footer, on the page
        cells = {t.replace("\n", "") for t in texts}
        seen += [i for i, row in enumerate(data["trials"]) if row["trial"] in cells]
    assert seen == list(range(100))  # every trial once, in the study's order
    page1 = [t for t, _ in laid_out_apart(figs[0])]
    assert any("100 trials" in t and "failed: 6" in t for t in page1)
    done = [i for i in range(100) if i % 17 != 5]
    pf = [sum(i % 3 == k for i in done) for k in range(3)]
    ls = [sum(i % 2 == k for i in done) for k in range(2)]
    tally = f"PF: ok {pf[0]}, check {pf[1]}, fail {pf[2]}   LS: ok {ls[0]}, check {ls[1]}, fail 0"
    assert any(tally in t for t in page1), tally
    subjects = {t.replace("\n", "") for fig in figs for t, _ in laid_out_apart(fig)}
    assert "subject_with_a_long_identifier_S00" in subjects
    errors = [t for fig in figs for t, _ in laid_out_apart(fig) if "ACRO" in t]
    assert len(errors) == 6 and all(e.replace("\n", "").count("missing") in (1, 2, 3) for e in errors)
    assert not any("/data/lab" in e for e in errors)  # paths as file names, as on the trial report


def test_a_reason_longer_than_a_page_is_cut_where_it_says_so():
    data = _study(3)
    data["trials"][1].update(status="failed", error=LONG_ERROR * 200)  # some 40,000 characters
    figs = study_pages(data)
    texts = [t for fig in figs for t, _ in laid_out_apart(fig)]
    reason = next(t for t in texts if "ACRO" in t)
    assert reason.endswith("... (in full in study.json)") and reason.count("\n") == 7  # 8 lines


def test_one_trial_and_no_trial_give_one_page(tmp_path):
    for n in (0, 1):
        figs = study_pages(_study(n))
        assert len(figs) == 1
        laid_out_apart(figs[0])
    path = tmp_path / "study.json"
    path.write_text(json.dumps(_study(40)), encoding="utf-8")
    pdf = build_study_report(path, tmp_path / "study.report.pdf")
    assert pdf.read_bytes().count(b"/Type /Page\n") + pdf.read_bytes().count(b"/Type /Page ") >= 2
