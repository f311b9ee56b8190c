"""What the model's girdle cannot follow of the bones (exubio.truth.girdle): the fit's arithmetic, the
shipped matrix is the fit of the shared pin trials, and with it a lab's u covers a task it was not
fitted on where it did not before (the bone, not exubio, is the truth)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError, ModelError
from exubio.io.yaml import read_yaml
from exubio.model.load import DEFAULT_MODEL
from exubio.trust.sta_amplitude import load_sta_amplitude
from exubio.truth.girdle import GirdleMotion, fit_girdle, girdle_motion, girdle_offset, offset_likelihoods
from exubio.truth.sta_format import read_sta_trial

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "truth" / "sta_opendata"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/truth/sta_opendata is absent")
RATE = 300.0


def test_the_fit_is_the_girdle_error_and_its_covariance_with_the_skin_per_rad2_of_driver():
    """Two made-up trials: C = sum(g g^T + g s^T + s g^T) / sum(theta^2) over the finite frames of the trials
    whose verdict is not fail, s = skin - g; a trial that failed adds nothing; none left is an error."""
    rng = np.random.default_rng(5)
    a = GirdleMotion("a", rng.normal(size=(50, 6)), rng.normal(size=(50, 6)), rng.uniform(0, 2, 50), "ok")
    b = GirdleMotion("b", rng.normal(size=(30, 6)), rng.normal(size=(30, 6)), rng.uniform(0, 2, 30), "check")
    b.xi[3] = np.nan  # a frame where a bone is not seen
    bad = GirdleMotion("c", 100 * rng.normal(size=(20, 6)), rng.normal(size=(20, 6)), rng.uniform(0, 2, 20), "fail")
    g = np.concatenate([a.xi, np.delete(b.xi, 3, axis=0)])
    s = np.concatenate([a.skin, np.delete(b.skin, 3, axis=0)]) - g
    th = np.concatenate([a.theta, np.delete(b.theta, 3)])
    expect = (g.T @ g + g.T @ s + s.T @ g) / np.sum(th ** 2)
    C = fit_girdle([a, b, bad])
    np.testing.assert_allclose(C, expect, rtol=1e-12)
    np.testing.assert_allclose(C, C.T, rtol=0, atol=1e-15)
    with pytest.raises(InputError, match="fail"):
        fit_girdle([bad])
    np.testing.assert_allclose(fit_girdle([a, b, bad], offset_rad=0.3),
                               (g.T @ g + g.T @ s + s.T @ g) / np.sum((th + 0.3) ** 2), rtol=1e-12)


@pytest.mark.parametrize("true_deg", [0, 30, 60])
def test_the_offset_chosen_is_the_one_a_made_up_girdle_error_grows_from(true_deg):
    """Three made-up trials whose girdle error per axis has the spread sd_axis (theta + theta_0): the offset
    whose held-out likelihood is highest is theta_0, on the 5 deg grid; one usable trial cannot choose."""
    rng = np.random.default_rng(true_deg)
    sd = np.radians([3.0, 5.0, 8.0, 1.5, 1.0, 2.5])
    trials = []
    for i in range(3):
        theta = np.abs(np.sin(np.linspace(0, 3 * np.pi, 3000))) * rng.uniform(1.2, 2.2)  # rests and raises
        g = rng.normal(size=(3000, 6)) * sd * (theta + np.radians(true_deg))[:, None]
        trials.append(GirdleMotion(str(i), g, g.copy(), theta, "ok"))
    lik = offset_likelihoods(trials)
    assert max(lik, key=lik.get) == true_deg, lik
    assert np.degrees(girdle_offset(trials)) == pytest.approx(true_deg)
    with pytest.raises(InputError, match="two at least"):
        girdle_offset(trials[:1] + [GirdleMotion("x", trials[1].xi, trials[1].skin, trials[1].theta, "fail")])


@needs_data
@pytest.mark.slow
@pytest.mark.exudyn
def test_the_shipped_girdle_is_the_fit_of_the_shared_pin_trials():
    """exubio/data/sta_amplitude_s2m.json's girdle matrix is fit_girdle on the S2M trials of ../shared
    (punching left out: its LS verdict with the markers carried by the bones is fail), to the file's 6
    significant digits; the pinned scapula is several degrees off the model's at the arm's highest."""
    generic = read_yaml(DEFAULT_MODEL, error=ModelError)
    motions = [girdle_motion(read_sta_trial(f), generic, rate_hz=RATE) for f in sorted(DATA.glob("*S2M*.mat"))]
    assert [m.verdict == "fail" for m in motions] == ["punching" in m.file for m in motions]
    shipped = load_sta_amplitude()
    offset = girdle_offset(motions)
    assert offset == pytest.approx(shipped.girdle_offset_rad, abs=1e-6)
    np.testing.assert_allclose(fit_girdle(motions, offset_rad=offset), shipped.girdle, rtol=1e-5, atol=1e-9)
    abd = next(m for m in motions if "armAbd" in m.file)
    high = np.degrees(abd.theta) > 90
    assert np.degrees(np.sqrt(np.nanmean(abd.xi[high, 2] ** 2))) > 5  # about the scapula's Z axis


@needs_data
@pytest.mark.slow
@pytest.mark.exudyn
def test_with_the_girdle_fitted_on_two_tasks_a_labs_u_covers_the_third():
    """S2M eating, judged with the u a lab's run gives (LS, no still-thorax term): without the girdle term
    the bone's ST upward rotation lies within +-2u in under 80 % of its measured frames (studies/README.md:
    72-73 %); with the term fitted on the abduction and the flexion alone (its offset chosen on them), in at
    least 85 %."""
    from exubio.truth.compare import compare_bone_trial
    from exubio.truth.lab_run import setup_lab_run

    generic = read_yaml(DEFAULT_MODEL, error=ModelError)
    others = [girdle_motion(read_sta_trial(DATA / f"dataSample_S2M_{t}.mat"), generic, rate_hz=RATE)
              for t in ("armAbd", "armFlex")]
    base = dataclasses.replace(load_sta_amplitude(), girdle=None)
    run = setup_lab_run(read_sta_trial(DATA / "dataSample_S2M_eating.mat"), generic, rate_hz=RATE)
    coverage = {}
    o = girdle_offset(others)
    for key, amp in (("without", base), ("with", dataclasses.replace(base, girdle=fit_girdle(others, offset_rad=o),
                                                                     girdle_offset_rad=o))):
        comp, _ = compare_bone_trial(run, methods=("ls",), amplitude=amp)
        coverage[key] = comp.angles["ST_X_upward_rotation"]["ls"].lab
    assert coverage["without"].coverage < 0.80, coverage
    assert coverage["with"].coverage >= 0.85 and coverage["with"].measured_fraction > 0.9, coverage
