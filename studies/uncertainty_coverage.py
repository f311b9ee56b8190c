"""Is each angle's stated uncertainty honest on simulated trials with the bone-pin artefact? For the
paper's motions (abduction, flexion, scaption, SIER), simulated with 1 mm noise and the soft-tissue
artefact fitted on bone pins (``--sta bone``; per-marker 10 mm on the segments the pins do not
cover), reconstructed by LS and PF with the shipped protocol: per angle the RMSE against the truth,
the fraction of measured frames, the coverage (fraction of measured frames where the truth lies
within +-2u; about 95 % is the aim, 90-99 % honest) and the RMS of error / u (about 1 where u is the
size of a standard uncertainty, whatever the error's distribution: an error that is systematic, as
the artefact's mean course is, lies within +-2u in every frame when its RMS is u).

    python studies/uncertainty_coverage.py --seeds 3          # a table per method
    python studies/uncertainty_coverage.py --seeds 3 --sta per-marker
    python studies/uncertainty_coverage.py --seeds 5 --by-elevation   # also per HT elevation band (LS)
    python studies/uncertainty_coverage.py --seeds 5 --no-direct-misfit   # u as before the direct misfit term

The bone-pin model is one subject's (S2M; Cereatti et al. 2017, J Biomech 62:5-13).
"""
from __future__ import annotations

import argparse
import logging
import warnings

import numpy as np

MOTIONS = ("abduction", "flexion", "scaption", "sier")
BANDS = ((0, 30), (30, 60), (60, 90), (90, 180))


def one(motion: str, seed: int, sta: str, methods, duration: float, rate: float):
    import exubio
    from exubio.model.angles import anatomical_table
    from exubio.synth.simulate import simulate_trial
    from exubio.synth.sta_bone import load_sta_model

    model = exubio.load_model()
    protocol = exubio.load_protocol(model=model)
    kw = {"sta_mm": 10.0} if sta == "bone" else {"sta_mm": 20.0}
    if sta == "bone":
        kw["sta_model"] = load_sta_model("bone")
    sim = simulate_trial(model, motion, duration_s=duration, rate_hz=rate, noise_mm=1.0, seed=seed, **kw)
    _, truth = anatomical_table(model, sim.q_true)
    out = {}
    for m in methods:
        rec = exubio.reconstruct(sim.trajectories, model, protocol, method=m)
        det = exubio.angle_status(rec, model, protocol)
        names, est = anatomical_table(model, rec.q_rad)
        err = np.abs(np.angle(np.exp(1j * (est - truth))))
        ht = np.degrees(np.abs(truth[:, names.index("HT_X_elevation")]))
        out[m] = (names, err, det.status == 0, det.uncertainty_rad, str(getattr(rec.quality.verdict, "value", rec.quality.verdict)),
                  ht)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--sta", default="bone", choices=["bone", "per-marker"])
    ap.add_argument("--methods", nargs="+", default=["ls", "pf"])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--by-elevation", action="store_true", help="also coverage per HT elevation band, first method")
    ap.add_argument("--no-direct-misfit", action="store_true",
                    help="as before the direct misfit term: a misfit segment's frame not turned "
                         "(exubio.trust.angle_uncertainty.misfit_angle_variance)")
    args = ap.parse_args(argv)
    if args.no_direct_misfit:
        from exubio.trust import angle_uncertainty

        angle_uncertainty.DIRECT_MISFIT = False
    band: dict = {}
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    acc: dict = {}
    verdicts: dict = {}
    for motion in MOTIONS:
        for seed in range(1, args.seeds + 1):
            res = one(motion, seed, args.sta, args.methods, args.duration, args.rate)
            for m, (names, err, meas, u, verdict, ht) in res.items():
                verdicts.setdefault(m, {}).setdefault(verdict, 0)
                verdicts[m][verdict] += 1
                for j, n in enumerate(names):
                    a = acc.setdefault((m, motion, n), {"e2": 0.0, "n": 0, "cov": 0, "frames": 0, "z2": 0.0})
                    ok = meas[:, j] & np.isfinite(err[:, j])
                    a["frames"] += err.shape[0]
                    a["n"] += int(ok.sum())
                    a["e2"] += float(np.sum(err[ok, j] ** 2))
                    a["cov"] += int(np.sum(err[ok, j] <= 2 * u[ok, j]))
                    a["z2"] += float(np.sum((err[ok, j] / u[ok, j]) ** 2))
                    if args.by_elevation:
                        for lo, hi in BANDS:
                            b = ok & (ht >= lo) & (ht < hi)
                            e = band.setdefault((m, motion, n, lo), {"n": 0, "cov": 0, "z2": 0.0})
                            e["n"] += int(b.sum())
                            e["cov"] += int(np.sum(err[b, j] <= 2 * u[b, j]))
                            e["z2"] += float(np.sum((err[b, j] / u[b, j]) ** 2))
    for m in args.methods:
        print(f"\n**{m.upper()}**, STA {args.sta}, {args.seeds} seeds x {args.duration:g} s at {args.rate:g} Hz, 1 mm noise; "
              f"verdicts: {verdicts[m]}\n")
        print("| angle | " + " | ".join(MOTIONS) + " |")
        print("|---|" + "---|" * len(MOTIONS))
        names = sorted({n for (mm, _, n) in acc if mm == m}, key=lambda n: list(acc).index((m, MOTIONS[0], n)))
        for n in names:
            cells = []
            for motion in MOTIONS:
                a = acc[(m, motion, n)]
                if a["n"] == 0:
                    cells.append("not measured")
                    continue
                cells.append(f"{np.degrees(np.sqrt(a['e2'] / a['n'])):.1f} / {a['cov'] / a['n']:.0%} / "
                             f"{np.sqrt(a['z2'] / a['n']):.2f} ({a['n'] / a['frames']:.0%})")
            print(f"| {n} | " + " | ".join(cells) + " |")
        print("\ncells: RMSE deg over measured frames / coverage of +-2u / RMS of error/u (fraction of frames measured)")
    if args.by_elevation:
        m = args.methods[0]
        print(f"\n**{m.upper()} by HT elevation** (coverage / RMS of error/u (measured frames); bands in deg)\n")
        print("| angle | motion | " + " | ".join(f"HT {lo}-{hi}" for lo, hi in BANDS) + " |")
        print("|---|---|" + "---|" * len(BANDS))
        for n in names:
            for motion in MOTIONS:
                cells = []
                for lo, _ in BANDS:
                    e = band.get((m, motion, n, lo))
                    cells.append("-" if not e or not e["n"] else f"{e['cov'] / e['n']:.0%} / {np.sqrt(e['z2'] / e['n']):.2f} ({e['n']})")
                print(f"| {n} | {motion} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
