"""PF's inertia (PFOptions.inertia_scale) on every real trial of ../shared/data and on the
sensitivity grid's corner: which runs finish, per inertia. The measurement behind the default 0.1
(studies/README.md, "PF across its parameters"): a lower inertia lets the grid's softest,
barely damped springs (c = 10 N/m, d = 0.1 Ns/m) carry the real abduction to its end, but makes the
limits' stiff modes faster still, and modified Newton then fails on a strained real trial.

Each run is calibrated as in studies/trust_real_trials.py (the session's static, or the trial's
first frames), then PF runs with the trial's protocol at each inertia (c, d the protocol's, or the
corner's where said). Prints per run: the mean spring deflection (mm), or FAILED and where.

    python studies/pf_inertia_real.py                     # ~2 minutes on 2 cores
    python studies/pf_inertia_real.py --scales 0.1,0.01
    python studies/pf_inertia_real.py --scales 0.01 --full-newton   # Jacobian rebuilt every iteration
    python studies/pf_inertia_real.py --cost     # CPU time per frame: the defaults against x 0.01 + full Newton
    python studies/pf_inertia_real.py --agreement   # PF's fallback options against its defaults, every real run
"""
from __future__ import annotations

import argparse
import logging
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from exubio.errors import ReconstructionError
from exubio.io.trial import read_trial
from exubio.prep.targets import prepare_targets
from exubio.protocol.labels import relabel_trajectories
from exubio.run.inputs import load_session
from exubio.run.pipeline import reconstruct
from exubio.run.session import StaticSpec, calibrate_session
from exubio.validation.sensitivity import with_springs

from trust_real_trials import SHARED, runs  # the same runs, calibrated the same way

CORNER = (10.0, 0.1)  # c N/m, d Ns/m: the sensitivity grid's softest, least damped run (Fig. 2)


def prepared(spec: dict, work: Path):
    session = load_session(protocol_path=spec["protocol"])
    trial = read_trial(spec["trial"])
    if spec.get("relabel"):
        trial = relabel_trajectories(trial, spec["relabel"])
    static = spec.get("static")
    if static and spec.get("static_relabel"):
        static = relabel_trajectories(read_trial(static), spec["static_relabel"])
    cal = calibrate_session(static if static else trial, session, work, spec["trial"].stem,
                            spec=StaticSpec(frames=None if static else spec["static_frames"]))
    protocol = cal.session.protocol
    return cal.session.model, protocol, prepare_targets(trial, protocol)


def one(model, protocol, targets, scale: float, modified_newton: bool = True) -> str:
    try:
        rec = reconstruct(model, protocol, targets, method="pf", inertia_scale=scale, modified_newton=modified_newton,
                          fallback=False)  # the options as given: PF's fallback would hide a stop
    except ReconstructionError as exc:
        text = str(exc)
        return "FAILED " + text[text.find("the PF"):][:90]
    return f"{np.nanmean(rec.residuals_m) * 1000:6.2f} mm"


def cost(runs: int = 3) -> None:
    """PF's CPU time per frame (build and run, median of ``runs``) at the default options against
    the robust ones, on the simulated 25 s abduction at 200 Hz (1.5 mm noise, as
    bench_reconstruction.py) and on the real ABD01."""
    from exubio import load_model, load_protocol
    from exubio.synth.simulate import simulate_trial
    from exubio.methods.pf import FALLBACK_OPTIONS
    from exubio.validation.trials import real_trial

    model, protocol = load_model(), load_protocol()
    sim = simulate_trial(model, "abduction", duration_s=25.0, rate_hz=200.0, noise_mm=1.5, seed=1)
    cases = {"simulated abduction 25 s, 200 Hz": (model, protocol, prepare_targets(sim.trajectories, protocol))}
    if SHARED.is_dir():
        cases["tsm_rmr_ABD01.trc"] = real_trial("abduction")[:3]
    print(f"PF CPU time per frame (ms, median of {runs}): default options | {FALLBACK_OPTIONS}")
    for name, (m, p, t) in cases.items():
        out = []
        for kw in ({}, FALLBACK_OPTIONS):
            ts = []
            for _ in range(runs):
                c0 = time.process_time()
                reconstruct(m, p, t, method="pf", **kw)
                ts.append((time.process_time() - c0) / t.n_frames * 1000.0)
            out.append(f"{statistics.median(ts):.3f} ({', '.join(f'{x:.3f}' for x in ts)})")
        print(f"{name}: " + " | ".join(out), flush=True)


def agreement(model, protocol, targets) -> str:
    """The fallback's result against the defaults' (both without fallback): the worst coordinate's
    RMSE (deg) and the largest model-point distance (mm) over the trial."""
    from exubio.methods.pf import FALLBACK_OPTIONS

    try:
        a = reconstruct(model, protocol, targets, method="pf", fallback=False)
        b = reconstruct(model, protocol, targets, method="pf", fallback=False, **FALLBACK_OPTIONS)
    except ReconstructionError as exc:
        return "FAILED " + str(exc)[:90]
    rmse = np.degrees(np.sqrt(np.mean((a.q_rad - b.q_rad) ** 2, axis=0)))
    j = int(np.argmax(rmse))
    dist = np.linalg.norm(a.model_points_m - b.model_points_m, axis=2) * 1000.0
    return f"worst coordinate RMSE {rmse[j]:.3f} deg ({a.coordinate_names[j]}), model points up to {np.nanmax(dist):.2f} mm"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scales", default="1,0.1,0.03,0.01", help="inertia scales, comma-separated")
    ap.add_argument("--full-newton", action="store_true", help="PFOptions.modified_newton False")
    ap.add_argument("--cost", action="store_true", help="only the CPU time of the defaults against the robust options")
    ap.add_argument("--agreement", action="store_true", help="only the fallback options' result against the defaults'")
    args = ap.parse_args(argv)
    if args.cost:
        cost()
        return 0
    scales = [float(s) for s in args.scales.split(",")]
    logging.basicConfig(level=logging.ERROR)
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to run", file=sys.stderr)
        return 2
    if args.agreement:
        print("PF with its fallback options (inertia x 0.01, full Newton) against its defaults, both run to the end:")
    else:
        print("PF per inertia scale: mean spring deflection, or why it stopped"
              + (" (full Newton)" if args.full_newton else ""))
        print("run | " + " | ".join(f"x {s:g}" for s in scales))
    with tempfile.TemporaryDirectory() as tmp:
        for i, spec in enumerate(runs()):
            model, protocol, targets = prepared(spec, Path(tmp) / str(i))
            what = (spec["trial"].name + (" [session relabel]" if "session" in str(spec["protocol"]) else "")
                    + (" [OTHER SESSION'S STATIC]" if spec.get("cross") else ""))
            if args.agreement:
                print(f"{what}: {agreement(model, protocol, targets)}", flush=True)
                continue
            print(f"{what} | " + " | ".join(one(model, protocol, targets, s, not args.full_newton) for s in scales), flush=True)
            if spec["trial"].suffix == ".trc":
                corner = with_springs(protocol, CORNER[0], CORNER[1])
                print(f"{spec['trial'].name} at c {CORNER[0]:g} N/m, d {CORNER[1]:g} Ns/m | "
                      + " | ".join(one(model, corner, targets, s, not args.full_newton) for s in scales), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
