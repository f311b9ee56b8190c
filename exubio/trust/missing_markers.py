"""A marker the protocol needs but the trial lacks (a label typo, a marker that fell off before the
recording: no label, or a label without a single sample): dropped when the markers left still measure every anatomical angle the full set
measures (the noise-gain criterion over the reference postures, exubio.trust.assess), else refused with
the angles it would cost. A dropped marker is a ``check`` of the trial naming it."""
from __future__ import annotations

import dataclasses
import difflib

from exubio.errors import InputError
from exubio.types import Model, Protocol, Trajectories

__all__ = ["drop_missing_markers"]


def _present(protocol: Protocol, traj: Trajectories) -> dict[str, bool]:
    """Per protocol marker: the trial has it under its name or an alias, with at least one sample."""
    import numpy as np

    relabel = dict(getattr(protocol, "relabel", None) or {})
    column = {relabel.get(lab, lab): i for i, lab in enumerate(traj.labels)}
    out = {}
    for m in protocol.markers:
        cols = [column[lab] for lab in (m.name, *m.aliases) if lab in column]
        out[m.name] = any(bool(np.isfinite(traj.positions_m[:, c]).all(axis=1).any()) for c in cols)
    return out


def drop_missing_markers(traj: Trajectories, protocol: Protocol, model: Model, /) -> tuple[Protocol, tuple[str, ...]]:
    """(the protocol with the trial's missing non-optional markers made optional, their names);
    InputError naming the file, the markers, a near label the trial has and the angles that would
    no longer be measured, when dropping them costs a measured angle."""
    from exubio.trust.assess import angle_status_of_protocol

    present = _present(protocol, traj)
    missing = tuple(m.name for m in protocol.markers if not m.optional and not present[m.name])
    if not missing:
        return protocol, ()
    reduced = dataclasses.replace(protocol, markers=tuple(
        dataclasses.replace(m, optional=True) if m.name in missing else m for m in protocol.markers))
    full = angle_status_of_protocol(model, protocol, bounded=False)  # what the markers see: the bound would
    left = angle_status_of_protocol(model, reduced, bounded=False)   # move with any marker's weight
    lost = [n for n, s in full.items() if s == "measured" and left.get(n) != "measured"]
    if lost:
        unused = [lab for lab in traj.labels if lab not in {n for m in protocol.markers for n in (m.name, *m.aliases)}]
        hints = []
        for name in missing:
            near = difflib.get_close_matches(name, unused, n=1, cutoff=0.6)
            if near:
                hints.append(f"'{near[0]}' for {name}? (protocol: aliases: [{near[0]}], or --relabel {near[0]}={name})")
        raise InputError(f"{traj.source or 'trial'}: marker(s) {list(missing)} of protocol {protocol.name} missing; "
                         f"without them the markers would no longer measure {', '.join(lost)}"
                         + (f"; the trial has {', '.join(hints)}" if hints else f"; the trial has {list(traj.labels)}"))
    return reduced, missing
