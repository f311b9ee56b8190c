"""Calibration and reconstruction of the real trials of ../shared/data (skipped when absent).

C3D: Ipuch/bioptim_exo (MIT); TRC: thoracoscapular shoulder model study, Seth et al. 2019
(CC BY 4.0); see ../shared/data/SOURCES.md. Thresholds: the paper's maximum per-frame mean marker
residual was 18.0 mm (abduction) and 18.7 mm (flexion) with its MRI-calibrated model."""
from pathlib import Path

import numpy as np
import pytest

from exubio.calibration import calibrate_model, calibrated_protocol
from exubio.trust.evaluate import residual_statistics
from exubio.io.trial import read_trial
from exubio.model.load import load_model, save_model
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.io.resources import shipped_file

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
pytestmark = [pytest.mark.exudyn, pytest.mark.slow, pytest.mark.skipif(not DATA.is_dir(), reason=f"real data folder {DATA} is absent")]

TRC_PROTOCOL = shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols")
PAPER_MAX_FRAME_MEAN_MM = 19.0
F0_MAX_FRAME_MEAN_MM = 22.0
"""F0_boire_05's worst frame mean residual: 20.7 mm since the calibration holds the protocol's held
sc_posterior_rotation at 0 in the static pose, as both methods do (it was fitted freely before,
a pose no reconstruction could take; 18.x mm then); the paper's in vivo worst frame was 19 mm."""
TRC_MAX_FRAME_MEAN_MM = 25.0
"""The TRC trials' worst frame mean residual. Above the paper's in vivo 19 mm since the generic girdle
follows the published (thoracoscapular) geometry and its ellipsoid carries Ludewig's mean rhythm:
the arm markers fit better (gu/EpL/centelbow RMS 8.6/5.3/4.4 mm on ABD01, were 11.9/7.3/7.1) but
the skin markers ts and ai, registered as the ellipsoid contact points at the arm-down frames,
leave the ellipsoid at elevation (RMS 24/27 mm, were 16/18; OpenSim IK with the subject's own
model leaves ai up to 22 mm): worst frame 22.9 (ABD01) and 23.6 mm (FLX01), was 17.4."""
UNOBSERVED_ON_TRC = ("elbow_flexion", "pronation", "wrist_flexion", "wrist_radial_deviation")


def _calibrate_and_reconstruct(path: Path, frames: slice, protocol_path=None):
    model, protocol = load_model_and_protocol(protocol_path=protocol_path)
    traj = read_trial(path)
    targets = prepare_targets(traj, protocol)
    cal, report = calibrate_model(model, protocol, traj, frames=frames, targets=targets)
    bound = calibrated_protocol(protocol, cal)
    recons = {m: reconstruct(cal, bound, targets, method=m) for m in ("ls", "pf")}
    return cal, report, recons


def test_static_calibration_of_the_c3d_static_trial(tmp_path):
    path = DATA / "c3d" / "bioptim_exo_martin_statique.c3d"
    model, protocol = load_model_and_protocol()
    cal, report = calibrate_model(model, protocol, read_trial(path))
    # the arm is held still (T-pose) for about the first 2.1 s, then lowered: found automatically
    assert report.frames_chosen_automatically
    assert report.frames[0] == 0 and 180 <= report.frames[1] <= 225, report.frames
    res = report.residual_mm
    assert len(res) == 17  # 21 markers: 4 build the thorax frame; ELB (optional) is not in the static
    assert not next(m for m in report.markers if m.name == "ELB").registered
    assert all(np.isfinite(v) for v in res.values())
    assert report.mean_residual_mm < 5.0, res
    assert max(res.values()) < 5.0, res
    assert report.constraint_abs < 1e-10
    # the file records the fit and the residual per marker, and reads back
    back = load_model(save_model(cal, tmp_path / "martin.yaml", calibration=report.to_dict()))
    markers = back.metadata["calibration"]["markers"]
    assert markers["EPI_lat"]["residual_mm"] == pytest.approx(res["EPI_lat"], abs=1e-3)
    assert markers["ELB"]["registered"] is False


def test_drinking_trial_calibrated_from_its_first_frames():
    cal, report, recons = _calibrate_and_reconstruct(DATA / "c3d" / "bioptim_exo_F0_boire_05.c3d", slice(0, 20))
    assert report.mean_residual_mm < 5.0
    for method, recon in recons.items():
        stats = residual_statistics(recon)
        assert stats["max_frame_mean"] < F0_MAX_FRAME_MEAN_MM, (method, stats["max_frame_mean"])
        assert np.abs(recon.constraint).max() < 1e-8, method
        assert (recon.status == 0).all(), method
    diff = np.angle(np.exp(1j * (recons["ls"].q_rad - recons["pf"].q_rad)))  # the same angle, whatever turn
    agree = np.rad2deg(np.sqrt(np.mean(diff**2, axis=0)))
    assert agree.max() < 5.0, dict(zip(recons["ls"].coordinate_names, agree.round(2)))


@pytest.mark.parametrize("trial", ["tsm_rmr_ABD01.trc", "tsm_rmr_FLX01.trc"])
def test_trc_trials_calibrated_from_their_first_frames(trial):
    cal, report, recons = _calibrate_and_reconstruct(DATA / "trc" / trial, slice(0, 50), TRC_PROTOCOL)
    assert report.mean_residual_mm < 5.0
    assert not report.thorax_scale_measured  # identity thorax frame: no thorax landmarks
    for method, recon in recons.items():
        stats = residual_statistics(recon)
        assert stats["max_frame_mean"] < TRC_MAX_FRAME_MEAN_MM, (method, stats["max_frame_mean"])
        assert np.abs(recon.constraint).max() < 1e-8, method
    # LS holds the coordinates no marker observes at their start value (see the protocol file)
    ls = recons["ls"]
    idx = [ls.coordinate_names.index(c) for c in UNOBSERVED_ON_TRC]
    assert np.ptp(ls.q_rad[:, idx], axis=0).max() < 1e-6
    # the scapula orientation from LS and PF agrees (the clavicle's does not: see the protocol)
    from exubio.model.kinematics import Kinematics

    kin = Kinematics(cal)
    i = cal.segment_index("scapula")
    R_ls, R_pf = (kin.frames(r.q_rad).R[:, i] for r in (recons["ls"], recons["pf"]))
    cos = (np.einsum("nji,nji->n", R_ls, R_pf) - 1.0) / 2.0
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    assert np.percentile(angle, 99) < 2.0 and angle.max() < 3.0, (np.percentile(angle, 99), angle.max())
