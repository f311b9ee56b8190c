"""PF across its parameters on the real TRC abduction (issue 21, item 4): the 32 runs of the
sensitivity grid (Fig. 2: c x k = d/c) with what each run ends with (mean spring deflection, and
whether it finished on PF's fallback; or the error saying where it stopped), the runs that stop
again without range-of-motion limits, and the PF-LS marker-trajectory RMSE (Fig. 6) decomposed into
its damping and inertia parts (PF with d varied and PFOptions.inertia_scale 1, the physical
segments, 0.1, the default, and 0.01), on both real trials and on a simulated noise-free abduction.

Usage:  python studies/pf_grid_real.py                  (needs ../shared/data/trc; ~2 minutes)
        python studies/pf_grid_real.py --inertia 0.01   (the grid with PFOptions.inertia_scale 0.01)
        python studies/pf_grid_real.py --inertia 0.01 --full-newton   (and modified_newton False)
        python studies/pf_grid_real.py --no-fallback    (a run that stops fails: PF's options as given)
"""
from __future__ import annotations

import argparse
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


def pf_ls(model, protocol, targets, ls, c, d, inertia) -> str:
    rec = reconstruct(model, with_springs(protocol, c, d), targets, method="pf", inertia_scale=inertia)
    dist = np.linalg.norm(rec.model_points_m - ls.model_points_m, axis=2) * 1000.0
    rmse = np.sqrt(np.nanmean(dist**2, axis=0))
    j = int(np.argmax(rmse))
    return f"{rmse[j]:.2f} mm ({rec.marker_names[j]})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inertia", type=float, default=None,
                    help="PFOptions.inertia_scale for the grid (default: PF's default)")
    ap.add_argument("--full-newton", action="store_true", help="PFOptions.modified_newton False for the grid")
    ap.add_argument("--no-fallback", action="store_true", help="PFOptions.fallback False: a run that stops fails")
    args = ap.parse_args(argv)
    grid_kw = ({} if args.inertia is None else {"inertia_scale": args.inertia}) | (
        {"modified_newton": False} if args.full_newton else {}) | ({"fallback": False} if args.no_fallback else {})
    logging.basicConfig(level=logging.ERROR)
    why = why_no_real_trial("abduction")
    if why:
        print(f"abduction: {why}", file=sys.stderr)
        return 2
    model, protocol, targets, _ = real_trial("abduction")
    s = ValidationSettings()
    failed = []
    print("sensitivity grid on the real ABD01 (c N/m, k = d/c s): mean spring deflection or why it stopped"
          + (f" (inertia x {args.inertia:g})" if args.inertia is not None else "")
          + (" (full Newton)" if args.full_newton else "") + (" (no fallback)" if args.no_fallback else ""))
    for k in s.sensitivity_ratio_s:
        for c in s.sensitivity_stiffness_n_per_m:
            try:
                rec = reconstruct(model, with_springs(protocol, c, k * c), targets, method="pf", **grid_kw)
                fb = rec.info.get("fallback")
                print(f"  c {c:8.1f}  k {k:5g}: {np.nanmean(rec.residuals_m) * 1000:6.2f} mm"
                      + (f"  (on PF's fallback; its first run: {fb['first_run']})" if fb else ""))
            except ReconstructionError as exc:
                failed.append((c, k))
                print(f"  c {c:8.1f}  k {k:5g}: FAILED: {exc}")
    print(f"{32 - len(failed)} of 32 finish")
    for c, k in failed:
        try:
            rec = reconstruct(model, with_springs(protocol, c, k * c), targets, method="pf", **grid_kw,
                              limit_stiffness_nm_per_rad=None, divergence_deflection_m=5.0)
            sweep = np.degrees(np.ptp(rec.q_rad, axis=0))
            print(f"  without range limits c {c:.1f} k {k:g}: finishes, mean deflection "
                  f"{np.nanmean(rec.residuals_m) * 1000:.1f} mm, largest coordinate sweep {sweep.max():.0f} deg")
        except ReconstructionError as exc:
            print(f"  without range limits c {c:.1f} k {k:g}: still fails: {exc}")
    print("\nPF-LS marker-trajectory RMSE, worst marker (c = 1500 N/m):")
    cases = [(300, 0.1), (300, 1.0), (300, 0.01), (30, 1.0), (30, 0.01), (3, 0.01)]
    print("  " + " | ".join(f"d {d:g}, inertia x {f:g}" for d, f in cases))
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
