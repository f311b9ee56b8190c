"""Thorax landmarks are label-checked before the thorax frame is built (exubio.trust.thorax_check): two
exchanged landmarks are refused with one error naming them and the relabel that fixes them; the
files as labelled pass. Built from the real trials of ../shared/data (skipped when absent) and a
simulated trial."""
import dataclasses
import itertools
from pathlib import Path

import pytest

from exubio.cli import main
from exubio.errors import InputError
from exubio.io.c3d import write_c3d
from exubio.io.trial import read_trial
from exubio.model.load import load_model
from exubio.run.pipeline import load_inputs
from exubio.run.inputs import load_model_and_protocol, protocol_for_model
from exubio.io.resources import shipped_file
from exubio.synth.simulate import simulate_trial
from exubio.trust.thorax_check import check_thorax_labels, thorax_label_fit

pytestmark = pytest.mark.exudyn

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"real data folder {DATA} is absent")


def _swap(traj, a, b):
    labels = list(traj.labels)
    i, j = labels.index(a), labels.index(b)
    labels[i], labels[j] = labels[j], labels[i]
    return dataclasses.replace(traj, labels=tuple(labels))


@needs_data
@pytest.mark.parametrize("name", ["c3d/bioptim_exo_kinova_martin_tete_f3_1.c3d", "c3d/bioptim_exo_F0_boire_05.c3d",
                                  "trc/tsm_rmr_ABD01.trc"])
def test_every_exchange_of_two_thorax_landmarks_is_found_and_undone(name):
    model, protocol = load_model_and_protocol()
    if name.endswith(".trc"):
        protocol = protocol_for_model(model, shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols"))
    traj = read_trial(DATA / name)
    fit = check_thorax_labels(traj, protocol, model)  # as labelled: accepted
    assert fit is not None and not fit.swapped and fit.best == fit.labels
    for a, b in itertools.combinations(fit.labels, 2):
        bad = thorax_label_fit(_swap(traj, a, b), protocol, model)
        assert bad.swapped and bad.relabel() == {a: b, b: a}, (a, b, bad)
        assert bad.best_rms_mm == pytest.approx(fit.rms_mm)  # the proposed relabel gives back the file's fit


@needs_data
def test_a_swapped_manubrium_and_xiphoid_is_one_error_naming_them(tmp_path, capsys):
    """MAN and XYP exchanged in a real trial: exit 2, one message naming both labels and the
    relabel, before any work (today PF diverged blaming an epicondyle spring)."""
    traj = _swap(read_trial(DATA / "c3d" / "bioptim_exo_martin_dynamique.c3d"), "MAN", "XYP")
    path = write_c3d(tmp_path / "swapped.c3d", traj)
    out = tmp_path / "out"
    assert main(["-q", "reconstruct", str(path), "--method", "both", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "thorax landmarks look mislabelled" in err and "MAN: XYP" in err and "XYP: MAN" in err
    assert "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())


def test_a_simulated_trial_passes_and_its_swap_is_refused(tmp_path):
    model = load_model()
    sim = simulate_trial(model, "abduction", duration_s=1.0, rate_hz=50.0, noise_mm=1.0, seed=1)
    load_inputs(sim.trajectories)  # accepted as labelled
    with pytest.raises(InputError, match="C7.*T10|T10.*C7"):
        load_inputs(_swap(sim.trajectories, "C7", "T10"))


@needs_data
def test_the_fit_does_not_depend_on_the_block_of_frames(monkeypatch):
    """The landmark distances are computed a block of frames at a time (issue 38's memory bound: no
    (frames, n, n, 3) array of a long trial): the fit is the same to the last bit whatever the block."""
    import exubio.trust.thorax_check as tc

    model, protocol = load_model_and_protocol()
    traj = _swap(read_trial(DATA / "c3d" / "bioptim_exo_martin_dynamique.c3d"), "MAN", "XYP")
    whole = thorax_label_fit(traj, protocol, model)
    monkeypatch.setattr(tc, "BLOCK_FRAMES", 97)  # many blocks, the last one short
    blocks = thorax_label_fit(traj, protocol, model)
    assert blocks == whole and blocks.swapped
