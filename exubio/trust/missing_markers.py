"""A marker the protocol needs but the trial lacks (a label typo, a marker that fell off before the
recording: no label, or a label without a single sample): dropped when the markers left still measure every anatomical angle the full set
measures (the noise-gain criterion over the reference postures, exubio.trust.assess), else refused with
the angles it would cost. A dropped marker is a ``check`` of the trial naming it."""
from __future__ import annotations

import dataclasses
import difflib

from exubio.errors import InputError
from exubio.protocol.bind import Binding
from exubio.types import Protocol, Trajectories

__all__ = ["drop_missing_markers", "near_labels"]


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


def drop_missing_markers(traj: Trajectories, binding: Binding, /) -> tuple[Binding, tuple[str, ...]]:
    """(the binding (exubio.protocol.bind) of its model and its protocol with the trial's missing
    non-optional markers made optional (``binding`` itself when none is missing), their names, each
    with the near label the trial has where it has one: ``SCAP_Cor (the trial has 'CAP_Cor' ...)``);
    InputError naming the file, the markers, a near label the trial has and the angles that would
    no longer be measured, when dropping them costs a measured angle."""
    from exubio.trust.assess import angle_status_of_protocol

    protocol = binding.protocol
    present = _present(protocol, traj)
    missing = tuple(m.name for m in protocol.markers if not m.optional and not present[m.name])
    if not missing:
        return binding, ()
    reduced = dataclasses.replace(protocol, markers=tuple(
        dataclasses.replace(m, optional=True) if m.name in missing else m for m in protocol.markers))
    rebound = binding.rebound(reduced)
    full = angle_status_of_protocol(binding, bounded=False)  # what the markers see: the bound would
    left = angle_status_of_protocol(rebound, bounded=False)  # move with any marker's weight
    lost = [n for n, s in full.items() if s == "measured" and left.get(n) != "measured"]
    if lost:
        hints = [f"'{near}' for {name}? ({fix})" for name, (near, fix) in near_labels(missing, traj, protocol).items()]
        raise InputError(f"{traj.source or 'trial'}: marker(s) {list(missing)} of protocol {protocol.name} missing; "
                         f"without them the markers would no longer measure {', '.join(lost)}"
                         + (f"; the trial has {', '.join(hints)}" if hints else f"; the trial has {list(traj.labels)}"))
    near = near_labels(missing, traj, protocol)
    return rebound, tuple(f"{n} (the trial has '{near[n][0]}': {near[n][1]})" if n in near else n for n in missing)


def near_labels(missing, traj: Trajectories, protocol: Protocol, /) -> dict[str, tuple[str, str]]:
    """Per missing marker, a label of the trial that no marker uses and that is near its name or an
    alias (difflib), with the fix to type: {'SCAP_Cor': ('CAP_Cor', '--relabel CAP_Cor=SCAP_Cor, or ...')}."""
    used = {n for m in protocol.markers for n in (m.name, *m.aliases)}
    used |= {getattr(protocol.thorax_frame, k) for k in protocol.thorax_frame.keys}
    used |= {a for names in (getattr(protocol, "thorax_aliases", None) or {}).values() for a in names}
    relabel = dict(getattr(protocol, "relabel", None) or {})
    unused = [lab for lab in traj.labels if relabel.get(lab, lab) not in used]
    out = {}
    for name in missing:
        m = next((m for m in protocol.markers if m.name == name), None)
        for candidate in (name, *(m.aliases if m is not None else ())):
            near = difflib.get_close_matches(candidate, unused, n=1, cutoff=0.6)
            if near:
                out[name] = (near[0], f"--relabel {near[0]}={name}, or in the protocol markers.{name}.aliases: "
                                      f"[{near[0]}]")
                break
    return out
