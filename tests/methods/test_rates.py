"""PF's and LS's rates against a simulated truth (exubio.validation.rates): the consistent q̇ and q̈
of PF are within the aims noise-free, the lead-in removes PF's start transient, the constraints
hold at velocity and acceleration level, and the section's records round-trip."""
from __future__ import annotations

import numpy as np
import pytest

from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.synth.simulate import simulate_trial
from exubio.io.records import decode
from exubio.validation.rates import (PF_AIM_QD_DEG_S, PF_AIM_QDD_DEG_S2, finite_differences, rates_against_truth,
                                     rates_checks, rates_of)
from exubio.validation.results import Rates
from exubio.validation.settings import QUICK_SETTINGS

pytestmark = pytest.mark.exudyn


@pytest.fixture(scope="module")
def noise_free():
    model, protocol = load_model_and_protocol()
    sim = simulate_trial(model, "abduction", duration_s=4.0, rate_hz=100.0)
    targets = prepare_targets(sim.trajectories, protocol)
    return model, rates_of(model, protocol, targets, sim, with_no_lead_in=True)


def test_finite_differences_are_exact_on_a_quadratic():
    t = np.arange(20) * 0.01
    q = np.stack([1 + 2 * t + 3 * t**2, -t**2], axis=1)
    qd, qdd = finite_differences(q, 0.01)
    np.testing.assert_allclose(qd[1:-1], np.stack([2 + 6 * t, -2 * t], axis=1)[1:-1], atol=1e-12)
    np.testing.assert_allclose(qdd[1:-1], np.tile([6.0, -2.0], (18, 1)), atol=1e-9)
    assert np.isnan(qd[0]).all() and np.isnan(qdd[-1]).all()


def test_pf_rates_noise_free_within_the_aims(noise_free):
    """Noise-free, PF's own q̇ and q̈ are within 1 deg/s and 5 deg/s^2 of the exact rates on every
    coordinate (all 13 are measured by the 21-marker set), and so are LS's."""
    model, got = noise_free
    for method in ("pf", "ls"):
        qd = got["qd_rmse_deg_s"][method]
        qdd = got["qdd_rmse_deg_s2"][method]
        assert max(qd.values()) < PF_AIM_QD_DEG_S, (method, qd)
        assert max(qdd.values()) < PF_AIM_QDD_DEG_S2, (method, qdd)


def test_lead_in_removes_the_start_transient(noise_free):
    """Without the lead-in PF's q̈ starts at its force-free value: its worst coordinate's q̈ RMSE is
    several times the lead-in run's (the truth is the judge, not the code)."""
    _, got = noise_free
    with_lead = max(got["qdd_rmse_deg_s2"]["pf"].values())
    without = max(got["qdd_rmse_deg_s2"]["pf_no_lead_in"].values())
    assert without > 3 * with_lead, (with_lead, without)
    # q and q̇ are unaffected (the transient is in q̈)
    assert max(got["q_rmse_deg"]["pf"].values()) < 0.1


def test_constraints_hold_at_every_level(noise_free):
    """PF (projected) and LS satisfy g = 0, G q̇ = 0 and G q̈ + eta = 0 to round-off; the finite
    differences of q do not at acceleration level to the same degree (they are not consistent by
    construction) but stay small noise-free."""
    _, got = noise_free
    for method in ("pf", "ls"):
        assert got["max_abs_g"][method] < 1e-8
        assert got["max_abs_g_qd_1_s"][method] < 1e-6
        assert got["max_abs_g_qdd_eta_1_s2"][method] < 1e-4


def test_section_records_round_trip():
    """The quick section runs, decodes from its own JSON equal, and its checks pass noise-free."""
    rates = rates_against_truth(QUICK_SETTINGS, lambda msg: None)
    assert set(rates.conditions) == {"noise_free", "noise_sta"}
    again = decode(Rates, rates.to_json())
    assert again == rates
    assert rates.pf_noise_free_max_qd_rmse_deg_s < PF_AIM_QD_DEG_S
    assert all(c.passed for c in rates_checks(rates))
    noisy = rates.conditions["noise_sta"]
    assert set(noisy.qdd_rmse_deg_s2) == {"pf", "ls", "pf_fd", "ls_fd"}


def test_a_failed_pf_run_says_where_and_the_default_inertia_converges_there():
    """Springs far too soft and barely damped for the motion (c = 10 N/m, d = 0.1 Ns/m, the corner of
    the sensitivity grid, Fig. 2) on the real abduction, with the segments' physical inertia
    (inertia_scale 1.0, the paper's): the run stops; its error names the time, the worst spring, the
    fastest coordinate and any coordinate beyond its range of motion at the last frame. With the
    default inertia (PFOptions.inertia_scale 0.1) the same springs carry the motion to its end, on
    the options asked (no fallback): they stopped there too while gh_abduction and gh_flexion had
    ranges, whose limits near the X-Y'-Z'' sequence's lock spun the humerus (studies/README.md)."""
    from exubio.errors import ReconstructionError
    from exubio.run.pipeline import reconstruct
    from exubio.validation.sensitivity import with_springs
    from exubio.validation.trials import real_trial, why_no_real_trial

    if why_no_real_trial("abduction"):
        pytest.skip(why_no_real_trial("abduction"))
    model, protocol, targets, _ = real_trial("abduction")
    soft = with_springs(protocol, 10.0, 0.1)
    with pytest.raises(ReconstructionError) as err:
        reconstruct(model, soft, targets, method="pf", inertia_scale=1.0, fallback=False)
    msg = str(err.value)
    assert "diverged at t =" in msg and "spring '" in msg, msg
    fastest = msg.split("fastest coordinate ")[1].split(" ")[0]
    assert fastest in model.coordinate_names, msg
    if "beyond their range of motion there: " in msg:
        named = msg.split("beyond their range of motion there: ")[1].split("; ")[0]
        assert all(part.split(" ")[0] in model.coordinate_names for part in named.split(", ")), msg
    rec = reconstruct(model, soft, targets, method="pf", fallback=False)
    assert rec.n_frames == targets.n_frames and np.all(np.isfinite(rec.q_rad)) and "fallback" not in rec.info


def test_springs_softer_than_the_grid_finish_on_pfs_fallback_and_say_so():
    """Springs a tenth of the grid's softest corner (c = 1 N/m, d = 0.01 Ns/m) on the real abduction:
    PF's run at the options asked for stops, saying where (fallback off); with the fallback on (the
    default) PF runs it again with inertia x 0.01 and full Newton, carries the whole trial and says
    so in the result, in the trial's verdict and in the sensitivity study's record."""
    import dataclasses

    from exubio.errors import ReconstructionError
    from exubio.methods.pf import FALLBACK_OPTIONS
    from exubio.run.pipeline import reconstruct
    from exubio.trust.quality import fallback_reasons
    from exubio.validation.sensitivity import sensitivity_study, with_springs
    from exubio.validation.settings import ValidationSettings
    from exubio.validation.trials import Trial, real_trial, why_no_real_trial

    if why_no_real_trial("abduction"):
        pytest.skip(why_no_real_trial("abduction"))
    model, protocol, targets, _ = real_trial("abduction")
    softer = with_springs(protocol, 1.0, 0.01)
    with pytest.raises(ReconstructionError) as err:
        reconstruct(model, softer, targets, method="pf", fallback=False)
    assert "at t =" in str(err.value) and "fastest coordinate" in str(err.value), err.value
    ticks = []
    rec = reconstruct(model, softer, targets, method="pf", progress=ticks.append)
    assert rec.n_frames == targets.n_frames and np.isfinite(rec.q_rad).all()
    assert sum(ticks) == targets.n_frames and min(ticks) > 0  # the second run counted on from the first's frames
    assert np.nanmean(rec.residuals_m) < 0.25  # carried to the end, within the divergence check
    assert rec.info["fallback"]["first_run"] == str(err.value)
    assert rec.info["fallback"]["options"] == FALLBACK_OPTIONS == {"inertia_scale": 0.01, "modified_newton": False}
    assert rec.info["options"]["inertia_scale"] == 0.01 and rec.info["options"]["modified_newton"] is False
    (note,) = fallback_reasons(rec.info)
    assert note.level.value == "note" and "stopped" in note.message
    settings = dataclasses.replace(ValidationSettings(), sensitivity_stiffness_n_per_m=(1.0,), sensitivity_ratio_s=(0.01,))
    sens = sensitivity_study(Trial("abduction", model, protocol, targets, data=None), settings, lambda _: None)
    assert sens.runs == 1 and sens.failed_runs == () and len(sens.fallback_runs) == 1
    assert sens.fallback_runs[0].error == str(err.value)
    assert sens.mean_deflection_mm[0, 0] == pytest.approx(sens.fallback_runs[0].robust_deflection_mm)


def test_lead_in_extrapolates_the_first_frame_backwards():
    """The lead-in's targets continue a quadratic path exactly, keep a missing marker missing, and
    fall back to a straight line when the first frame's acceleration is an edge spike."""
    from exubio.methods.pf_time import LEAD_IN_MAX_BEND_M, lead_in_frames, with_lead_in
    from exubio.types import MarkerTargets

    dt, n = 0.01, 5
    t = np.arange(n) * dt
    v, a = np.array([0.1, 0.0, -0.2]), np.array([1.0, -2.0, 0.5])
    pos = np.stack([np.array([0.1, 0.2, 0.3]) + v * s + 0.5 * a * s**2 for s in t])[:, None, :]
    pos = np.concatenate([pos, np.full((n, 1, 3), np.nan)], axis=1)  # marker 2 missing
    vel = np.concatenate([np.stack([v + a * s for s in t])[:, None], np.full((n, 1, 3), np.nan)], axis=1)
    acc = np.concatenate([np.tile(a, (n, 1))[:, None], np.full((n, 1, 3), np.nan)], axis=1)
    tg = MarkerTargets(time_s=t, marker_names=("m1", "m2"), positions_m=pos, velocities_m_s=vel, accelerations_m_s2=acc)
    lead = lead_in_frames(0.1, dt, dt)
    assert lead == 10 and lead_in_frames(0.1, dt, 2 * dt) == 10 and lead_in_frames(0.0, dt, dt) == 0
    ext = with_lead_in(tg, lead, dt)
    s = ext.time_s[:lead][:, None]
    np.testing.assert_allclose(ext.time_s[lead:], t)
    np.testing.assert_allclose(ext.positions_m[:lead, 0], 0.1 * np.array([1, 2, 3]) + v * s + 0.5 * a * s**2, atol=1e-15)
    np.testing.assert_allclose(ext.velocities_m_s[:lead, 0], v + a * s, atol=1e-15)
    assert np.isnan(ext.positions_m[:lead, 1]).all()
    spike = MarkerTargets(time_s=t, marker_names=("m1", "m2"), positions_m=pos, velocities_m_s=vel,
                          accelerations_m_s2=acc * (3 * LEAD_IN_MAX_BEND_M / (0.5 * np.linalg.norm(a) * 0.1**2)))
    lin = with_lead_in(spike, lead, dt)
    np.testing.assert_allclose(lin.positions_m[:lead, 0], pos[0, 0] + v * s, atol=1e-15)


def test_pf_ls_marker_difference_is_inertia_and_damping():
    """On the real abduction PF's model points differ from LS's by ~1 mm (the paper: < 0.37 mm);
    with every segment almost massless and the dampers weakened PF comes within the paper's figure:
    the difference is PF's physics (inertia, damper lag), not an error of either method."""
    from exubio.run.pipeline import reconstruct
    from exubio.validation.agreement import _marker_rmse_causes
    from exubio.validation.trials import Trial, real_trial, why_no_real_trial

    if why_no_real_trial("abduction"):
        pytest.skip(why_no_real_trial("abduction"))
    model, protocol, targets, _ = real_trial("abduction")
    ls = reconstruct(model, protocol, targets, method="ls")
    pf = reconstruct(model, protocol, targets, method="pf")
    full = np.nanmax(np.sqrt(np.nanmean((np.linalg.norm(pf.model_points_m - ls.model_points_m, axis=2)) ** 2, axis=0)))
    causes = _marker_rmse_causes(Trial("abduction", model, protocol, targets, data=None), ls)
    assert full > 0.37e-3
    assert causes["masses_x0.01_dampers_x0.1"] < 0.37 < full * 1000
