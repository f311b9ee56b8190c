"""``exubio demo``: the shipped example trial reconstructed with PF and LS and compared with its truth."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from exubio.cli.common import EXIT_OK, epilog, print_quality, print_result, progress_factory
from exubio.model.signs import add_signs_arguments  # small: the --signs option

EXAMPLE_COMMAND = ("exubio simulate --motion abduction --duration 10 --rate 100 --noise-mm 1 --sta-mm 10 "
                   "--seed 1 --out exubio/data/example_abduction.c3d")


def cmd_demo(args: argparse.Namespace) -> int:
    import numpy as np

    from exubio.io.resources import shipped_file
    from exubio.io.results import read_angles_csv
    from exubio.run.pipeline import reconstruct_file
    from exubio.trust.evaluate import measured_angle_rmse_deg

    out = Path(args.out)
    c3d = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    truth_csv = c3d.with_name("example_abduction.truth.csv")
    print(f"example trial: {c3d}")
    print("  synthetic arm abduction, 10 s at 100 Hz, 22 markers, 1 mm noise, 10 mm soft-tissue artefact;")
    print(f"  made by: {EXAMPLE_COMMAND}")
    print(f"reconstructing it with the potential-field (pf) and least-squares (ls) methods -> {out}")
    from exubio.run.inputs import load_session
    from exubio.run.pipeline import RunSettings

    session = load_session(signs=args.signs)
    outputs = reconstruct_file(c3d, out, methods=["pf", "ls"], session=session,
                               settings=RunSettings(overwrite=True, progress_factory=progress_factory(not args.quiet)))
    t_true, names, q_true = read_angles_csv(truth_csv)
    from exubio.model.angles import anatomical_table

    angle_names, true_angles = anatomical_table(session.model, q_true)
    for o in outputs:  # each method's outcome (exubio.run.outcome.MethodOutcome), written afresh (overwrite)
        recon, summ = o.reconstruction, o.summary
        print_result(recon, o.paths, summ)
        measured = measured_angle_rmse_deg(session.model, recon.q_rad, q_true, o.angles.status)
        print(f"[{recon.method}] anatomical angles against the truth, the {len(measured)} measured ones: RMSE mean "
              f"{np.mean(list(measured.values())):.2f} deg, max {max(measured.values()):.2f} deg "
              f"({max(measured, key=measured.get)}); SC elevation {measured.get('SC_X_elevation', float('nan')):.2f}, "
              f"SC protraction {measured.get('SC_Y_protraction', float('nan')):.2f} deg")
        others = (summ.get("anatomical_angles") or {}).get("status", {})
        for label in ("modelled", "not measured"):
            these = [n for n, v in others.items() if v.endswith(label)]
            if these:
                print(f"[{recon.method}] {label} (not compared with the truth): {', '.join(these)}")
        print_quality(recon.method, o.quality, summ.get("not_measured"))
    agree = outputs[0].agreement_deg
    worst = max(agree, key=agree.get)
    print(f"PF-LS agreement (measured anatomical angles): max RMSE {agree[worst]:.3f} deg ({worst})")
    from exubio.report.trial_report import Truth, draw_trial_report
    from exubio.run.outcome import reported

    pdf, png = draw_trial_report([reported(o, model=session.model) for o in outputs], out / "example_abduction.report.pdf",
                                  truth=Truth(t_true, angle_names, true_angles))
    print(f"report: {pdf} and {png}")
    print(f"results are in {out.resolve()}")
    return EXIT_OK


def add_parser(sub: Any, common: argparse.ArgumentParser, /) -> None:
    """Register this module's subcommand(s) on exubio's subparsers."""
    d = sub.add_parser("demo", parents=[common], formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog=epilog("demo"), help="reconstruct the shipped example trial with PF and LS, compare with its truth")
    d.add_argument("--out", default="exubio_demo", help="output folder (default ./exubio_demo)")
    add_signs_arguments(d)
    d.set_defaults(func=cmd_demo)
