"""``exubio reconstruct TRIAL --fill FILE``: the trial's markers with their gaps filled from the reconstruction.

FILE has the trial's format (.c3d for a C3D trial, .trc for a TRC trial) and is the trial's copy
with only the filled samples changed (exubio.prep.fill: model point plus the marker's mean offset
around the gap; gaps longer than exubio.prep.fill.MAX_FILL_S left empty). Beside it,
``FILE.fill.csv`` lists every gap of every marker (frames as the file numbers them, filled 1/0, why
not, the offset used); in a C3D the filled samples also carry residual 0 and are listed in the
parameter group EXUBIO_FILL. The reconstruction used is PF's where both methods ran (the default
method), else the one that ran.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from exubio.errors import InputError
from exubio.io.results import atomic_write, read_npz_arrays
from exubio.io.trial import read_trial
from exubio.prep.fill import MAX_FILL_S, GapFill, fill_gaps, fill_table_text

__all__ = ["add_fill_arguments", "check_fill", "companion_path", "write_fill", "fill_from_result"]

_FORMATS = (".c3d", ".trc")


def add_fill_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fill", metavar="FILE", help="also write the trial's markers with every gap of up to "
                        f"{MAX_FILL_S:g} s filled from the reconstructed model (FILE.c3d or FILE.trc, the trial's "
                        "format; every other sample, marker and label kept), and FILE.fill.csv listing each gap")


def companion_path(path: str | Path) -> Path:
    return Path(str(path) + ".fill.csv")


def check_fill(args: argparse.Namespace) -> None:
    """Refuse (InputError, before any work) a --fill the run cannot honour."""
    if not getattr(args, "fill", None):
        return
    out = Path(args.fill)
    if len(args.trials) != 1:
        raise InputError(f"--fill {args.fill}: fills one trial; give one TRIAL (got {len(args.trials)})")
    trial = Path(args.trials[0])
    if out.suffix.lower() not in _FORMATS or out.suffix.lower() != trial.suffix.lower():
        raise InputError(f"--fill {args.fill}: expected a file of the trial's format ({trial.suffix.lower()} for "
                         f"{trial.name}), so that its other markers, labels and frame numbers are kept")
    if out.resolve() == trial.resolve():
        raise InputError(f"--fill {args.fill}: this is the trial itself; write the filled copy to another file")
    for flag in ("relabel", "repair_labels", "both_arms"):
        if getattr(args, flag, None):
            raise InputError(f"--fill with --{flag.replace('_', '-')}: not supported (the filled file keeps the "
                             f"file's labels); relabel the trial in the capture software first")
    if not args.overwrite:
        for p in (out, companion_path(out)):
            if p.exists():
                raise InputError(f"--fill {args.fill}: {p} exists; give --overwrite to replace it")


def write_fill(trial_path: str | Path, out: str | Path, fill: GapFill, /) -> tuple[Path, Path]:
    """Write the filled copy of the trial file and its fill table (both atomically)."""
    trial_path, out = Path(trial_path), Path(out)
    samples = {lab: (fill.filled[:, k], fill.positions_m[:, k]) for k, lab in enumerate(fill.labels)
               if fill.filled[:, k].any()}
    if trial_path.suffix.lower() == ".c3d":
        from exubio.io.c3d import write_c3d_samples

        path = write_c3d_samples(trial_path, out, samples)
    else:
        from exubio.io.trc import write_trc_samples

        path = write_trc_samples(trial_path, out, samples)
    traj = read_trial(trial_path)
    first = _first_frame(trial_path)
    table = fill_table_text(fill, traj.time_s, first_frame=first)
    csv = atomic_write(companion_path(out), lambda tmp: tmp.write_text(table, encoding="utf-8"))
    return path, csv


def _first_frame(trial_path: Path) -> int:
    """The number the file gives its first frame (a C3D's header first frame, a TRC's first Frame# cell)."""
    if trial_path.suffix.lower() == ".c3d":
        from exubio.io.c3d_raw import raw_header
        import struct

        byte_order, _, header = raw_header(trial_path)
        return int(struct.unpack(byte_order + "H", header[6:8])[0])
    for line in trial_path.read_text(encoding="utf-8").splitlines()[5:]:
        if line.strip():
            try:
                return int(float(line.split("\t")[0]))
            except ValueError:
                return 1
    return 1


def fill_from_result(trial_path: str | Path, out: str | Path, npz: str | Path, session: Any, /) -> tuple[GapFill, Path, Path]:
    """Fill the trial from its result set ``npz`` (its q) made with ``session`` (exubio.run.inputs.Session:
    the model and protocol the trial was reconstructed with) and write FILE and FILE.fill.csv."""
    from exubio.trust.missing_markers import drop_missing_markers

    traj = read_trial(trial_path)
    q = read_npz_arrays(npz, ("q_rad",))["q_rad"]
    binding, _ = drop_missing_markers(traj, session.binding)
    fill = fill_gaps(traj, session.model, binding.protocol, q)
    path, csv = write_fill(trial_path, out, fill)
    return fill, path, csv


def fill_after_run(args: argparse.Namespace, result: Any, session: Any, /) -> None:
    """After ``exubio reconstruct`` ran one trial: fill it from its PF result (else its LS result) and
    say what was written and what was left empty."""
    if not result.methods:
        raise InputError(f"--fill {args.fill}: no reconstruction of {args.trials[0]} to fill from")
    by = {m.method: m for m in result.methods}
    method = by.get("pf") or next(iter(by.values()))
    if result.calibration is not None:  # calibrated on the trial's own frames
        from exubio.run.inputs import load_session

        session = load_session(model_path=result.calibration.model_file, protocol_path=args.protocol)
    fill, path, csv = fill_from_result(args.trials[0], args.fill, method.paths["npz"], session)
    left = [g for g in fill.gaps if not g.filled]
    print(f"filled ({method.method}): {sum(g.filled for g in fill.gaps)} gap(s), {fill.n_filled} sample(s): {path}; "
          f"{len(left)} gap(s) left empty; every gap listed in {csv}")
