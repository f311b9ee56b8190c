"""A trial's marker labels matched to a protocol: each protocol marker found among the labels (by
its name, then its aliases) after the protocol's own ``relabel``, and a relabel given for one
trial (``--relabel A=B,...``) parsed and applied."""
from __future__ import annotations

import dataclasses
import difflib
import logging
from dataclasses import dataclass
from typing import Mapping, Sequence

from exubio.errors import InputError, ProtocolError
from exubio.types import Protocol, Trajectories

__all__ = ["LabelMatch", "parse_relabel", "relabel_trajectories", "resolve_labels"]

log = logging.getLogger(__name__)
_WARNED: set[tuple[str, str]] = set()  # (trial, relabel key) said to match no label


@dataclass(frozen=True)
class LabelMatch:
    """Where each protocol marker is in a trial.

    columns:        protocol marker name -> trial column (None: optional marker not in the trial),
                    in protocol order.
    thorax_columns: thorax-frame landmark key (ij, px, c7, t8) -> trial column; empty when the
                    protocol's thorax frame is the identity.
    unused:         trial labels neither tracked nor used for the thorax frame, in trial order.
    """

    columns: dict[str, int | None]
    thorax_columns: dict[str, int]
    unused: tuple[str, ...]


def resolve_labels(protocol: Protocol, labels: Sequence[str], /, *, source: str = "") -> LabelMatch:
    """Find each protocol marker among a trial's ``labels`` (by its name, then its aliases in
    order) and the thorax-frame landmarks (by label).

    A missing non-optional marker or thorax landmark raises an InputError naming them, the file
    (``source``) and the labels the trial has. Missing optional markers map to None.

    The protocol's ``relabel`` is applied first: a trial label that is a key of it is read as its
    value (the columns are unchanged; ``unused`` lists the labels as the trial has them).
    """
    where = source or "trial"
    trial_labels = tuple(labels)
    labels = _relabelled(protocol, trial_labels, where)
    index = {lab: i for i, lab in enumerate(labels)}
    columns: dict[str, int | None] = {}
    owner: dict[int, str] = {}
    missing: list[str] = []
    for m in protocol.markers:
        col = None
        for lab in (m.name, *m.aliases):
            if lab in index:
                if col is None:
                    col = index[lab]
                else:
                    log.warning(
                        "%s: marker '%s' found as '%s' and also as '%s'; using '%s'",
                        where, m.name, labels[col], lab, labels[col],
                    )
        if col is not None and col in owner:
            raise ProtocolError(
                f"{protocol.source or protocol.name}: trial label '{labels[col]}' matches both marker "
                f"'{owner[col]}' and marker '{m.name}'; names and aliases must be unique"
            )
        if col is None and not m.optional:
            alias = f" (aliases {list(m.aliases)})" if m.aliases else ""
            missing.append(f"'{m.name}'{alias}")
        if col is not None:
            owner[col] = m.name
        columns[m.name] = col

    thorax: dict[str, int] = {}
    frame = protocol.thorax_frame
    if not frame.is_identity:
        aliases = getattr(protocol, "thorax_aliases", None) or {}
        for key in frame.keys:
            lab = getattr(frame, key)
            found = next((a for a in (lab, *aliases.get(lab, ())) if a in index), None)
            if found is None:
                also = f", aliases {list(aliases[lab])}" if aliases.get(lab) else ""
                missing.append(f"'{lab}' (thorax_frame.{key}{also})")
            else:
                thorax[key] = index[found]
    if missing:
        taken = {labels[c] for c in (*owner, *thorax.values())}
        wanted = [w.split("'")[1] for w in missing]
        near = {w: difflib.get_close_matches(w, [lab for lab in labels if lab not in taken], n=1, cutoff=0.6)
                for w in wanted}
        hint = "; ".join(f"'{n[0]}' for {w}? (--relabel {n[0]}={w})" for w, n in near.items() if n)
        raise InputError(
            f"{where}: protocol '{protocol.name}' needs marker(s) {', '.join(missing)}, not in the trial; "
            + (f"the trial has {hint}; " if hint else "")
            + f"the trial has {list(trial_labels)}"
            + (f" (read as {list(labels)} after the protocol's relabel)" if labels != trial_labels else "")
        )
    used = set(owner) | set(thorax.values())
    unused = tuple(lab for i, lab in enumerate(trial_labels) if i not in used)
    return LabelMatch(columns=columns, thorax_columns=thorax, unused=unused)


def parse_relabel(text: str | None, /, *, option: str = "--relabel") -> dict[str, str]:
    """``A=B,C=D`` (read trial label A as B, ...) -> {A: B, C: D}; an InputError names the option and
    the item when an item is not LABEL=LABEL or a label is read twice."""
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        item = item.strip()
        if not item:
            continue
        old, sep, new = item.partition("=")
        old, new = old.strip(), new.strip()
        if not sep or not old or not new:
            raise InputError(f"{option} {text}: '{item}' is not LABEL=LABEL (read trial label LABEL as LABEL), "
                             f"e.g. {option} RADIUS=ULNA,ULNA=RADIUS")
        if old in out:
            raise InputError(f"{option} {text}: '{old}' is given twice")
        out[old] = new
    return out


def relabel_trajectories(traj: Trajectories, relabel: Mapping[str, str], /, *, option: str = "--relabel") -> Trajectories:
    """The trial with its labels read as ``relabel`` says (a permutation: no two labels may end as
    one; a label the trial lacks is an InputError naming it and the file)."""
    if not relabel:
        return traj
    where = traj.source or "trial"
    missing = sorted(set(relabel) - set(traj.labels))
    if missing:
        raise InputError(f"{option}: {where} has no label {missing}; it has {list(traj.labels)}")
    labels = tuple(relabel.get(lab, lab) for lab in traj.labels)
    if len(set(labels)) != len(labels):
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        raise InputError(f"{option}: {where} would have two markers labelled {dup}; a relabel must be a permutation "
                         f"of the trial's labels (e.g. A=B,B=A)")
    log.info("%s: labels read as %s says: %s", where, option, ", ".join(f"{a}->{b}" for a, b in relabel.items()))
    return dataclasses.replace(traj, labels=labels)


def _relabelled(protocol: Protocol, labels: tuple[str, ...], where: str) -> tuple[str, ...]:
    """The trial's labels as the protocol's ``relabel`` reads them. Reading a label as one the
    trial already has (and keeps) would make two markers of one label: a ProtocolError names the
    protocol file, the relabel key and the trial."""
    relabel = getattr(protocol, "relabel", None) or {}
    if not relabel:
        return labels
    for key in relabel:
        if key not in labels and (where, key) not in _WARNED:
            _WARNED.add((where, key))  # said once per trial, however often its labels are matched
            near = difflib.get_close_matches(key, list(labels), n=3, cutoff=0.5)
            log.warning("%s: relabel.%s of %s matches no label of the trial%s", where, key,
                        protocol.source or protocol.name, f" (near: {near})" if near else "")
    out = tuple(relabel.get(lab, lab) for lab in labels)
    if len(set(out)) != len(out):
        seen: dict[str, str] = {}
        for old, new in zip(labels, out):
            if new in seen:
                renamed = old if old in relabel else seen[new]
                other = seen[new] if renamed == old else old
                raise ProtocolError(
                    f"{protocol.source or protocol.name}: relabel.{renamed}: {where} has both '{renamed}' and "
                    f"'{other}', and both would be read as '{new}'; a relabel must be a permutation of the "
                    f"trial's labels (add '{other}: <label>' to read '{other}' as another label)"
                )
            seen[new] = old
    changed = [f"{a}->{b}" for a, b in zip(labels, out) if a != b]
    if changed:
        log.info("%s: labels read as the protocol's relabel says: %s", where, ", ".join(changed))
    return out
