"""An interrupted `exubio reconstruct`, run again without --overwrite, resumes: the result sets that
the interrupted run left complete are kept (not refused, not computed again), the rest is computed,
and the files are those of an uninterrupted run (exubio.run.resume). Other inputs are still refused."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

import exubio.io.results as results
import exubio.report.trial_report as trial_report
from exubio.cli import main
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.synth.simulate import Motion, simulate_trial

pytestmark = [pytest.mark.exudyn, pytest.mark.slow]

KINDS = ("csv", "mot", "npz", "summary.json")


def _trial(path: Path, seed: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    sim = simulate_trial(load_model(), Motion.ABDUCTION, duration_s=1.0, rate_hz=50.0, noise_mm=0.5, seed=seed)
    return write_c3d(path, sim.trajectories)


@pytest.fixture(scope="module")
def trials(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("resume")
    return _trial(folder / "a.c3d", 1), _trial(folder / "b.c3d", 2)


def _bytes(out: Path, stem: str, method: str) -> dict[str, bytes]:
    return {k: (out / f"{stem}.{method}.{k}").read_bytes() for k in KINDS}


def _without_timings(summary: bytes) -> dict:
    data = json.loads(summary)
    for key in ("wall_time_s", "ms_per_frame", "timings_s"):
        data.pop(key, None)
    data.get("info", {}).pop("exudyn_cpu_times_s", None)
    return data


def test_ctrl_c_while_the_report_is_drawn_then_the_same_command_keeps_both_sets_and_draws_it(tmp_path, trials,
                                                                                           monkeypatch, capsys):
    """It was refused (exit 2, 'result file already exists') although both sets were complete."""
    a = trials[0]
    out = tmp_path / "out"
    argv = ["reconstruct", str(a), "--method", "both", "--out", str(out)]

    def interrupted(*args, **kw):
        raise KeyboardInterrupt
    with monkeypatch.context() as m:
        m.setattr(trial_report, "draw_trial_report", interrupted)  # the drawing, whatever the entry
        assert main(argv) == 130
    assert "the same command again resumes" in capsys.readouterr().err
    assert not (out / "a.report.pdf").exists()
    before = {m: _bytes(out, "a", m) for m in ("pf", "ls")}
    assert main(argv) == 0
    console = capsys.readouterr().out
    assert "[pf] kept" in console and "[ls] kept" in console, console
    assert {m: _bytes(out, "a", m) for m in ("pf", "ls")} == before  # kept as they were, not written again
    assert (out / "a.report.pdf").is_file() and (out / "a.report.png").is_file()
    # once the report is there, the same command keeps everything (nothing to do)
    png = (out / "a.report.png").read_bytes()
    assert main(argv) == 0
    assert "(kept from the earlier run)" in capsys.readouterr().out
    assert (out / "a.report.png").read_bytes() == png


def test_ctrl_c_between_the_two_sets_then_the_same_command_keeps_pf_and_writes_ls_as_a_full_run(tmp_path, trials,
                                                                                            monkeypatch, capsys):
    a = trials[0]
    full, out = tmp_path / "full", tmp_path / "out"
    assert main(["-q", "reconstruct", str(a), "--method", "both", "--no-report", "--out", str(full)]) == 0
    commit, calls = results.ResultSet.commit, [0]

    def second_interrupted(self, **kw):
        calls[0] += 1
        if calls[0] == 2:
            raise KeyboardInterrupt
        return commit(self, **kw)
    argv = ["-q", "reconstruct", str(a), "--method", "both", "--no-report", "--out", str(out)]
    with monkeypatch.context() as m:
        m.setattr(results.ResultSet, "commit", second_interrupted)
        assert main(argv) == 130
    assert (out / "a.pf.summary.json").is_file() and not list(out.glob("a.ls.*"))
    pf = _bytes(out, "a", "pf")
    capsys.readouterr()
    assert main(argv) == 0
    console = capsys.readouterr().out
    assert "[pf] kept" in console and "[ls] kept" not in console, console
    assert _bytes(out, "a", "pf") == pf
    ls, ref = _bytes(out, "a", "ls"), _bytes(full, "a", "ls")
    for kind in ("csv", "mot"):  # the LS set computed now is the uninterrupted run's
        assert ls[kind] == ref[kind], kind
    assert _without_timings(ls["summary.json"]) == _without_timings(ref["summary.json"])


def test_a_set_of_other_inputs_is_still_refused_and_overwrite_computes_it_again(tmp_path, trials, capsys):
    a, b = trials
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(a), "--method", "pf", "--no-report", "--out", str(out)]) == 0
    capsys.readouterr()
    # other PF options, then another trial file of the same name: the kept set would be wrong
    assert main(["-q", "reconstruct", str(a), "--method", "pf", "--gravity", "--no-report", "--out", str(out)]) == 2
    assert "a.pf.csv: result file already exists" in capsys.readouterr().err
    other = tmp_path / "other" / "a.c3d"
    other.parent.mkdir()
    other.write_bytes(b.read_bytes())
    assert main(["-q", "reconstruct", str(other), "--method", "pf", "--no-report", "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["-q", "reconstruct", str(a), "--method", "pf", "--gravity", "--no-report", "--out", str(out),
                 "--overwrite"]) == 0
    assert "[pf] kept" not in capsys.readouterr().out
    assert json.loads((out / "a.pf.summary.json").read_text())["info"]["gravity"] is True


def test_several_trials_interrupted_after_the_first_resume_with_the_second(tmp_path, trials, capsys):
    a, b = trials
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(a), "--method", "ls", "--out", str(out)]) == 0  # as if stopped after a
    capsys.readouterr()
    assert main(["-q", "reconstruct", str(a), str(b), "--method", "ls", "--out", str(out)]) == 0
    console = capsys.readouterr().out
    assert console.count("[ls] kept") == 1, console
    assert (out / "b.ls.summary.json").is_file() and (out / "b.report.pdf").is_file()


def test_a_set_made_by_other_code_is_refused_not_kept(tmp_path, trials, capsys, monkeypatch):
    """The same command after exubio's code changed (a development install between two commits keeps
    its version string, and the new code can give other angles, uncertainties or verdicts): the kept set
    is not taken as this code's (it would mix two codes' results in one study), the run stops on it as on
    a set of other inputs, and --overwrite computes it again. Without the change the set is kept."""
    import exubio.run.resume as resume

    a, _ = trials
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(a), "--method", "ls", "--no-report", "--out", str(out)]) == 0
    assert main(["-q", "reconstruct", str(a), "--method", "ls", "--no-report", "--out", str(out)]) == 0
    assert "[ls] kept" in capsys.readouterr().out
    key = json.loads((out / "a.ls.summary.json").read_text())["inputs_sha256"]
    monkeypatch.setattr(resume, "_FINGERPRINT", ["0" * 64])  # as if one source file of the package had changed
    assert main(["-q", "reconstruct", str(a), "--method", "ls", "--no-report", "--out", str(out)]) == 2
    assert "a.ls.csv: result file already exists" in capsys.readouterr().err
    assert main(["-q", "reconstruct", str(a), "--method", "ls", "--no-report", "--out", str(out), "--overwrite"]) == 0
    assert json.loads((out / "a.ls.summary.json").read_text())["inputs_sha256"] != key


def test_a_base_protocol_edited_between_two_runs_is_other_inputs(tmp_path, trials, capsys):
    """A session protocol that extends the lab's base: the base's filter changed after the first run makes
    the same command other inputs (refused without --overwrite, as any other input change), not a set to
    keep; the base as it was keeps it again."""
    a, _ = trials
    base, session = tmp_path / "base.yaml", tmp_path / "session.yaml"
    session.write_text("schema_version: 1\nextends: base.yaml\n")
    run = lambda: main(["-q", "reconstruct", str(a), "--method", "ls", "--no-report", "--protocol", str(session),
                        "--out", str(tmp_path / "out")])
    base.write_text("schema_version: 1\nextends: upper_limb_21\nfilter: {cutoff_hz: 6}\n")
    assert run() == 0
    base.write_text("schema_version: 1\nextends: upper_limb_21\nfilter: {cutoff_hz: 3}\n")
    capsys.readouterr()
    assert run() == 2
    assert "a.ls.csv: result file already exists" in capsys.readouterr().err
    base.write_text("schema_version: 1\nextends: upper_limb_21\nfilter: {cutoff_hz: 6}\n")
    assert run() == 0 and "[ls] kept" in capsys.readouterr().out


def test_the_code_fingerprint_follows_source_and_data_files_not_caches(tmp_path):
    from exubio.run.resume import code_fingerprint

    pkg = tmp_path / "pkg"
    (pkg / "data").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "m.py").write_text("x = 1\n")
    (pkg / "data" / "amp.json").write_text("{}")
    first = code_fingerprint(pkg)
    (pkg / "__pycache__" / "m.cpython-311.pyc").write_bytes(b"\0")
    (pkg / "m.nbi").write_bytes(b"\1")
    assert code_fingerprint(pkg) == first
    (pkg / "data" / "amp.json").write_text('{"girdle": 1}')
    assert code_fingerprint(pkg) != first
    (pkg / "data" / "amp.json").write_text("{}")
    (pkg / "data" / "amp.json").rename(pkg / "amp.json")  # the same bytes elsewhere: another package
    assert code_fingerprint(pkg) != first
