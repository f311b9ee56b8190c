"""The thorax-label check (exubio.trust.thorax_check) on every real trial of ../shared/data, as labelled
and with two of its thorax landmarks exchanged (every pair): the fit of the file's labels, of the
best assignment, and whether the trial would be refused. Prints one line per case.

Usage: python studies/thorax_labels.py
"""
from __future__ import annotations

import dataclasses
import itertools
import sys
import warnings
from pathlib import Path

from exubio.io.trial import read_trial
from exubio.run.inputs import load_model_and_protocol, protocol_for_model
from exubio.io.resources import shipped_file
from exubio.trust.thorax_check import SWAP_RATIO, thorax_label_fit

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _swap(traj, a, b):
    labels = list(traj.labels)
    i, j = labels.index(a), labels.index(b)
    labels[i], labels[j] = labels[j], labels[i]
    return dataclasses.replace(traj, labels=tuple(labels))


def main() -> int:
    warnings.simplefilter("ignore")
    if not DATA.is_dir():
        print(f"{DATA} is absent", file=sys.stderr)
        return 2
    model, c3d_protocol = load_model_and_protocol()
    trc_protocol = protocol_for_model(model, shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols"))
    print(f"refused when the file's labels fit {SWAP_RATIO} times worse than another assignment")
    for path in sorted(DATA.glob("c3d/*.c3d")) + sorted(DATA.glob("trc/*.trc")):
        protocol = trc_protocol if path.suffix == ".trc" else c3d_protocol
        traj = read_trial(path)
        labels = [getattr(protocol.thorax_frame, k) for k in protocol.thorax_frame.keys]
        for swap in [None, *itertools.combinations(labels, 2)]:
            fit = thorax_label_fit(traj if swap is None else _swap(traj, *swap), protocol, model)
            ratio = fit.rms_mm / fit.best_rms_mm
            print(f"{path.name:44s} {'as labelled' if swap is None else 'swapped ' + '-'.join(swap):22s} "
                  f"file's labels {fit.rms_mm:5.1f} mm, best {fit.best_rms_mm:5.1f} mm ({ratio:.2f}x) "
                  f"-> {'REFUSED: read as ' + ', '.join(fit.best) if fit.swapped else 'accepted'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
