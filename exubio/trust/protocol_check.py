"""A protocol checked before any trial (``exubio protocols FILE [--trial T] [--static S]``): what its
markers can measure, per anatomical angle (measured / modelled / not measured, and why), and the
mistakes a hand-written protocol makes, each named by its key and marker:

* a segment left without markers while a segment below it has some (warning: its orientation is
  seen only through its children's markers, and its angles say so);
* a relabel that reads a label as one no marker uses (warning); with a trial, a relabel key that
  matches no label of it, with the near labels (error);
* with a trial or static: markers on the wrong side of the thorax for the protocol's ``side``
  (error when most are, warning naming the few otherwise), protocol markers the trial lacks with
  their near labels (error);
* with a static: markers declared on a bony landmark (``point`` equal to the landmark) that the
  static, once calibrated, puts more than DECLARED_ON_LANDMARK_MM from it (warning with the
  distances: a skin marker over SC, AC or the coracoid sits 10-20 mm off the bone).

Metres written in a ``_mm`` key are refused when the protocol is read (exubio.protocol.load).
Errors make the command exit 2; warnings are printed and leave it 0."""
from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from exubio.errors import InputError, ProtocolError
from exubio.model.frame_definitions import JOINT_SEGMENTS
from exubio.types import Model, Protocol, Trajectories

__all__ = ["DECLARED_ON_LANDMARK_MM", "ProtocolCheck", "ProtocolFinding", "check_protocol"]

DECLARED_ON_LANDMARK_MM = 10.0
"""A marker declared on a landmark that the calibrated static puts farther than this from it is
named: the girdle markers of the 21-marker trials sit 13-16 mm from SC, AC and the coracoid, and
declared on those landmarks they made a reconstruction of martin_dynamique fail (30-37 mm mean
residual, LS) where declared 15 mm out from the bone it gives 6.7 mm (docs/troubleshooting-protocols.md)."""

WRONG_SIDE_MM = 10.0
"""A marker whose median position lies more than this across the thorax's sagittal plane (ISB Z) is
on the other side: the sternoclavicular markers sit 5-30 mm off the midline on their own side."""

_DISTAL = {"elbow_flexion": ("humerus", "ulna"), "forearm_pronation": ("ulna", "radius"),
           "wrist_flexion": ("radius", "hand"), "wrist_radial_deviation": ("radius", "hand")}


@dataclass(frozen=True)
class ProtocolFinding:
    """level: 'error' (the command exits 2) or 'warning'; key: the protocol key it is about."""

    level: str
    key: str
    message: str


@dataclass(frozen=True)
class ProtocolCheck:
    """status: per anatomical angle, what the markers can do before any trial (measured, modelled,
    not measured, partly ...); why: for each angle not measured or modelled, the reason."""

    status: Mapping[str, str]
    why: Mapping[str, str]
    findings: tuple[ProtocolFinding, ...]

    @property
    def errors(self) -> tuple[ProtocolFinding, ...]:
        return tuple(f for f in self.findings if f.level == "error")


def check_protocol(model: Model, protocol: Protocol, /, *, trial: Trajectories | None = None,
                   static: Trajectories | None = None) -> ProtocolCheck:
    """Check ``protocol`` (loaded against ``model``) before any trial; with ``trial`` or ``static``
    also against its labels and marker positions (module docstring)."""
    from exubio.protocol.bind import bind
    from exubio.trust.assess import angle_determinacy_of_protocol

    det, ht = angle_determinacy_of_protocol(bind(model, protocol))
    status = det.trial_status()
    findings = _unmarked_segments(model, protocol) + _relabel_values(protocol)
    for traj in (t for t in (trial, static) if t is not None):
        findings += _against_trial(model, protocol, traj)
    if static is not None and not any(f.level == "error" for f in findings):
        findings += _declared_on_landmarks(model, protocol, static)
    return ProtocolCheck(status, _why(model, protocol, status, det.causes(), ht), tuple(findings))


def _marked(model: Model, protocol: Protocol) -> dict[str, int]:
    count = {s.name: 0 for s in model.segments}
    for m in protocol.markers:
        count[m.segment] += 1
    return count


def _below(model: Model, segment: str) -> list[str]:
    out, frontier = [], [segment]
    while frontier:
        kids = [s.name for s in model.segments if s.parent in frontier]
        out += kids
        frontier = kids
    return out


def _unmarked_segments(model: Model, protocol: Protocol) -> list[ProtocolFinding]:
    count = _marked(model, protocol)
    out = []
    for seg in model.segments[1:]:
        below = [s for s in _below(model, seg.name) if count[s]]
        if count[seg.name] == 0 and below:
            out.append(ProtocolFinding(
                "warning", "markers", f"segment '{seg.name}' has no marker (no markers.*.segment: {seg.name}), while "
                f"{', '.join(below)} below it have {sum(count[s] for s in below)}: its orientation is seen only "
                f"through theirs, so its joint angles are measured only as far as the status above says; add a "
                f"marker on '{seg.name}' (exubio model-points --segment {seg.name} lists its points)"))
    return out


def _relabel_values(protocol: Protocol) -> list[ProtocolFinding]:
    labels = {n for m in protocol.markers for n in (m.name, *m.aliases)}
    labels |= {getattr(protocol.thorax_frame, k) for k in protocol.thorax_frame.keys}
    labels |= {a for names in protocol.thorax_aliases.values() for a in names}
    out = []
    for key, value in protocol.relabel.items():
        if value not in labels and value not in protocol.relabel:
            near = difflib.get_close_matches(value, sorted(labels), n=3, cutoff=0.5)
            out.append(ProtocolFinding(
                "warning", f"relabel.{key}", f"relabel.{key}: reads '{key}' as '{value}', which is no marker of the "
                f"protocol (names, aliases, thorax_frame)" + (f"; near: {near}" if near else "")))
    return out


def _against_trial(model: Model, protocol: Protocol, traj: Trajectories) -> list[ProtocolFinding]:
    from exubio.prep.targets import prepare_targets
    from exubio.trust.missing_markers import near_labels

    where = traj.source or "trial"
    out = []
    for key in protocol.relabel:
        if key not in traj.labels:
            near = difflib.get_close_matches(key, list(traj.labels), n=3, cutoff=0.5)
            out.append(ProtocolFinding(
                "error", f"relabel.{key}", f"relabel.{key}: {where} has no label '{key}', so this relabel reads "
                f"nothing; " + (f"near labels it has: {near}" if near else f"its labels are {list(traj.labels)}")))
    relabel = protocol.relabel
    have = {relabel.get(lab, lab) for lab in traj.labels}
    missing = [m.name for m in protocol.markers if not m.optional and not ({m.name, *m.aliases} & have)]
    if missing:
        near = near_labels(missing, traj, protocol)
        out.append(ProtocolFinding(
            "error", "markers", f"{where} lacks marker(s) {missing} of the protocol"
            + (": " + "; ".join(f"'{n[0]}' for {name}? ({n[1]})" for name, n in near.items()) if near else "")))
    loose = dataclasses.replace(protocol, markers=tuple(dataclasses.replace(m, optional=True) for m in protocol.markers),
                                cutoff_hz=None)
    try:
        targets = prepare_targets(traj, loose)
    except (InputError, ProtocolError) as exc:
        return out + [ProtocolFinding("error", "thorax_frame", str(exc))]
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            z_mm = np.nanmedian(targets.positions_m[..., 2], axis=0) * 1000.0
    seen = [(m.name, z) for m, z in zip(protocol.markers, z_mm) if np.isfinite(z)]
    wrong = [(n, z) for n, z in seen if z < -WRONG_SIDE_MM]
    if not wrong:
        return out
    side, other = protocol.side, "left" if protocol.side == "right" else "right"
    sign = -1.0 if protocol.side == "left" else 1.0  # back to the trial's own Z (a left arm is mirrored)
    zs = [sign * z for _, z in wrong]
    names = ", ".join(n for n, _ in wrong)
    if len(wrong) > len(seen) / 2:
        out.append(ProtocolFinding(
            "error", "side", f"side: {side}, but {len(wrong)} of the {len(seen)} markers ({names}) lie on the thorax's "
            f"{other} side in {where} (ISB Z {min(zs):+.0f} to {max(zs):+.0f} mm; Z points to the right): this is "
            f"a {other}-arm trial; set side: {other}, or use the {other} arm's protocol"))
    else:
        out.append(ProtocolFinding(
            "warning", "markers", f"{', '.join(f'markers.{n}' for n, _ in wrong)}: on the thorax's {other} side in "
            f"{where} (ISB Z {', '.join(f'{z:+.0f}' for z in zs)} mm) while the protocol is for the {side} arm and its "
            f"other markers are on that side: another arm's marker under this label?"))
    return out


def _declared_on_landmarks(model: Model, protocol: Protocol, static: Trajectories) -> list[ProtocolFinding]:
    from exubio.calibration import calibrate_model

    on = [m for m in protocol.markers if m.landmark is not None and m.point == m.landmark]
    if not on:
        return []
    try:
        _, report = calibrate_model(model, protocol, static)
    except (InputError, ProtocolError) as exc:
        return [ProtocolFinding("error", "markers", f"the static {static.source}: {exc}")]
    except Exception as exc:  # noqa: BLE001 - a calibration that fails is the finding, said once
        return [ProtocolFinding("warning", "markers", f"the static {static.source} could not be calibrated with this "
                                f"protocol ({type(exc).__name__}: {exc}); the landmark places were not checked")]
    offset = {c.name: c.generic_offset_mm for c in report.markers if c.registered}
    far = sorted(((offset[m.name], m) for m in on if offset.get(m.name, 0.0) > DECLARED_ON_LANDMARK_MM),
                 key=lambda x: -x[0])
    if not far:
        return []
    what = ", ".join(f"{m.name} {d:.0f} mm from {m.landmark}" for d, m in far)
    keys = ", ".join(f"markers.{m.name}.point" for _, m in far)
    return [ProtocolFinding(
        "warning", keys,
        f"{keys}: declared on their landmark (point: = landmark:), but {static.source} puts them elsewhere: {what} (the "
        f"calibrated static's place against the declared one). A skin marker sits off the bone: declare where it "
        f"is, the landmark plus its offset (local_position_mm, keep landmark: and give landmark_offset_mm); for "
        f"the girdle see docs/troubleshooting-protocols.md")]


def _bound_reasons(name: str, causes: Mapping[str, np.ndarray], ht: np.ndarray) -> list[str]:
    from exubio.trust.angle_uncertainty import GIMBAL_MARGIN_DEG, U_BOUND_DEG

    out = []
    n = ht.size
    for cause, text in (("gimbal", f"within {GIMBAL_MARGIN_DEG:g} deg of its sequence's gimbal lock"),
                        ("uncertainty", f"its standard uncertainty under the bone-pin soft-tissue artefact and the "
                                        f"model girdle's error above {U_BOUND_DEG:g} deg")):
        frames = causes[cause]
        if frames.any():
            h = np.degrees(ht[frames])
            out.append(f"{text} in {int(frames.sum())} of {n} reference postures (HT {h.min():.0f}-{h.max():.0f} deg)")
    return out


def _why(model: Model, protocol: Protocol, status: Mapping[str, str],
         causes: Mapping[str, Mapping[str, np.ndarray]] | None = None, ht: np.ndarray | None = None) -> dict[str, str]:
    """Per angle not measured or modelled: the reason, from the segments' markers, the holds, and
    (``causes``, ``ht``: AngleDeterminacy.causes over the reference postures and their HT elevation)
    the gimbal margin and the uncertainty bound."""
    count = _marked(model, protocol)
    seen = {s.name: count[s.name] > 0 or any(count[b] for b in _below(model, s.name)) for s in model.segments}
    seen["thorax"] = True
    out = {}
    for name, st in status.items():
        if st == "measured":
            continue
        pair = _DISTAL.get(name) or JOINT_SEGMENTS.get(name.split("_", 1)[0])
        blind = [s for s in (pair or ()) if not seen.get(s, True)]
        bare = [s for s in (pair or ()) if s != "thorax" and count.get(s, 1) == 0 and seen.get(s, True)]
        if st.endswith("modelled"):
            out[name] = f"set by the protocol's hold ({', '.join(protocol.held_coordinates)}), not by the markers"
        elif blind:
            out[name] = f"no marker on {' or '.join(blind)} or below it"
        elif bare:
            out[name] = f"no marker on {' or '.join(bare)}: seen only through the segments below it"
        elif causes is not None and ht is not None and not causes[name]["markers"].any():
            out[name] = "; ".join(_bound_reasons(name, causes[name], ht)) or "not determined"
        else:
            segs = " and ".join(s for s in (pair or ()) if s != "thorax")
            bound = "; ".join(_bound_reasons(name, causes[name], ht)) if causes is not None and ht is not None else ""
            out[name] = (f"the markers on {segs} do not determine it in some reference postures (noise gain above "
                         f"2 deg per mm): near the arm hanging, where the angle's sequence is in gimbal lock or a "
                         f"straight elbow hides the humerus's axial rotation, or markers close to the segment's axis"
                         if st.startswith("partly") else
                         f"the markers on {segs} do not determine it in any reference posture (noise gain above 2 deg "
                         f"per mm): markers on a line, or too few off the segment's axis") + (f"; {bound}" if bound else "")
    return out
