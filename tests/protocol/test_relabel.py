"""A relabel where it belongs: ``--relabel`` reads one trial's labels as others without touching the
static, ``--static-relabel`` the static only; bad relabels are one error naming the option."""
import dataclasses
import json

import pytest

from exubio.cli import main
from exubio.errors import InputError
from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.protocol.labels import parse_relabel, relabel_trajectories
from exubio.synth.simulate import simulate_trial


def _swap(traj, a, b):
    labels = list(traj.labels)
    i, j = labels.index(a), labels.index(b)
    labels[i], labels[j] = labels[j], labels[i]
    return dataclasses.replace(traj, labels=tuple(labels))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("relabel")
    model = load_model()
    static = simulate_trial(model, "abduction", duration_s=0.4, rate_hz=50.0, noise_mm=0.5, seed=5).trajectories
    task = simulate_trial(model, "flexion", duration_s=2.0, rate_hz=50.0, noise_mm=0.5, seed=6).trajectories
    return {"static": write_c3d(folder / "static.c3d", static),
            "swapped_static": write_c3d(folder / "swapped_static.c3d", _swap(static, "MET2", "MET5")),
            "task_swapped": write_c3d(folder / "task.c3d", _swap(task, "MET2", "MET5"))}


def _labels(out, stem="task"):
    s = json.loads((out / f"{stem}.ls.summary.json").read_text(encoding="utf-8"))
    return s, [r for r in s["quality"]["reasons"] if r["code"] == "label"]


def test_a_trial_relabel_fixes_the_trial_and_leaves_the_static_alone(tmp_path, files):
    base = ["-q", "reconstruct", str(files["task_swapped"]), "--static", str(files["static"]), "--method", "ls",
            "--no-report"]
    assert main([*base, "--out", str(tmp_path / "as_is")]) in (0, 1)
    _, found = _labels(tmp_path / "as_is")
    assert found and any("MET2" in r["message"] and "MET5" in r["message"] for r in found)
    assert main([*base, "--relabel", "MET2=MET5,MET5=MET2", "--out", str(tmp_path / "fixed")]) in (0, 1)
    summ, found = _labels(tmp_path / "fixed")
    assert not found and summ["quality"]["verdict"] != "fail"  # (a simulated static moves its hand: a check)
    static_labels = summ["calibration"]["labels"]  # the static was read as it is: no finding on it
    assert not static_labels


def test_a_static_relabel_fixes_the_static_only(tmp_path, files):
    out = tmp_path / "o"
    code = main(["-q", "reconstruct", str(files["task_swapped"]), "--static", str(files["swapped_static"]),
                 "--static-relabel", "MET2=MET5,MET5=MET2", "--relabel", "MET2=MET5,MET5=MET2", "--method", "ls",
                 "--no-report", "--out", str(out)])
    assert code in (0, 1)
    summ, found = _labels(out)
    assert not found and not summ["calibration"]["labels"]


@pytest.mark.parametrize("text,match", [("MET2", "not LABEL=LABEL"), ("MET2=MET5,MET2=SEML", "given twice"),
                                         ("=MET5", "not LABEL=LABEL")])
def test_a_malformed_relabel_is_one_error(text, match):
    with pytest.raises(InputError, match=match):
        parse_relabel(text)


def test_a_relabel_that_merges_or_names_a_missing_label_is_refused(files):
    traj = simulate_trial(load_model(), "abduction", duration_s=0.2, rate_hz=50.0).trajectories
    with pytest.raises(InputError, match="two markers labelled"):
        relabel_trajectories(traj, {"MET2": "MET5"})
    with pytest.raises(InputError, match="no label"):
        relabel_trajectories(traj, {"NOPE": "MET5"})


def test_static_relabel_needs_a_static(tmp_path, files, capsys):
    assert main(["-q", "reconstruct", str(files["task_swapped"]), "--static-relabel", "A=B", "--out",
                 str(tmp_path / "x")]) == 2
    assert "--static-relabel" in capsys.readouterr().err
