"""``exubio simulate``: a synthetic trial (C3D), its true angles and, with a body mass, its true moments."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_OK, epilog
from exubio.errors import InputError
from exubio.synth.thorax_lean import add_lean_arguments  # small: numpy and the dynamics' dataclass


def cmd_simulate(args: argparse.Namespace) -> int:
    from exubio.model.load import load_model
    from exubio.synth.simulate import Motion, simulate_trial, write_simulated_trial
    from exubio.synth.thorax_lean import lean_from_args

    out = Path(args.out)
    if out.suffix.lower() != ".c3d":
        raise InputError(f"--out {out}: expected a path ending in .c3d")
    from exubio.synth.perturb import ModelPerturbation

    model = (load_model(args.model, body_mass_kg=args.body_mass) if args.model
             else load_model(body_mass_kg=args.body_mass))
    perturbation = ModelPerturbation.parse(args.perturb) if args.perturb else None
    if perturbation is not None:
        perturbation.apply(model)  # bad segment or point names: exit 2 before any work
    out.parent.mkdir(parents=True, exist_ok=True)
    trial = simulate_trial(model, Motion.parse(args.motion), duration_s=args.duration, rate_hz=args.rate,
                           noise_mm=args.noise_mm, sta_mm=args.sta_mm, seed=args.seed, perturbation=perturbation,
                           sta_model=args.sta, cycle_s=args.cycle_s, thorax_lean=lean_from_args(args))
    if trial.sta_model != "per-marker":
        print(f"soft-tissue artefact: {trial.sta_model}")
    if args.protocol:
        from exubio.run.inputs import protocol_for_model
        from exubio.synth.protocol_markers import with_protocol_markers

        trial = with_protocol_markers(trial, [protocol_for_model(model, p) for p in args.protocol],
                                      noise_mm=args.noise_mm, seed=args.seed)
    c3d, truth = write_simulated_trial(trial, out)
    if perturbation is not None:
        print(f"generated with the model perturbed by {' '.join(perturbation.words()) or 'nothing'} (in {truth.name}'s header)")
    print(f"wrote {c3d} ({trial.trajectories.n_markers} markers, {trial.trajectories.n_frames} frames, "
          f"{args.rate:g} Hz, noise {args.noise_mm:g} mm, soft-tissue artefact {args.sta_mm:g} mm)")
    print(f"wrote {truth} (true joint angles, deg)")
    if args.body_mass is not None:
        from exubio.synth.truth_moments import write_truth_moments

        moments = write_truth_moments(trial, out, hand_load_kg=args.hand_load_kg)
        print(f"wrote {moments} (true joint moments, N m: {args.body_mass:g} kg, {args.hand_load_kg:g} kg in the hand)")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    s = sub.add_parser("simulate", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=epilog("simulate"), help="write a synthetic trial (C3D) and its true joint angles (CSV)")
    s.add_argument("--motion", required=True, choices=["abduction", "flexion", "scaption", "sier"])
    s.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    s.add_argument("--rate", type=float, default=100.0, help="sampling rate, Hz (default 100)")
    s.add_argument("--noise-mm", type=float, default=0.0, help="Gaussian measurement noise SD, mm")
    s.add_argument("--sta-mm", type=float, default=0.0, help="soft-tissue artefact amplitude, mm")
    s.add_argument("--sta", default="per-marker", metavar="MODEL",
                   help="soft-tissue artefact model: per-marker (default: each marker its own random artefact of "
                        "--sta-mm), bone (fitted on bone pins, S2M: exubio/data/sta_bone_s2m.json) or a model JSON of "
                        "'exubio sta-fit': the scapula and humerus markers move as a cluster over the bone as the model "
                        "predicts from the simulated angles, plus its non-rigid rest; the clavicle, forearm and hand "
                        "markers keep the per-marker artefact of --sta-mm (the model has no data for them), the thorax none")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--cycle-s", type=float, default=5.0, help="period of the elevation cycles, s (default 5: a slow "
                   "raise; 0.6: a fast one, peak angular accelerations of thousands of deg/s^2)")
    s.add_argument("--body-mass", type=float, help="body mass, kg: also write PATH.truth_moments.csv, the motion's "
                   "exact joint moments (Dumas et al. 2007 inertia)")
    s.add_argument("--hand-load-kg", type=float, default=0.0, help="mass held in the hand, kg (with --body-mass)")
    s.add_argument("--model", help="model YAML (default: the generic model)")
    add_lean_arguments(s)
    s.add_argument("--perturb", nargs="+", metavar="KEY=VALUE",
                   help="generate with the model perturbed (mm in the thorax frame; a model mismatch for a reconstruction "
                        "with the unperturbed model): ellipsoid_centre_mm=DX,DY,DZ ellipsoid_radii_scale=S|SX,SY,SZ "
                        "length.SEGMENT=S joint.SEGMENT=DX,DY,DZ marker.POINT=DX,DY,DZ; written into the truth file's header")
    s.add_argument("--protocol", action="append", help="write this protocol's markers instead of the default set "
                   "(at its positions, under its labels; side: left mirrors the simulated arm); give it twice, one "
                   "per arm, for a trial of both arms (noise-free or --noise-mm; no --sta-mm)")
    s.add_argument("--out", required=True, help="PATH.c3d; PATH.truth.csv is written beside it")
    s.set_defaults(func=cmd_simulate)
