"""PF's and LS's joint rates against a simulated truth (issue 21): q̇ and q̈ RMSE per coordinate of
PF (integrated), LS (solved from the spline rates) and central finite differences of each one's q,
noise-free and with noise + STA, the constraint residuals at each level, and PF without the
lead-in (the former start) as the evidence for what limited PF's q̈.

It prints the validation study's own section (exubio.validation.rates; the report's Fig. 8) for
the validation settings (simulated abduction, 25 s at 200 Hz, noise 1 mm, STA 20 mm) or, with
``--rate HZ --duration S``, for another trial length.

Usage:  python studies/rates_truth.py [--rate 200] [--duration 25]      (~30 s)
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import sys

from exubio.validation.rates import rates_against_truth, rates_checks
from exubio.validation.settings import ValidationSettings

SOURCES = ("pf", "ls", "pf_fd", "ls_fd", "pf_no_lead_in")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rate", type=float, default=None)
    ap.add_argument("--duration", type=float, default=None)
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    s = ValidationSettings()
    s = dataclasses.replace(s, trial_rate_hz=a.rate or s.trial_rate_hz, trial_duration_s=a.duration or s.trial_duration_s)
    rates = rates_against_truth(s, lambda msg: print(f"# {msg}", file=sys.stderr))
    names = rates.coordinates
    width = max(len(n) for n in names)
    for key, c in rates.conditions.items():
        print(f"\n=== {key}: {c.description}")
        present = [x for x in SOURCES if x in c.qd_rmse_deg_s]
        for level, table, unit, truth in (("q̇", c.qd_rmse_deg_s, "deg/s", c.truth_rms_qd_deg_s),
                                         ("q̈", c.qdd_rmse_deg_s2, "deg/s^2", c.truth_rms_qdd_deg_s2)):
            print(f"{level} RMSE vs truth ({unit})".ljust(width + 2) + "".join(f"{x:>14}" for x in present)
                  + f"{'truth RMS':>12}")
            for n in names:
                print(f"  {n:<{width}}" + "".join(f"{table[x][n]:>14.3f}" for x in present) + f"{truth[n]:>12.1f}")
        print("constraint residuals, max |g| / |G q̇| (1/s) / |G q̈ + eta| (1/s^2):")
        for x in c.max_abs_g:
            print(f"  {x:<14} {c.max_abs_g[x]:.1e} / {c.max_abs_g_qd_1_s[x]:.1e} / {c.max_abs_g_qdd_eta_1_s2[x]:.1e}")
        print("wall s: " + ", ".join(f"{k} {v:.1f}" for k, v in c.wall_s.items()))
    print(f"\nmeasured coordinates: {len(rates.measured_coordinates)} of {len(names)}")
    for c in rates_checks(rates):
        print(f"{'met' if c.passed else 'NOT met'}: {c.what}: {c.value:.3g} {c.unit} (aim <= {c.limit:g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
