"""Joint moments against a known truth: `exubio simulate --body-mass --hand-load-kg` writes the
exact moments of its motion (checked here against biorbd's inverse dynamics of the same exact
states, so the truth does not rest on exubio.dynamics alone); noise-free reconstructions (PF and
LS) of a slow raise and a fast one (70 kg, 2 kg in the hand) give moments within 1 % of their peak;
`exubio reconstruct --body-mass` writes <stem>.<method>.moments.csv in its result set and the peaks
in summary.json; exubio.moments gives the same table as a DataFrame."""
import dataclasses
import json
import locale

import numpy as np
import pytest

import exubio
from exubio.cli import main
from exubio.dynamics.inertia import dynamics_model
from exubio.dynamics.moments import joint_moments
from exubio.dynamics.moments_file import read_moments_csv
from exubio.export import write_biomod
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial

pytestmark = pytest.mark.exudyn

MASS, LOAD = 70.0, 2.0
MOMENTS = ("GH_X_moment_Nm", "GH_Y_moment_Nm", "GH_Z_moment_Nm", "elbow_X_moment_Nm", "elbow_Z_moment_Nm",
           "wrist_X_moment_Nm", "wrist_Z_moment_Nm", "elbow_flexion_moment_Nm", "forearm_pronation_moment_Nm",
           "wrist_flexion_moment_Nm", "wrist_radial_deviation_moment_Nm")


@pytest.fixture(autouse=True)
def _keep_the_locale():
    before = locale.setlocale(locale.LC_ALL)
    yield
    locale.setlocale(locale.LC_ALL, before)


@pytest.fixture(scope="module")
def model():
    return load_model(body_mass_kg=MASS)


def worst_share_of_peak(got, truth, frames=slice(None)):
    """Largest |error| of every moment column over ``frames``, as a share of the truth's peak."""
    out = {}
    for c in MOMENTS:
        t = truth.column(c)
        out[c] = float(np.abs(got.column(c) - t)[frames].max() / np.abs(t).max())
    return out


def test_simulate_writes_the_truth_biorbd_agrees_with(tmp_path, model):
    biorbd = pytest.importorskip("biorbd")
    out = tmp_path / "fast.c3d"
    args = ["simulate", "--motion", "abduction", "--duration", "0.6", "--rate", "200", "--cycle-s", "0.6",
            "--body-mass", str(MASS), "--hand-load-kg", str(LOAD), "--out", str(out)]
    assert main(args) == 0
    t, cols, values = read_moments_csv(tmp_path / "fast.truth_moments.csv")
    header = (tmp_path / "fast.truth_moments.csv").read_text(encoding="utf-8")
    assert "Dumas" in header and "70 kg" in header and "2 kg" in header
    trial = simulate_trial(model, "abduction", duration_s=0.6, rate_hz=200, cycle_s=0.6)
    np.testing.assert_allclose(t, trial.time_s, atol=1e-9)
    bio = biorbd.Model(str(write_biomod(dynamics_model(model, hand_load_kg=LOAD), tmp_path / "m.bioMod")))
    ref = np.array([bio.InverseDynamics(q, qd, qdd).to_array()
                    for q, qd, qdd in zip(trial.q_true, trial.qd_true, trial.qdd_true)])
    got = np.column_stack([values[:, cols.index(f"{n}_generalized_force_Nm")] for n in model.coordinate_names])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
    # a fast motion: peak accelerations of thousands of deg/s^2, a GH moment well above the slow raise's
    assert np.degrees(np.abs(trial.qdd_true)).max() > 2000
    assert np.abs(values[:, cols.index("GH_X_moment_Nm")]).max() > 60
    assert main(["simulate", "--motion", "abduction", "--cycle-s", "0", "--out", str(tmp_path / "x.c3d")]) == 2


@pytest.mark.parametrize("method", ["ls", "pf"])
def test_noise_free_slow_raise_moments_within_1_percent(model, method):
    trial = simulate_trial(model, "abduction", duration_s=5.0, rate_hz=100)
    truth = joint_moments(model, trial.q_true, trial.qd_true, trial.qdd_true, hand_load_kg=LOAD)
    rec = exubio.reconstruct(trial.trajectories, model, method=method)
    err = worst_share_of_peak(exubio_moments(rec, model), truth)
    assert max(err.values()) < 0.01, err


def exubio_moments(rec, model):
    return joint_moments(model, rec.q_rad, rec.qd_rad_s, rec.qdd_rad_s2, hand_load_kg=LOAD)


@pytest.mark.parametrize("method", ["ls", "pf"])
def test_noise_free_fast_raise_moments_within_1_percent(model, method):
    """0.6 s cycles of 10-120 deg (peak accelerations ~6000 deg/s^2) at 200 Hz, the markers not
    low-pass filtered (the default 'auto' cut-off attenuates this fast a motion: about 4 % of the
    peak, docs/moments.md). PF starts at rest while the truth already accelerates: its first
    0.3 s are a start transient, left out for PF."""
    trial = simulate_trial(model, "abduction", duration_s=1.8, rate_hz=200, cycle_s=0.6)
    truth = joint_moments(model, trial.q_true, trial.qd_true, trial.qdd_true, hand_load_kg=LOAD)
    protocol = dataclasses.replace(exubio.load_protocol(model=model), cutoff_hz=None)
    rec = exubio.reconstruct(trial.trajectories, model, protocol, method=method)
    frames = slice(None) if method == "ls" else slice(int(0.3 * 200), None)
    err = worst_share_of_peak(exubio_moments(rec, model), truth, frames)
    assert max(err.values()) < 0.01, err


def test_reconstruct_writes_moments_in_its_result_set(tmp_path, model):
    c3d = tmp_path / "slow.c3d"
    assert main(["simulate", "--motion", "abduction", "--duration", "2", "--out", str(c3d)]) == 0
    out = tmp_path / "out"
    assert main(["reconstruct", str(c3d), "--method", "ls", "--body-mass", str(MASS), "--hand-load-kg", str(LOAD),
                 "--out", str(out), "--no-report", "-q"]) == 0
    path = out / "slow.ls.moments.csv"
    t, cols, values = read_moments_csv(path)
    text = path.read_text(encoding="utf-8")
    assert "ISB frame" in text and "right-hand rule" in text and "Dumas" in text and "LS reconstruction" in text
    summary = json.loads((out / "slow.ls.summary.json").read_text(encoding="utf-8"))
    peaks = summary["moments"]["peak_abs"]
    assert peaks["GH_X_moment_Nm"] == pytest.approx(np.abs(values[:, cols.index("GH_X_moment_Nm")]).max(), abs=5e-5)
    assert summary["moments"]["body_mass_kg"] == MASS and summary["moments"]["hand_load_kg"] == LOAD
    # the API gives the same table
    rec = exubio.reconstruct(exubio.read_trial(c3d), model, method="ls")
    df = exubio.moments(rec, model, hand_load_kg=LOAD)
    assert list(df.columns) == list(cols)
    np.testing.assert_allclose(df["GH_X_moment_Nm"].to_numpy(), values[:, cols.index("GH_X_moment_Nm")],
                               rtol=0, atol=1e-6 * np.abs(values).max())
    assert "Dumas" in df.attrs["inertia_source"]
    # without --body-mass: no moments; a load without a mass: one clear error, exit 2
    assert main(["reconstruct", str(c3d), "--method", "ls", "--out", str(tmp_path / "plain"), "--no-report", "-q"]) == 0
    assert not list((tmp_path / "plain").glob("*.moments.csv"))
    # asking for moments where a set without them exists: not kept silently as if complete
    assert main(["reconstruct", str(c3d), "--method", "ls", "--body-mass", str(MASS), "--out", str(tmp_path / "plain"),
                 "--no-report", "-q"]) == 2
    assert main(["reconstruct", str(c3d), "--method", "ls", "--body-mass", str(MASS), "--out", str(tmp_path / "plain"),
                 "--no-report", "-q", "--overwrite"]) == 0
    assert (tmp_path / "plain" / "slow.ls.moments.csv").is_file()
    assert main(["reconstruct", str(c3d), "--method", "ls", "--hand-load-kg", "2", "--out", str(tmp_path / "bad"),
                 "--no-report", "-q"]) == 2
