"""PF across its parameters on the real TRC abduction (issue 21, item 4): the 32 runs of the
sensitivity grid (Fig. 2: c x k = d/c) with what each run ends with (mean spring deflection, or the
error saying where it stopped), the four soft corner runs again without range-of-motion limits,
and the PF-LS marker-trajectory RMSE (Fig. 6) decomposed into its damping and inertia parts (PF
with d varied and with every segment's mass and inertia x 0.01), on both real trials and on a
simulated noise-free abduction.

Usage:  python benchmarks/pf_grid_real.py      (needs ../shared/data/trc; ~2 minutes)
"""
from __future__ import annotations

import dataclasses
import logging
import sys

import numpy as np

from exubio.errors import ReconstructionError
from exubio.run.pipeline import reconstruct
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets
from exubio.synth.simulate import simulate_trial
from exubio.validation.sensitivity import with_springs
from exubio.validation.settings import ValidationSettings
from exubio.validation.trials import real_trial, why_no_real_trial


def light(model, factor):
    return dataclasses.replace(model, segments=tuple(
        dataclasses.replace(s, mass_kg=s.mass_kg * factor, inertia_kgm2=np.asarray(s.inertia_kgm2) * factor)
        for s in model.segments))


def pf_ls(model, protocol, targets, ls, c, d, factor=1.0) -> str:
    rec = reconstruct(light(model, factor), with_springs(protocol, c, d), targets, method="pf")
    dist = np.linalg.norm(rec.model_points_m - ls.model_points_m, axis=2) * 1000.0
    rmse = np.sqrt(np.nanmean(dist**2, axis=0))
    j = int(np.argmax(rmse))
    return f"{rmse[j]:.2f} mm ({rec.marker_names[j]})"


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    why = why_no_real_trial("abduction")
    if why:
        print(f"abduction: {why}", file=sys.stderr)
        return 2
    model, protocol, targets, _ = real_trial("abduction")
    s = ValidationSettings()
    failed = []
    print("sensitivity grid on the real ABD01 (c N/m, k = d/c s): mean spring deflection or why it stopped")
    for k in s.sensitivity_ratio_s:
        for c in s.sensitivity_stiffness_n_per_m:
            try:
                rec = reconstruct(model, with_springs(protocol, c, k * c), targets, method="pf")
                print(f"  c {c:8.1f}  k {k:5g}: {np.nanmean(rec.residuals_m) * 1000:6.2f} mm")
            except ReconstructionError as exc:
                failed.append((c, k))
                print(f"  c {c:8.1f}  k {k:5g}: FAILED: {exc}")
    print(f"{32 - len(failed)} of 32 finish")
    for c, k in failed:
        try:
            rec = reconstruct(model, with_springs(protocol, c, k * c), targets, method="pf",
                              limit_stiffness_nm_per_rad=None, divergence_deflection_m=5.0)
            sweep = np.degrees(np.ptp(rec.q_rad, axis=0))
            print(f"  without range limits c {c:.1f} k {k:g}: finishes, mean deflection "
                  f"{np.nanmean(rec.residuals_m) * 1000:.1f} mm, largest coordinate sweep {sweep.max():.0f} deg")
        except ReconstructionError as exc:
            print(f"  without range limits c {c:.1f} k {k:g}: still fails: {exc}")
    print("\nPF-LS marker-trajectory RMSE, worst marker (c = 1500 N/m):")
    cases = [(300, 1.0), (300, 0.01), (30, 1.0), (30, 0.01), (3, 0.01)]
    print("  " + " | ".join(f"d {d:g}" + (", masses x 0.01" if f < 1 else "") for d, f in cases))
    for name in ("abduction", "flexion"):
        m, p, tg, _ = real_trial(name)
        ls = reconstruct(m, p, tg, method="ls")
        print(f"  {name} (real): " + " | ".join(pf_ls(m, p, tg, ls, 1500.0, d, f) for d, f in cases))
    gm, gp = load_model_and_protocol()
    sim = simulate_trial(gm, "abduction", duration_s=10.0, rate_hz=100.0)
    tg = prepare_targets(sim.trajectories, gp)
    ls = reconstruct(gm, gp, tg, method="ls")
    print("  abduction (simulated, noise-free, 21 markers): "
          + " | ".join(pf_ls(gm, gp, tg, ls, 1500.0, d, f) for d, f in cases))
    return 0


if __name__ == "__main__":
    sys.exit(main())
