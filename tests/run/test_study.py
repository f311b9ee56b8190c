"""Studies (exubio.run.study, `exubio study`): trials of the same name in two sessions never collide,
a re-run resumes (complete trials skipped, incomplete ones redone, leftovers removed), a broken
trial or session never stops the others, Dask gives the same files as a serial run, and SIGINT /
SIGKILL leave every trial's result set complete or absent."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from exubio.cli import main
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial, write_simulated_trial
from exubio.run.study import DONE_FILE, load_study

pytestmark = [pytest.mark.exudyn, pytest.mark.slow]

MODEL = Path(__file__).resolve().parents[2] / "models" / "upper_extremity.yaml"


def _trial(path: Path, motion: str = "abduction", seed: int = 1, duration: float = 2.0) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    sim = simulate_trial(load_model(), motion, duration_s=duration, rate_hz=50.0, noise_mm=0.5, seed=seed)
    write_simulated_trial(sim, path)
    return path


def _study(tmp: Path, sessions: list[dict], **top) -> Path:
    path = tmp / "study.yaml"
    path.write_text(yaml.safe_dump({"schema_version": 1, "name": "t", "report": False, **top, "sessions": sessions}), encoding="utf-8")
    return path


def _rows(out: Path) -> list[dict]:
    return json.loads((out / "study.json").read_text(encoding="utf-8"))["trials"]


def _complete_or_absent(out: Path) -> None:
    """Every trial folder holds a complete result set with DONE.json; no half-written one."""
    for d in out.rglob("*"):
        if d.is_dir() and not d.name.startswith(".") and d.parent.parent.parent == out:
            assert (d / DONE_FILE).is_file(), f"{d} has no {DONE_FILE}"
            files = json.loads((d / DONE_FILE).read_text(encoding="utf-8"))["files"]
            assert sorted(p.name for p in d.iterdir() if p.name != DONE_FILE) == sorted(files)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("study_data")
    _trial(tmp / "a" / "trial.c3d", "abduction", 1)
    _trial(tmp / "b" / "trial.c3d", "flexion", 2)
    _trial(tmp / "b" / "other.c3d", "abduction", 3)
    return tmp


def test_same_trial_name_in_two_sessions_and_resume(data, tmp_path):
    study = _study(data, [{"subject": "S01", "session": "day1", "trials": ["a/*.c3d"], "methods": ["ls"]},
                          {"subject": "S01", "session": "day2", "trials": ["b/*.c3d"], "methods": ["ls"]}])
    out = tmp_path / "out"
    assert main(["-q", "study", str(study), "--out", str(out)]) == 0
    a, b = out / "S01" / "day1" / "trial" / "trial.ls.csv", out / "S01" / "day2" / "trial" / "trial.ls.csv"
    assert a.is_file() and b.is_file() and a.read_bytes() != b.read_bytes()  # two trials, two result sets
    rows = _rows(out)
    assert [(r["session"], r["trial"], r["status"]) for r in rows] == [
        ("day1", "trial.c3d", "done"), ("day2", "other.c3d", "done"), ("day2", "trial.c3d", "done")]
    assert all(r["frames"] == 100 and r["ls_residual_mm"] > 0 and r["wall_s"] > 0 for r in rows)
    assert (out / "study.csv").read_text(encoding="utf-8").splitlines()[0].startswith("subject,session,trial,status")
    _complete_or_absent(out)
    # resume: nothing to redo; then an incomplete set (no DONE.json) and a killed run's leftover
    before = a.stat().st_mtime_ns
    assert main(["-q", "study", str(study), "--out", str(out)]) == 0
    assert a.stat().st_mtime_ns == before and {r["status"] for r in _rows(out)} == {"skipped (complete)"}
    (out / "S01" / "day2" / "other" / DONE_FILE).unlink()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    leftover = out / "S01" / "day1" / f".tmp-trial-{int(dead.stdout)}-2"  # of a run that was killed
    leftover.mkdir()
    assert main(["-q", "study", str(study), "--out", str(out)]) == 0
    assert [r["status"] for r in _rows(out)] == ["skipped (complete)", "done", "skipped (complete)"]
    assert not leftover.exists()
    _complete_or_absent(out)


def test_broken_trials_and_sessions_do_not_stop_the_study(data, tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "corrupt.c3d").write_bytes(b"not a c3d file at all" * 10)
    sim = simulate_trial(load_model(), "abduction", duration_s=1.0, rate_hz=50.0, seed=4)
    from exubio.io.c3d import write_c3d
    from exubio.types import Trajectories

    keep = [i for i, lb in enumerate(sim.trajectories.labels) if lb not in ("MET2", "MET5")]  # the wrist unmeasured
    t = sim.trajectories
    write_c3d(bad / "no_epicondyle.c3d", Trajectories(labels=tuple(t.labels[i] for i in keep),
                                                      positions_m=t.positions_m[:, keep], rate_hz=t.rate_hz,
                                                      time_s=t.time_s, source="x", units_in_file="m"))
    model = yaml.safe_load(MODEL.read_text(encoding="utf-8"))
    model["segments"][1]["mass_fraction"] = "abc"
    (tmp_path / "broken_model.yaml").write_text(yaml.safe_dump(model), encoding="utf-8")
    study = tmp_path / "study.yaml"
    study.write_text(yaml.safe_dump({"schema_version": 1, "report": False, "methods": ["ls"], "sessions": [
        {"subject": "S01", "trials": [str(data / "a" / "trial.c3d")]},
        {"subject": "S02", "trials": [str(bad / "corrupt.c3d"), str(bad / "no_epicondyle.c3d")]},
        {"subject": "S03", "model": str(tmp_path / "broken_model.yaml"), "trials": [str(data / "b" / "other.c3d")]},
        {"subject": "S04", "trials": [str(data / "b" / "trial.c3d")]},
    ]}), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["-q", "study", str(study), "--out", str(out)]) == 1  # some trials failed
    rows = {(r["subject"], r["trial"]): r for r in _rows(out)}
    assert rows[("S01", "trial.c3d")]["status"] == "done" and rows[("S04", "trial.c3d")]["status"] == "done"
    assert rows[("S02", "corrupt.c3d")]["status"] == "failed" and "corrupt.c3d" in rows[("S02", "corrupt.c3d")]["error"]
    assert "MET2" in rows[("S02", "no_epicondyle.c3d")]["error"]
    assert rows[("S03", "other.c3d")]["status"] == "failed" and "mass_fraction" in rows[("S03", "other.c3d")]["error"]
    _complete_or_absent(out)
    assert "failed: S02" in capsys.readouterr().out


def test_study_file_errors_are_refused_before_any_work(tmp_path, data, capsys):
    cases = {
        "unknown key": {"schema_version": 1, "sessions": [{"subject": "S", "trials": ["a/*.c3d"], "speed": 2}]},
        "no match": {"schema_version": 1, "sessions": [{"subject": "S", "trials": ["nothing/*.c3d"]}]},
        "same session": {"schema_version": 1, "sessions": [{"subject": "S", "session": "x", "trials": ["a/*.c3d"]},
                                                           {"subject": "S", "session": "x", "trials": ["b/*.c3d"]}]},
        "bad method": {"schema_version": 1, "methods": ["kalman"], "sessions": [{"subject": "S", "trials": ["a/*"]}]},
    }
    for what, content in cases.items():
        path = data / f"bad_{what.replace(' ', '_')}.yaml"
        path.write_text(yaml.safe_dump(content), encoding="utf-8")
        out = tmp_path / what.replace(" ", "_")
        assert main(["-q", "study", str(path), "--out", str(out)]) == 2, what
        assert str(path) in capsys.readouterr().err, what
        assert not out.exists(), what


def test_dask_local_cluster_gives_the_same_files_as_a_serial_run(data, tmp_path):
    pytest.importorskip("distributed")
    study = _study(data, [{"subject": "S01", "session": "day2", "trials": ["b/*.c3d"]}])
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    assert main(["-q", "study", str(study), "--out", str(serial)]) == 0
    assert main(["-q", "study", str(study), "--out", str(dask), "--scheduler", "local:2"]) == 0
    names = sorted(p.relative_to(serial) for p in serial.rglob("*") if p.suffix in (".csv", ".mot") and
                   p.name != "study.csv")
    assert len(names) >= 8
    for rel in names:
        assert (serial / rel).read_bytes() == (dask / rel).read_bytes(), rel
    assert [r["status"] for r in _rows(dask)] == ["done", "done"]


def test_two_trials_of_one_name_in_one_session_are_refused(data):
    from exubio.errors import InputError

    study = _study(data, [{"subject": "S01", "trials": ["b/*.c3d", "a/trial.c3d"]}])
    with pytest.raises(InputError, match="several trials named"):
        load_study(study)
    spec = load_study(_study(data, [{"subject": "S01", "trials": ["b/*.c3d"]}]))
    assert [t.name for t in spec.sessions[0].trials] == ["other.c3d", "trial.c3d"]
    assert all(t.is_absolute() or t.exists() for t in spec.sessions[0].trials)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_interrupted_study_leaves_complete_sets_and_the_next_run_finishes(tmp_path, sig):
    for k in range(4):
        _trial(tmp_path / "d" / f"t{k}.c3d", "abduction", 10 + k, duration=6.0)
    study = _study(tmp_path, [{"subject": "S01", "trials": ["d/*.c3d"], "methods": ["pf", "ls"]}])
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "exubio.cli", "-q", "study", str(study), "--out", str(out)]
    for delay in (4.0, 9.0):
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, encoding="utf-8",
                             env={**os.environ, "PYTHONUNBUFFERED": "1"})
        time.sleep(delay)
        t0 = time.perf_counter()
        p.send_signal(sig)
        _, err = p.communicate(timeout=60)
        stopped = time.perf_counter() - t0
        if sig == signal.SIGINT and p.returncode != 0:  # 0: it had finished before the signal
            assert p.returncode == 130 and "interrupted" in err.splitlines()[-1]
            assert stopped < 5.0  # about a second on an idle machine; CI machines are slower
        _complete_or_absent(out)
    assert subprocess.run(cmd, capture_output=True, text=True, encoding="utf-8", timeout=300).returncode == 0
    _complete_or_absent(out)
    assert [r["status"] for r in _rows(out)] and all(r["status"] != "failed" for r in _rows(out))
    assert not list(out.rglob(".tmp-*"))


def test_reconstruct_on_dask_writes_the_files_of_a_local_run(data, tmp_path):
    pytest.importorskip("distributed")
    trials = [str(data / "b" / "trial.c3d"), str(data / "b" / "other.c3d")]
    local, dask = tmp_path / "local", tmp_path / "dask"
    assert main(["-q", "reconstruct", *trials, "--method", "ls", "--no-report", "--out", str(local)]) == 0
    assert main(["-q", "reconstruct", *trials, "--method", "ls", "--no-report", "--out", str(dask),
                 "--scheduler", "local:2"]) == 0
    files = sorted(p.name for p in local.iterdir() if p.suffix in (".csv", ".mot"))
    assert len(files) == 4  # per trial: the angles as .csv and .mot
    for name in files:
        assert (local / name).read_bytes() == (dask / name).read_bytes(), name
    assert main(["-q", "reconstruct", *trials, "--method", "ls", "--out", str(tmp_path / "x"),
                 "--scheduler", "nowhere"]) == 2


def test_local_dask_workers_keep_glibc_malloc_defaults_and_no_profiler():
    """The workers of a local cluster do not get Dask's MALLOC_TRIM_THRESHOLD_ (it fixes glibc's
    mmap threshold: every trial array above 128 kB mapped afresh) nor its statistical profiler."""
    pytest.importorskip("distributed")
    from exubio.run.executors import map_on_scheduler

    def probe(_):
        import dask

        return os.environ.get("MALLOC_TRIM_THRESHOLD_"), dask.config.get("distributed.worker.profile.enabled")

    out = map_on_scheduler(probe, [0, 1], "local:1", on_error=lambda item, exc: exc)
    inherited = os.environ.get("MALLOC_TRIM_THRESHOLD_")  # (a value set by the user is kept)
    assert out == [(inherited, False), (inherited, False)]


def _listening_addresses(pid: int | None = None) -> list[str]:
    """The local IPv4/IPv6 addresses (hex, as /proc/net/tcp* gives them) of the listening TCP sockets
    of the process ``pid`` (None: the calling one)."""
    pid = pid or os.getpid()
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            link = os.readlink(fd)
        except OSError:
            continue
        if link.startswith("socket:["):
            inodes.add(link[8:-1])
    out = []
    for table in ("tcp", "tcp6"):
        path = Path(f"/proc/{pid}/net/{table}")
        for line in path.read_text().splitlines()[1:] if path.exists() else []:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # state LISTEN, a socket of this process
                out.append(fields[1].split(":")[0])
    return out


def test_a_local_dask_cluster_listens_on_the_loopback_only():
    """Its HTTP server listened on 0.0.0.0 (dashboard_address ":0"): open to the lab's network while
    a study ran. Every listening socket of this process and of its workers is on 127.0.0.1 now."""
    pytest.importorskip("distributed")
    if not Path("/proc/self/net/tcp").exists():
        pytest.skip("reads Linux's /proc/net/tcp")
    from exubio.run.executors import map_on_scheduler

    loopback = {"0100007F", "00000000000000000000000001000000"}  # 127.0.0.1, ::1 as /proc writes them
    seen = []
    out = map_on_scheduler(_listening_addresses, [None], "local:1", on_error=lambda item, exc: exc,
                           on_done=lambda _: seen.append(_listening_addresses(os.getpid())))
    assert not isinstance(out[0], Exception), out
    here, worker = seen[0], out[0]  # this process's sockets while the cluster runs; the worker's own
    assert here and set(here) <= loopback, here
    assert worker and set(worker) <= loopback, worker


def test_a_relabel_fixes_one_trial_of_a_session_without_touching_the_others(data, tmp_path):
    """trial_relabel reads one trial's labels as others, for that trial only; the session's other
    trials and its static are read as they are; a relabel naming a trial the session lacks is refused."""
    import dataclasses

    from exubio.io.c3d import write_c3d, read_c3d

    folder = tmp_path / "sess"
    folder.mkdir()
    good = read_c3d(data / "b" / "other.c3d")
    write_c3d(folder / "good.c3d", good)
    labels = list(good.labels)
    i, j = labels.index("MET2"), labels.index("MET5")
    labels[i], labels[j] = labels[j], labels[i]
    write_c3d(folder / "swapped.c3d", dataclasses.replace(good, labels=tuple(labels)))
    session = {"subject": "S", "trials": ["sess/*.c3d"], "methods": ["ls"], "static": "sess/good.c3d"}
    for fixed in (False, True):
        extra = {"trial_relabel": {"swapped.c3d": {"MET2": "MET5", "MET5": "MET2"}}} if fixed else {}
        study = tmp_path / f"study_{fixed}.yaml"
        study.write_text(yaml.safe_dump({"schema_version": 1, "report": False, "sessions": [{**session, **extra}]}),
                         encoding="utf-8")
        out = tmp_path / f"out_{fixed}"
        main(["-q", "study", str(study), "--out", str(out)])
        for trial in ("good", "swapped"):
            summ = json.loads(next((out / "S" / "s1" / trial).glob("*.ls.summary.json")).read_text(encoding="utf-8"))
            labelled = [r for r in summ["quality"]["reasons"] if r["code"] == "label"]
            assert bool(labelled) == (trial == "swapped" and not fixed), (fixed, trial, labelled)
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"schema_version": 1, "sessions": [
        {**session, "trial_relabel": {"nothere.c3d": {"A": "B"}}}]}), encoding="utf-8")
    assert main(["-q", "study", str(bad), "--out", str(tmp_path / "x")]) == 2


def test_leftovers_of_killed_runs_go_a_running_studys_stay(tmp_path):
    """A second study into the same folder removed every .tmp-* folder, those of a study still at work too."""
    from exubio.run.study import clean_leftovers

    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True).stdout)
    trial = tmp_path / "S01" / "s1"
    trial.mkdir(parents=True)
    killed = [trial / f".tmp-t0-{dead}-123", trial / f".tmp-calibration-{dead}"]
    running = [trial / f".tmp-t1-{os.getpid()}-456", trial / f".tmp-calibration-{os.getpid()}"]
    for d in killed + running:
        d.mkdir()
    killed_file = trial / f".study.csv.{dead}.0123abcd.tmp.csv"
    running_file = trial / f".study.csv.{os.getpid()}.0123abcd.tmp.csv"
    killed_file.write_text("x")
    running_file.write_text("x")
    removed = clean_leftovers(tmp_path)
    assert sorted(removed) == sorted(killed + [killed_file])
    assert all(p.exists() for p in running + [running_file])


def test_a_trial_calibrated_on_its_own_frames_names_its_model_where_it_is(data, tmp_path):
    """A study writes each trial in a temporary folder and renames it into place: the calibrated
    model file its summary and .npz name is the one in the trial's folder, not the temporary one."""
    import numpy as np

    study = _study(data, [{"subject": "S01", "session": "day1", "trials": ["a/*.c3d"], "methods": ["ls"],
                           "static_frames": "0:30"}])
    out = tmp_path / "out"
    assert main(["-q", "study", str(study), "--out", str(out)]) == 0
    folder = out / "S01" / "day1" / "trial"
    summary = json.loads((folder / "trial.ls.summary.json").read_text(encoding="utf-8"))
    named = Path(summary["calibration"]["model_file"])
    assert named == folder / "trial.model.yaml" and named.is_file()
    with np.load(folder / "trial.ls.npz") as z:
        assert Path(json.loads(str(z["metadata_json"]))["model"]) == named
    assert ".tmp-" not in (folder / "trial.ls.summary.json").read_text(encoding="utf-8")


def test_a_study_says_which_trial_of_how_many_and_the_time_left(data, tmp_path, capsys):
    study = _study(data, [{"subject": "S01", "session": "day1", "trials": ["a/*.c3d"], "methods": ["ls"]},
                          {"subject": "S01", "session": "day2", "trials": ["b/*.c3d"], "methods": ["ls"]}])
    assert main(["study", str(study), "--out", str(tmp_path / "out")]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("[")]
    assert len(lines) == 3, lines
    assert re.match(r"\[1/3, about \d+ (s|min) left\] S01/day\d/\w+\.c3d: done", lines[0]), lines
    assert re.match(r"\[2/3, about \d+ (s|min) left\] S01/day\d/\w+\.c3d: done", lines[1]), lines
    assert re.match(r"\[3/3\] S01/day\d/\w+\.c3d: done", lines[2]), lines
