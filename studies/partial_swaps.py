"""Labels exchanged in part of a trial (exubio.trust.label_ranges) on the real C3D/TRC trials of
../shared/data: as recorded (the largest gain any exchange gives, which the threshold must clear),
and with pairs of markers exchanged in a frame range (found, and the frames found). Prints one line
per case.

Usage: python studies/partial_swaps.py
"""
from __future__ import annotations

import dataclasses
import sys
import warnings
from pathlib import Path

from exubio.io.trial import read_trial
from exubio.trust.label_ranges import GAIN_MM, find_partial_swaps
from exubio.run.inputs import load_model_and_protocol, protocol_for_model
from exubio.protocol.labels import resolve_labels
from exubio.io.resources import shipped_file

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SESSION = Path(__file__).resolve().parents[1] / "protocols" / "examples" / "kinova_martin_session.yaml"
INJECT = [("EPI_lat", "EPI_med"), ("ARM", "DELT"), ("ULNA", "RADIUS"), ("MET2", "MET5"), ("SCAP_IA", "SCAP_AA")]


def _exchanged(traj, a, b, start, stop):
    pos = traj.positions_m.copy()
    i, j = traj.labels.index(a), traj.labels.index(b)
    pos[start:stop, [i, j]] = pos[start:stop, [j, i]]
    return dataclasses.replace(traj, positions_m=pos)


def main() -> int:
    warnings.simplefilter("ignore")
    if not DATA.is_dir():
        print(f"{DATA} is absent", file=sys.stderr)
        return 2
    model, shipped = load_model_and_protocol()
    session = protocol_for_model(model, SESSION)
    trc = protocol_for_model(model, shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols"))
    print(f"threshold {GAIN_MM} mm")
    for path in sorted(DATA.glob("c3d/*.c3d")) + sorted(DATA.glob("trc/*.trc")):
        protocol = trc if path.suffix == ".trc" else (session if "kinova" in path.name else shipped)
        traj = read_trial(path)
        found = find_partial_swaps(traj, protocol, model)
        probe = next((g for g in (25.0, 20.0, 15.0, 10.0) if find_partial_swaps(traj, protocol, model, gain_mm=g)), None)
        print(f"{path.name:44s} as recorded: {[s.describe() for s in found] or 'none'}; an exchange would first be "
              f"found at a threshold of {probe if probe is not None else '< 10'} mm")
        if path.suffix == ".trc" or "statique" in path.name:
            continue
        n = traj.positions_m.shape[0]
        match = resolve_labels(protocol, traj.labels)
        for a, b in INJECT:
            la = next(lab for lab in traj.labels if match.columns.get(a) is not None and traj.labels.index(lab) == match.columns[a])
            lb = next(lab for lab in traj.labels if match.columns.get(b) is not None and traj.labels.index(lab) == match.columns[b])
            start, stop = n // 4, n // 4 + n // 5
            hit = [s for s in find_partial_swaps(_exchanged(traj, la, lb, start, stop), protocol, model)
                   if {s.a, s.b} == {a, b}]
            got = "; ".join(f"frames {', '.join(f'{x}-{y - 1}' for x, y in s.ranges)} gain {s.gain_mm:.0f} mm" for s in hit)
            print(f"    {a}-{b} exchanged in frames {start}-{stop - 1}: {got or 'NOT FOUND'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
