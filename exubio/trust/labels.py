"""Marker-label checks: swapped labels, a label on a marker of another segment, a marker that moved
or whose label jumps, and a reference (static) trial of another subject -- from what the protocol
and the model say, never from the name of a marker.

Expectations (:func:`model_expectations`, computed once per model, protocol and ranges): the model
is posed in ``N_POSTURES`` postures drawn uniformly within the coordinate ranges, with every
protocol marker at its local position on its segment.

1. Side relations. (A; X, Y), "A is nearer X than Y", is kept when, in every sampled posture,
   |A-Y| >= SIDE_RATIO_MIN |A-X| (subject proportions) and |A-Y| - |A-X| >= SIDE_GAP_MIN_M (the
   model's marker points are only known to MODEL_POINT_TOLERANCE_M). A trial reverses a relation
   when its median distances order them the other way.
2. Rigid pairs: markers of one segment, and pairs whose model distance varies by less than
   RIGID_MODEL_VARIATION_M (a point on a joint axis). Against a reference (:func:`pair_distances`
   of the session's static trial, or :func:`model_pair_distances` of a calibrated model) a rigid
   distance off by more than RIGID_TOLERANCE_M reveals a moved or swapped marker, and many of them
   on several segments another subject; within the trial, a spread beyond RIGID_SPREAD_MAX_M
   reveals a label that jumps between markers.
3. Chain fits. For every moving segment whose subtree carries at least 4 of the trial's markers
   on at least 2 segments, the subtree is fitted to CHAIN_FRAMES frames with its root free (6
   degrees of freedom: placement and proportions of the body above it do not matter) and its
   joints within the ranges. This is what tells mirror-image markers apart: over the wrist's range
   of motion every distance relation between the styloids and the metacarpal heads reverses
   somewhere (the generic model's min ratio for "MET5 nearer ULNA than RADIUS" is 0.83), but no
   posture of a chain turns its markers into their mirror image.

Swap search (:func:`check_trial`): every exchange of two labels is scored against the evidence.
A swap is reported when it resolves some of it and makes none worse: side relations (markers on
different segments only; within a segment the model's points do not decide), rigid distances to
the reference, or a chain that then fits. The largest chain a swap makes fit decides between rival
swaps. Accepted swaps are undone, then what is left is reported per marker: "wrong_segment" /
"side" (most of a marker's side relations reversed), "distance" (rigid distances off the
reference), "jump" (rigid distances varying within the trial); "other_subject" replaces the
reference-based findings when the reference disagrees everywhere.

What the checks cannot see: same-segment swaps of markers the model places within about 80 mm of
each other, or away from any landmark (ARM and DELT, the scapula's technical markers), without a
reference; the model's points for those may not be where a lab puts them. Mirror-image pairs are
found by the chain fits, which need frames where the chain's markers are all present.

The job is shared by five modules: the pair distances (label_distances), what the model says
(label_expectations: the posture sample, side relations, rigid pairs and chains), the chain fits
(label_chains), whether a swap is supported (label_swaps), and the findings and the check itself
(here). The thresholds are constants of the module that uses them; each says why it has its
value. Positions are metres inside; millimetres appear only in the evidence sentences.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.io.records import optional
from exubio.trust.label_chains import (
    CHAIN_FRAMES,
    CHAIN_GOOD_RMS_M,
    CHAIN_MIN_GAIN_M,
    CHAIN_SWAP_RATIO,
    chain_label,
    chain_scores,
)
from exubio.trust.label_distances import (
    PairDistances,
    in_protocol_order,
    mm_text,
    model_pair_distances,
    pair_distances,
    reference_matrix,
)
from exubio.trust.label_expectations import (
    MODEL_POINT_TOLERANCE_M,
    N_POSTURES,
    RIGID_MODEL_VARIATION_M,
    SIDE_GAP_MIN_M,
    SIDE_RATIO_MIN,
    ChainDef,
    LabelExpectations,
    SideRelation,
    model_expectations,
    sample_postures,
)
from exubio.trust.label_swaps import (
    RELATION_MIN_EXPECTED,
    RELATION_MIN_FIXED,
    RELATION_SWAP_SHARE,
    RIGID_TOLERANCE_M,
    permuted,
    rigid_bad,
    swap_facts,
    swap_support,
    violated,
)
from exubio.types import MarkerTargets, Model, Protocol

__all__ = [
    "CHAIN_FRAMES",
    "CHAIN_GOOD_RMS_M",
    "CHAIN_MIN_GAIN_M",
    "CHAIN_SWAP_RATIO",
    "MODEL_POINT_TOLERANCE_M",
    "N_POSTURES",
    "OTHER_SUBJECT_MIN_MARKERS",
    "OTHER_SUBJECT_MIN_SEGMENTS",
    "RELATION_MIN_EXPECTED",
    "RELATION_MIN_FIXED",
    "RELATION_SWAP_SHARE",
    "RIGID_MODEL_VARIATION_M",
    "RIGID_SPREAD_MAX_M",
    "RIGID_TOLERANCE_M",
    "SIDE_GAP_MIN_M",
    "SIDE_RATIO_MIN",
    "ChainDef",
    "LabelExpectations",
    "LabelFinding",
    "PairDistances",
    "SideRelation",
    "check_trial",
    "format_findings",
    "model_expectations",
    "model_pair_distances",
    "pair_distances",
    "sample_postures",
]

# --------------------------------------------------------------------------------------------
# Thresholds. "Measured" figures are from the eight C3D files of ../shared/data/c3d
# (Ipuch/bioptim_exo, MIT) with the generic model and its coordinate ranges.
# --------------------------------------------------------------------------------------------
# -- rigid pairs
RIGID_SPREAD_MAX_M = 0.020
"""Within one trial, a standard deviation of a rigid pair's distance above 20 mm flags a label that
jumps between markers. Skin motion of 10-30 mm peak to peak gives at most about 11 mm (measured:
6.6 mm at most in the correctly labelled trials; 11.3 mm for an epicondyle and the ULNA label of
the kinova_martin trials, which sits on the radial styloid and so turns with pronation); a label
that sits on a marker of another segment for 5 % of the frames or more, the distance jumping by
100 mm or more, gives at least 100 sqrt(0.05 x 0.95) = 22 mm."""

RIGID_STEP_MIN_M = 0.025
"""... and only where the distance also changes by more than 25 mm from one sample to the next: a
label that sits on another marker for part of the trial changes a rigid distance by Delta at once,
and SD > 20 mm needs Delta > 40 mm (SD = Delta sqrt(f (1 - f)) <= Delta / 2); skin that slides
changes it a little at a time (the paper's SIER with 20 mm of independent artefact per marker: SD
21-23 mm between the epicondyles, largest step 12 mm at 100 Hz with 1.5 mm noise), so a spread
without a step is the artefact, not a label."""

# -- the verdict
OTHER_SUBJECT_MIN_MARKERS = 3
"""The reference belongs to another subject when the rigid distances that disagree with it (once
up to MAX_SWAPS swaps that resolve some are undone) need at least 3 markers to be explained (the
fewest markers that appear in every disagreeing pair) ..."""

OTHER_SUBJECT_MIN_SEGMENTS = 2
"""... on at least 2 segments. A labelling error concerns one marker (moved, fallen off) or two (a
swap); another body changes segment lengths and marker spacings on several segments at once.
Measured: F0_boire_05 against martin_statique, 10 of 27 rigid distances on 3 segments, needing 4
markers; kinova_martin_statique against martin_statique (same subject, markers re-placed): none."""

MAX_SWAPS = 3
"""At most 3 swaps are reported per trial; more than that means another marker set or protocol,
not a few slips of the labeller."""

_SEVERITY = {"swap": "error", "permutation": "error", "wrong_segment": "error", "side": "warning", "distance": "warning",
             "jump": "error", "other_subject": "error"}


# --------------------------------------------------------------------------------------------
# Findings
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LabelFinding:
    """One labelling problem.

    kind:     "swap" (two labels exchanged), "permutation" (three or more in a cycle), "wrong_segment" (a label on a marker of another
              segment), "side" (a marker on the wrong side of its neighbours, no swap explains it),
              "distance" (a rigid distance disagrees with the reference: the marker moved or was
              re-placed), "jump" (a rigid distance varies within the trial: a label jumps),
              "other_subject" (the reference belongs to another subject).
    markers:  the protocol marker names concerned.
    evidence: one sentence with the numbers (mm).
    severity: "error" (the labels must be fixed before reconstruction) or "warning".
    relabel:  for a swap or permutation: the relabel that undoes it ({file label: read as}); left
              out of the file when there is none (exubio.io.records writes and reads a finding).
    """

    kind: str
    markers: tuple[str, ...]
    evidence: str
    severity: str
    relabel: Mapping[str, str] | None = optional(empty=True)

    def __post_init__(self) -> None:
        if self.relabel is None and self.kind == "swap" and len(self.markers) == 2:
            a, b = self.markers
            object.__setattr__(self, "relabel", {a: b, b: a})


def _finding(kind: str, markers: tuple[str, ...], evidence: str) -> LabelFinding:
    return LabelFinding(kind=kind, markers=markers, evidence=evidence, severity=_SEVERITY[kind])


def format_findings(findings: Sequence[LabelFinding], /, *, source: str = "") -> str:
    """One line per finding (or a line saying there is none)."""
    where = f"{source}: " if source else ""
    if not findings:
        return f"{where}labels look right (no finding)"
    return "\n".join(f"{where}{f.severity} [{f.kind}] {', '.join(f.markers)}: {f.evidence}" for f in findings)


# --------------------------------------------------------------------------------------------
# The checks
# --------------------------------------------------------------------------------------------
def _partners(pairs, m: int, most: int = 3) -> list[int]:
    """The other marker of (at most ``most`` of) the pairs that contain m."""
    return [int(p[1] if p[0] == m else p[0]) for p in pairs[:most]]


def _cover(pairs: np.ndarray) -> list[int]:
    """Fewest markers (greedy) such that every row of ``pairs`` (p, 2 or 3 marker indices) holds
    one of them: the markers that explain a set of disagreeing pairs or relations."""
    left = [tuple(p) for p in pairs]
    chosen: list[int] = []
    while left:
        counts: dict[int, int] = {}
        for p in left:
            for m in p:
                counts[m] = counts.get(m, 0) + 1
        best = max(sorted(counts), key=lambda m: counts[m])
        chosen.append(best)
        left = [p for p in left if best not in p]
    return chosen


def check_trial(
    trial: MarkerTargets | np.ndarray,
    marker_names: Sequence[str] | None = None,
    /,
    *,
    model: Model,
    protocol: Protocol,
    ranges_rad: np.ndarray | None = None,
    reference: PairDistances | None = None,
    expectations: LabelExpectations | None = None,
    chain_fits: bool = True,
) -> tuple[LabelFinding, ...]:
    """Check a trial's marker labels (see the module docstring).

    trial:        MarkerTargets, or positions (n_frames, k, 3) in metres (NaN = gap) with their
                  ``marker_names``; any frame (lab or thorax) — only distances and free-root fits
                  are used. Markers the protocol does not list are ignored; protocol markers the
                  trial lacks are skipped.
    model, protocol: what the checks expect (the protocol bound to the model). Use the generic
                  model, or one calibrated on a static trial whose labels were checked: a
                  calibration registers each marker where the static's label puts it, swap or not.
    ranges_rad:   (m, 2) coordinate ranges (rad) the postures are sampled in and the chains are
                  held within; default: the model's (``Model.coordinate_ranges_rad``).
    reference:    :func:`pair_distances` of the session's static trial (or
                  :func:`model_pair_distances` of a calibrated model) for the rigid-pair check.
    expectations: :func:`model_expectations` of the same model, protocol and ranges, to reuse
                  across trials (``ranges_rad`` is then not used): a session passes its
                  binding's (exubio.trust.label_expectations.expectations_of). When None they
                  are computed here.
    chain_fits:   run the chain fits (a few seconds); the distance checks alone cannot tell
                  mirror-image markers apart.

    Returns the findings, most serious first; an empty tuple when nothing is wrong.
    """
    exp = expectations if expectations is not None else model_expectations(model, protocol, ranges_rad)
    if exp.model is not model:
        raise InputError("check_trial: expectations were computed for another model")
    if exp.names != protocol.marker_names:
        raise InputError("check_trial: expectations were computed for another protocol")
    names = exp.names
    segs = exp.segments
    pos = in_protocol_order(trial, marker_names, protocol)
    pd = pair_distances(pos, names)
    d = pd.median_m
    ref = reference_matrix(reference, names)
    ref_name = (reference.source if reference is not None else "") or "the reference"
    k = len(names)
    findings: list[LabelFinding] = []

    # -- other subject: the reference disagrees on many markers of several segments
    other_subject = False
    bad_rigid = rigid_bad(d, ref, exp.rigid)
    if bad_rigid.any():
        # what a few swaps (greedy, up to MAX_SWAPS) do not explain must be covered by few markers
        dd, left = d, bad_rigid
        for _ in range(MAX_SWAPS):
            trials = [(int(rigid_bad(permuted(dd, i, j), ref, exp.rigid).sum()), i, j)
                      for i, j in itertools.combinations(range(k), 2)]
            n_bad, i, j = min(trials)
            if n_bad >= int(left.sum()):
                break
            dd = permuted(dd, i, j)
            left = rigid_bad(dd, ref, exp.rigid)
        cover = _cover(exp.rigid[left]) if left.any() else []
        if len(cover) >= OTHER_SUBJECT_MIN_MARKERS and len({segs[m] for m in cover}) >= OTHER_SUBJECT_MIN_SEGMENTS:
            other_subject = True
            pairs = exp.rigid[bad_rigid]
            diffs = np.abs(d[pairs[:, 0], pairs[:, 1]] - ref[pairs[:, 0], pairs[:, 1]])
            worst = "; ".join(
                f"{names[pairs[o, 0]]}-{names[pairs[o, 1]]} {mm_text(d[pairs[o, 0], pairs[o, 1]])} vs "
                f"{mm_text(ref[pairs[o, 0], pairs[o, 1]])}" for o in np.argsort(-diffs)[:3])
            seg_list = sorted({segs[m] for p in pairs for m in p})
            n_ref = int(np.isfinite(ref[exp.rigid[:, 0], exp.rigid[:, 1]]).sum())
            findings.append(_finding(
                "other_subject", tuple(sorted({names[m] for m in cover})),
                f"{int(bad_rigid.sum())} of {n_ref} rigid distances differ from {ref_name} by more than "
                f"{mm_text(RIGID_TOLERANCE_M)} on {len(seg_list)} segments ({', '.join(seg_list)}), e.g. {worst}; "
                f"no swap of labels explains them: the reference looks like another subject (or another "
                f"marker placement)"))
    if other_subject:
        ref = None
        bad_rigid = np.zeros(len(exp.rigid), dtype=bool)

    # -- swaps: greedy, best supported first; each accepted swap is undone before the next search,
    #    and the chains are fitted again (with the swaps undone) when one was accepted
    present = pd.n_frames.diagonal() > 0
    candidates = [sw for sw in itertools.combinations(range(k), 2) if present[sw[0]] and present[sw[1]]]
    perm = np.arange(k)
    used: set[int] = set()
    done: list[tuple[int, int]] = []  # accepted exchanges, in order (a marker may take part in two: a cycle)
    swaps: list[tuple[tuple[int, int], str]] = []
    n_found = -1
    while len(done) < MAX_SWAPS and n_found != len(done):
        n_found = len(done)
        chains = chain_scores(exp, pos if (perm == np.arange(k)).all() else pos[:, perm]) if chain_fits else {}
        stale: set[str] = set()  # chains fitted before a swap accepted in this pass
        while len(done) < MAX_SWAPS:
            dcur = d[np.ix_(perm, perm)]
            viol = violated(dcur, exp.relations)
            bad = rigid_bad(dcur, ref, exp.rigid)
            best = None
            for sw in candidates:
                if sw in done or (sw[0] in used and sw[1] in used):
                    continue  # an exchange once; a marker already exchanged may join one more marker (a cycle)
                ok, reasons, score = swap_support(exp, dcur, ref, ref_name, viol, bad, chains, stale, sw)
                if ok and (best is None or score > best[0]):
                    best = (score, sw, reasons)
            if best is None:
                break
            _, (i, j), reasons = best
            stale |= {c.root for c in exp.chains if i in c.markers or j in c.markers}
            used |= {i, j}
            done.append((i, j))
            facts = swap_facts(exp, dcur, ref, i, j)
            perm[[i, j]] = perm[[j, i]]
            swaps.append(((i, j), f"{names[i]} and {names[j]} look swapped: {facts}; swapping them: " + "; ".join(reasons)))
    findings += _permutation_findings(exp, pos, perm, swaps, chain_fits)
    d = d[np.ix_(perm, perm)]  # the remaining checks see the labels with the swaps undone
    spread = pd.spread_m[np.ix_(perm, perm)]

    # -- what no swap explains: reversed relations, rigid distances, spreads
    left = violated(d, exp.relations)
    if left.any():
        rel = exp.relations
        for m in _cover(rel[left]):
            rs = [r for r in np.flatnonzero(left) if m in rel[r]]
            total = int(np.any(rel == m, axis=1).sum())
            if m in used or len(rs) < RELATION_MIN_FIXED or len(rs) < RELATION_SWAP_SHARE * total:
                continue  # a few reversed relations: a marker placed unlike the model, not a label
            others = [n for n in range(k) if n != m and np.isfinite(d[m, n])]
            nearest = min(others, key=lambda n: d[m, n]) if others else m
            model_nearest = min((n for n in range(k) if n != m), key=lambda n: exp.model_median_m[m, n])
            wrong_seg = segs[nearest] != segs[m] and segs[model_nearest] == segs[m]
            r = rs[int(np.argmax(exp.min_ratio[rs]))]
            a_, x, y = rel[r]
            where = (f"; it is nearest {names[nearest]} ({mm_text(d[m, nearest])}), a marker of the {segs[nearest]}, "
                     f"not of its {segs[m]}" if wrong_seg else "")
            findings.append(_finding("wrong_segment" if wrong_seg else "side", (names[m],), (
                f"{names[a_]} is {mm_text(d[a_, x])} from {names[x]} and {mm_text(d[a_, y])} from {names[y]}; the model "
                f"puts {names[a_]} nearer {names[x]} (min ratio {exp.min_ratio[r]:.1f} over the joint ranges); "
                f"{len(rs)} of the {total} side relations of {names[m]} are reversed and no swap explains "
                f"them{where}")))
            used.add(m)

    bad_left = rigid_bad(d, ref, exp.rigid)
    if bad_left.any() and ref is not None:
        pairs = exp.rigid[bad_left]
        for m in _cover(pairs):
            if m in used:
                continue
            mine = [p for p in pairs if m in p]
            parts = [f"{names[o]} {mm_text(d[m, o])} (reference {mm_text(ref[m, o])})" for o in _partners(mine, m)]
            if len(mine) == 1:  # one distance: either marker may have moved
                o = int(mine[0][1] if mine[0][0] == m else mine[0][0])
                who, which = (names[m], names[o]), f"{names[m]} or {names[o]} moved, was re-placed or mislabelled"
            else:
                who, which = (names[m],), "moved, re-placed or mislabelled"
            findings.append(_finding("distance", who, (
                f"{names[m]} is at a different distance from markers that are rigid with it than in {ref_name}: "
                + ", ".join(parts) + f" (tolerance {mm_text(RIGID_TOLERANCE_M)}): {which}")))
            used.update(names.index(w) for w in who)

    sd = spread[exp.rigid[:, 0], exp.rigid[:, 1]] if len(exp.rigid) else np.zeros(0)
    jumpy = np.isfinite(sd) & (sd > RIGID_SPREAD_MAX_M)
    if pd.step_m is not None and len(exp.rigid):
        steps = pd.step_m[np.ix_(perm, perm)][exp.rigid[:, 0], exp.rigid[:, 1]]
        jumpy &= ~(steps <= RIGID_STEP_MIN_M)  # NaN (not computed): the spread alone decides
    if jumpy.any():
        pairs = exp.rigid[jumpy]
        for m in _cover(pairs):
            if m in used:
                continue
            mine = [p for p in pairs if m in p]
            parts = [f"{names[o]} (SD {mm_text(spread[m, o])}, median {mm_text(d[m, o])})" for o in _partners(mine, m)]
            findings.append(_finding("jump", (names[m],), (
                f"the distance of {names[m]} to markers that are rigid with it varies within the trial: "
                + ", ".join(parts) + f"; skin motion gives at most about {mm_text(RIGID_SPREAD_MAX_M)}: the label "
                "jumps between markers in part of the trial")))
            used.add(m)

    order = {"error": 0, "warning": 1}
    return tuple(sorted(findings, key=lambda f: order.get(f.severity, 2)))


def _permutation_findings(exp: LabelExpectations, pos: np.ndarray, perm: np.ndarray,
                          swaps: list[tuple[tuple[int, int], str]], chain_fits: bool) -> list[LabelFinding]:
    """The accepted exchanges as findings: a pair on its own is a "swap"; exchanges that share a
    marker compose a cycle (e.g. EPI_lat -> EPI_med -> DELT), reported once as a "permutation" with
    the relabel that undoes it (``LabelFinding.relabel``) and, where the chains were fitted, the
    residual before and after it."""
    names = exp.names
    groups: list[set[int]] = []
    for (i, j), _ in swaps:
        hit = [g for g in groups if i in g or j in g]
        merged = {i, j}.union(*hit) if hit else {i, j}
        groups = [g for g in groups if g not in hit] + [merged]
    out = []
    for g in groups:
        evidence = [text for (i, j), text in swaps if i in g]
        if len(g) == 2:
            (i, j), = [sw for sw, _ in swaps if sw[0] in g]
            out.append(_finding("swap", (names[i], names[j]), evidence[0]))
            continue
        members = sorted(g)
        # column perm[m] of the file holds marker m: its label names[perm[m]] is read as names[m]
        relabel = {names[int(perm[m])]: names[m] for m in members if perm[m] != m}
        text = ", ".join(f"{a} is {b}" for a, b in relabel.items())
        fit = ""
        if chain_fits:
            before, after = chain_scores(exp, pos), chain_scores(exp, pos[:, perm])
            roots = [c.root for c in exp.chains if set(members) & set(c.markers)]
            parts = [f"the {'-'.join(chain_label(exp, r))} chain {mm_text(before[r].rms_m)} -> {mm_text(after[r].rms_m)}"
                     for r in roots if r in before and r in after]
            if parts:
                fit = "; with the relabel, " + ", ".join(parts) + " RMS"
        out.append(LabelFinding("permutation", tuple(names[m] for m in members),
                                f"{len(members)} labels permuted in a cycle ({text}): found as {len(evidence)} "
                                f"exchanges that share a marker: " + " | ".join(evidence) + fit,
                                _SEVERITY["permutation"], relabel))
    return out
