"""``exubio study --template`` prints a study file that exubio reads as written (every key it
explains is a key the study reader takes, the shipped protocol and model by name), and ``exubio
study`` without a study file says what it expects, exit code 2."""
from __future__ import annotations

import pytest

from exubio.cli import main
from exubio.run.study import load_study


def test_the_template_is_a_study_file_exubio_reads(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["study", "--template"]) == 0
    (tmp_path / "study.yaml").write_text(capsys.readouterr().out, encoding="utf-8")
    for f in ("S01/static.c3d", "S01/move.c3d", "S01/raise.c3d", "S01/task_01.c3d", "S01/task_03.c3d", "S02/a.trc"):
        (tmp_path / f).parent.mkdir(exist_ok=True)
        (tmp_path / f).write_bytes(b"")
    spec = load_study(tmp_path / "study.yaml")
    s1, s2 = spec.sessions
    assert (s1.subject, s1.session, s2.subject, s2.session) == ("S01", "day1", "S02", "s1")  # counted per subject
    assert s1.protocol.name == "upper_limb_21.yaml" and s1.protocol.is_file()  # shipped, found by name
    assert s1.model.name == "upper_extremity.yaml" and s1.model.is_file()
    assert [t.name for t in s1.trials] == ["task_01.c3d", "task_03.c3d"] and s1.static.name == "static.c3d"
    assert s1.relabel_of(s1.trials[1]) == {"EPI_lat": "EPI_med", "EPI_med": "EPI_lat"}
    assert s1.relabel_of(s1.trials[0]) == {"RADIUS": "ULNA", "ULNA": "RADIUS"}
    assert s2.static_frames == "0:50" and [t.name for t in s2.trials] == ["a.trc"]


def test_study_without_a_file_says_what_it_expects(capsys):
    assert main(["study"]) == 2
    err = capsys.readouterr().err
    assert "STUDY.yaml" in err and "--template" in err and "Traceback" not in err


@pytest.mark.parametrize("name", ["no_such_protocol", "subdir/upper_limb_21"])
def test_a_protocol_that_is_neither_a_file_nor_shipped_is_named(tmp_path, name):
    from exubio.errors import InputError

    (tmp_path / "t.c3d").write_bytes(b"")
    (tmp_path / "study.yaml").write_text(f"schema_version: 1\nsessions:\n  - subject: S\n    protocol: {name}\n"
                                         "    trials: [t.c3d]\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"sessions\[0\]\.protocol"):
        load_study(tmp_path / "study.yaml")
