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

The thresholds are the constants below; each says why it has its value. Positions are metres
inside; millimetres appear only in the evidence sentences.
"""
from __future__ import annotations

import dataclasses
import enum
import hashlib
import itertools
from collections import OrderedDict
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import Kinematics, PointSet
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
# -- the posture sample
N_POSTURES = 3000
"""Postures sampled uniformly within the coordinate ranges to derive the side relations and the
rigid pairs. Another seed changes 1-2 % of the kept relations (3-8 of about 350, measured), four
times as many postures drop 5 of them (relations whose worst posture 3000 samples miss); no
finding on the C3D trials changes."""

POSTURE_SEED = 20240601
"""Fixed seed of the posture sample: the same model and ranges always give the same relations."""

# -- side relations
SIDE_RATIO_MIN = 1.3
"""A side relation "A is nearer X than Y" is kept only if |A-Y| >= 1.3 |A-X| in every sampled
posture. Adult segment lengths vary by about +-10-15 % between subjects, and not in proportion
along different directions: a 30 % margin survives that, so a correctly labelled subject does not
reverse a kept relation (a trial reverses it when its medians give |A-X| > |A-Y|)."""

MODEL_POINT_TOLERANCE_M = 0.020
"""How far a subject's marker may sit from the model's point for it: skin markers are placed by
palpation within about 10 mm of their landmark, and a generic model puts its points within about
10 mm of the landmark plus skin and marker radius. Markers placed away from landmarks (technical
markers of the upper arm and the scapula) can be much further off; the few relations they break
are not taken for a labelling error (see RELATION_MIN_EXPECTED)."""

SIDE_GAP_MIN_M = 4 * MODEL_POINT_TOLERANCE_M
"""A side relation also needs |A-Y| - |A-X| >= 80 mm in every sampled posture: moving each of A, X
and Y by up to MODEL_POINT_TOLERANCE_M changes that difference by at most 4 times as much (triangle
inequality). Two markers less than 80 mm apart on the model are therefore never told apart by side
relations (the rigid pairs with a reference, and the chain fits, do that)."""

RELATION_MIN_FIXED = 3
"""A swap is supported by side relations when it restores at least 3 more than it reverses, and it
is refused when it reverses 3 or more. Swapping two markers of different segments reverses 25-100
relations; a single relation can be reversed by one marker placed unlike the model."""

RELATION_MIN_EXPECTED = 10
"""Side relations only speak (for or against) a swap of two markers on different segments that the
model itself separates by at least 10 relations (reversed when the two are exchanged in the model
at its median distances over the sampled postures). One marker that the lab places unlike the
model reverses a few relations on its own (measured: 5-7 in every correctly labelled trial, all on
the scapula and clavicle, whose technical markers the generic model places elsewhere); a swap of
two nearby girdle markers that the model separates by a handful of relations cannot be told from
that."""

RELATION_SWAP_SHARE = 0.5
"""... and the swap must restore at least half of those: a real swap restores nearly all the
relations that tell its two markers apart, a misplaced marker only a few."""

# -- rigid pairs
RIGID_MODEL_VARIATION_M = 0.005
"""A pair of markers on different segments counts as rigid when its model distance varies by less
than 5 mm over the sampled postures (a marker on a joint axis: the epicondyles and the points of
the ulna). 5 mm is well below the skin-motion tolerance, so treating such a pair as rigid adds no
false finding."""

RIGID_TOLERANCE_M = 0.025
"""A rigid pair's median distance may differ from the reference by up to 25 mm. Skin markers over
the scapula and the humerus move 10-30 mm relative to the bone (most for the scapula at high arm
elevation and for humeral markers in axial rotation), and both markers of a pair move; a median
over a trial carries about half of that peak. Measured: up to 10 mm between a trial and its
session's static (7 mm martin, 10 mm kinova_martin: MET2-MET5 and CLAV_SC-CLAV_AC), up to 21 mm
between two sessions of one subject (markers re-placed); a swapped or misplaced marker changes
rigid distances by 40-300 mm."""

RIGID_SPREAD_MAX_M = 0.020
"""Within one trial, a standard deviation of a rigid pair's distance above 20 mm flags a label that
jumps between markers. Skin motion of 10-30 mm peak to peak gives at most about 11 mm (measured:
6.6 mm at most in the correctly labelled trials; 11.3 mm for an epicondyle and the ULNA label of
the kinova_martin trials, which sits on the radial styloid and so turns with pronation); a label
that sits on a marker of another segment for 5 % of the frames or more, the distance jumping by
100 mm or more, gives at least 100 sqrt(0.05 x 0.95) = 22 mm."""

# -- chain fits
CHAIN_FRAMES = 5
"""Chain fits use 5 frames spread evenly over the frames where the chain's markers are all
present: a swap shows in every frame; 5 average over postures and keep the fits cheap."""

CHAIN_STARTS = 8
"""Starts of the fit with the labels as given: the middle of the ranges and 7 random postures
within them (fixed seed); the root's placement is solved from each (Kabsch). Mirror-like
configurations have local minima (e.g. near 180 deg of pronation), so one start is not enough."""

CHAIN_SWAP_STARTS = 4
"""Starts of the fits with two labels exchanged: the fit with the labels as given (right for every
other marker), the middle of the ranges and 2 of the random postures."""

CHAIN_ITERATIONS = 60
"""Levenberg-Marquardt iterations at most (a fit stops earlier when every start has converged);
measured: 30 iterations already give the RMS residuals within 0.05 mm of 200."""

CHAIN_GOOD_RMS_M = 0.020
"""A chain fits when its RMS marker residual is at most 20 mm, the level of a correctly labelled
chain on a generic model: skin motion up to 10 mm, proportions and joint offsets of a generic
adult (measured: 11-14 mm on the forearm-and-hand chain). A swap is supported by a chain fit only
if the chain then fits; a chain that fits as given refuses a swap that makes it not fit. A chain
whose markers the model places poorly fits worse than that whatever the labels, so it neither
supports nor refuses anything."""

CHAIN_SWAP_RATIO = 0.6
"""... and only if the swap brings the chain's RMS residual to 60 % of its value with the labels as
given, or less: a swapped pair adds about the distance between the two markers (40-80 mm) to two
residuals (measured: 34-36 mm -> 13-14 mm for the kinova_martin forearm and hand)."""

CHAIN_MIN_GAIN_M = 0.010
"""... and by at least 10 mm: a small residual can halve by chance."""

CHAIN_RELIEF = 1.5
"""A swap is tried in a chain that does not fit only if undoing it could make the chain fit: the
RMS residual of the other markers, divided by 1.5, must be at most CHAIN_GOOD_RMS_M. Undoing a
swap also relieves the other markers (the fit no longer bends to the two wrong ones), by a factor
of 1.2 on the kinova_martin forearm and hand (21 -> 17 mm); 1.5 leaves a margin. With a generic
model this skips the girdle chains, whose technical markers the model places 50-120 mm from where
this lab puts them, and most of the fitting time."""

CHAIN_MAX_TRIES = 15
"""... and at most the 15 pairs with the lowest such bound per chain (every pair of a chain of up
to 6 markers, such as the forearm and hand): the fit may blame the wrong markers of a mirror-image
swap (a radius-ulna swap can show as large residuals on the metacarpal markers), so in a small
chain every pair is tried; in a large one the cost grows with every pair. A swap that makes any
chain fit is then also tried in the larger chains that hold it, and the largest chain it makes
fit decides between rival swaps."""

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
# Data types
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
    relabel:  for a swap or permutation: the relabel that undoes it ({file label: read as}).
    """

    kind: str
    markers: tuple[str, ...]
    evidence: str
    severity: str
    relabel: Mapping[str, str] | None = None

    def __post_init__(self) -> None:
        if self.relabel is None and self.kind == "swap" and len(self.markers) == 2:
            a, b = self.markers
            object.__setattr__(self, "relabel", {a: b, b: a})

    def to_dict(self) -> dict:
        out = {"kind": self.kind, "markers": list(self.markers), "evidence": self.evidence, "severity": self.severity}
        if self.relabel:
            out["relabel"] = dict(self.relabel)
        return out


@dataclass(frozen=True)
class PairDistances:
    """Median distance of every pair of markers over a trial.

    names:     marker names (rows and columns).
    median_m:  (k, k) median over the frames where both are present (NaN: never together).
    spread_m:  (k, k) standard deviation over those frames.
    n_frames:  (k, k) number of those frames.
    source:    the trial (or model) they come from.
    """

    names: tuple[str, ...]
    median_m: np.ndarray
    spread_m: np.ndarray
    n_frames: np.ndarray
    source: str = ""

    def get(self, a: str, b: str) -> float:
        """Median distance (m) of markers a and b; NaN if either is unknown or never seen."""
        if a not in self.names or b not in self.names:
            return float("nan")
        return float(self.median_m[self.names.index(a), self.names.index(b)])


@dataclass(frozen=True)
class SideRelation:
    """The model puts ``marker`` nearer ``nearer`` than ``farther`` in every sampled posture, by a
    ratio of at least ``min_ratio`` (|marker-farther| / |marker-nearer|)."""

    marker: str
    nearer: str
    farther: str
    min_ratio: float


@dataclass(frozen=True)
class ChainDef:
    """A kinematic chain fitted with its root free: the root segment, the model coordinates of the
    joints below it and the protocol markers on its segments (indices into the protocol order)."""

    root: str
    segments: tuple[str, ...]
    coordinates: np.ndarray
    markers: np.ndarray


@dataclass(frozen=True)
class LabelExpectations:
    """What the model and the protocol say about a trial's markers (see :func:`model_expectations`).

    relations: (r, 3) int indices (A, X, Y) into ``names``: A nearer X than Y; ``min_ratio`` (r,).
    rigid:     (p, 2) int indices of rigid pairs; ``rigid_model_m`` (p,) their model distance.
    model_median_m: (k, k) median model distance of every pair over the sampled postures.
    chains:    the chains to fit.
    """

    names: tuple[str, ...]
    segments: tuple[str, ...]
    relations: np.ndarray
    min_ratio: np.ndarray
    rigid: np.ndarray
    rigid_model_m: np.ndarray
    model_median_m: np.ndarray
    chains: tuple[ChainDef, ...]
    ranges_rad: np.ndarray
    model: Model
    protocol: Protocol

    @property
    def side_relations(self) -> tuple[SideRelation, ...]:
        n = self.names
        return tuple(SideRelation(n[a], n[x], n[y], float(r)) for (a, x, y), r in zip(self.relations, self.min_ratio))


# --------------------------------------------------------------------------------------------
# Distances
# --------------------------------------------------------------------------------------------
def _as_positions(positions_m: np.ndarray, names: Sequence[str]) -> np.ndarray:
    pos = np.asarray(positions_m, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3 or pos.shape[1] != len(names):
        raise InputError(f"positions must have shape (n_frames, {len(names)}, 3), got {pos.shape}")
    if len(set(names)) != len(names):
        raise InputError(f"duplicate marker names in {list(names)}")
    bad = ~np.isfinite(pos).all(axis=2)  # a sample with a non-finite coordinate is missing: all NaN
    if (bad & ~np.isnan(pos).all(axis=2)).any():  # copied only when that changes something (long trials)
        pos = pos.copy()
        pos[bad] = np.nan
    return pos


PAIR_BLOCK_VALUES = 2_000_000
"""pair_distances takes the distances of this many values' worth of marker pairs at a time (16 MB,
~50 MB of working copies; a 25 s trial at 200 Hz: 133 of the 231 pairs of 22 markers at once, a
20-minute one: 2)."""


def pair_distances(positions_m: np.ndarray, names: Sequence[str], /, *, source: str = "") -> PairDistances:
    """Median and standard deviation of every pairwise marker distance over the frames of
    ``positions_m`` (n_frames, k, 3) where both markers are present (NaN = gap)."""
    names = tuple(names)
    pos = _as_positions(positions_m, names)
    k = len(names)
    med = np.full((k, k), np.nan)
    sd = np.full((k, k), np.nan)
    cnt = np.zeros((k, k), dtype=int)
    # each pair once (|A-B| and |B-A| are the same numbers, (a - b)^2 = (b - a)^2 exactly), all
    # pairs in one array: the median and SD of every column are those of the pair's own series
    iu_all, ju_all = np.triu_indices(k, 1)
    cnt[np.arange(k), np.arange(k)] = np.isfinite(pos).all(axis=2).sum(axis=0)
    per = max(PAIR_BLOCK_VALUES // max(3 * pos.shape[0], 1), 1)  # pairs at a time: bounded memory on long trials
    for a in range(0, len(iu_all), per):
        iu, ju = iu_all[a:a + per], ju_all[a:a + per]
        d = np.linalg.norm(pos[:, iu, :] - pos[:, ju, :], axis=2)  # (n, pairs of the block)
        c = np.isfinite(d).sum(axis=0)
        cnt[iu, ju] = cnt[ju, iu] = c
        seen = c > 0
        if seen.any():
            # d[:, seen] is laid out column by column (as the rows of partners were): numpy sums each
            # column as one contiguous series, whatever the number of columns (bit-identical results)
            dm = d[:, seen]
            clean = bool(np.isfinite(dm).all())
            m = np.median(dm, axis=0) if clean else np.nanmedian(dm, axis=0)
            v = np.std(dm, axis=0) if clean else np.nanstd(dm, axis=0)
            med[iu[seen], ju[seen]] = med[ju[seen], iu[seen]] = m
            sd[iu[seen], ju[seen]] = sd[ju[seen], iu[seen]] = v
    np.fill_diagonal(med, 0.0)
    np.fill_diagonal(sd, 0.0)
    return PairDistances(names=names, median_m=med, spread_m=sd, n_frames=cnt, source=source)


def model_pair_distances(model: Model, protocol: Protocol, /) -> PairDistances:
    """Distances between the protocol markers that lie on the same segment, from their local
    positions (m): a reference for the rigid-pair check when no static trial is at hand. Pairs on
    different segments are NaN (they depend on the posture). Meant for a calibrated model, whose
    marker points are where the subject's markers are."""
    names = protocol.marker_names
    k = len(names)
    med = np.full((k, k), np.nan)
    for i, j in itertools.product(range(k), repeat=2):
        mi, mj = protocol.markers[i], protocol.markers[j]
        if mi.segment == mj.segment:
            med[i, j] = float(np.linalg.norm(mi.local_position_m - mj.local_position_m))
    seen = np.isfinite(med)
    return PairDistances(names=names, median_m=med, spread_m=np.where(seen, 0.0, np.nan),
                         n_frames=seen.astype(int), source=model.source or model.name)


# --------------------------------------------------------------------------------------------
# What the model says
# --------------------------------------------------------------------------------------------
def _ranges_of(model: Model, ranges_rad: np.ndarray | None) -> np.ndarray:
    if ranges_rad is not None:
        return np.asarray(ranges_rad, dtype=float)
    rng = getattr(model, "coordinate_ranges_rad", None)
    if rng is None:
        raise InputError(f"model '{model.name}' gives no coordinate ranges; pass ranges_rad (m, 2)")
    return np.asarray(rng, dtype=float)


def _finite_ranges(ranges_rad: np.ndarray, n: int) -> np.ndarray:
    rng = np.asarray(ranges_rad, dtype=float)
    if rng.shape != (n, 2):
        raise InputError(f"ranges_rad must have shape ({n}, 2) (one [lower, upper] per model coordinate), got {rng.shape}")
    if np.isnan(rng).any() or np.any(rng[:, 0] > rng[:, 1]):
        raise InputError(f"ranges_rad must be [lower, upper] with lower <= upper, got {rng.tolist()}")
    out = rng.copy()
    out[:, 0] = np.where(np.isfinite(out[:, 0]), out[:, 0], -np.pi)  # unbounded: any angle
    out[:, 1] = np.where(np.isfinite(out[:, 1]), out[:, 1], np.pi)
    return out


def sample_postures(ranges_rad: np.ndarray, n: int = N_POSTURES, /, *, seed: int = POSTURE_SEED) -> np.ndarray:
    """(n, m) postures drawn uniformly and independently within each coordinate's [lower, upper]
    (an unbounded side counts as +-pi: any angle)."""
    rng_ = np.asarray(ranges_rad, dtype=float)
    fin = _finite_ranges(rng_, rng_.shape[0] if rng_.ndim == 2 else -1)
    gen = np.random.default_rng(seed)
    return fin[:, 0] + (fin[:, 1] - fin[:, 0]) * gen.random((n, fin.shape[0]))


def _marker_points(kin: Kinematics, protocol: Protocol) -> PointSet:
    return kin.point_set([(m.segment, m.local_position_m) for m in protocol.markers])


def _subtree(model: Model, root: str) -> tuple[str, ...]:
    out = [root]
    for seg in model.segments:
        if seg.parent in out:
            out.append(seg.name)
    return tuple(out)


def model_expectations(model: Model, protocol: Protocol, ranges_rad: np.ndarray | None = None, /, *,
                       n_postures: int = N_POSTURES, seed: int = POSTURE_SEED) -> LabelExpectations:
    """Side relations, rigid pairs and chains of ``protocol`` on ``model`` (see the module
    docstring), from ``n_postures`` postures sampled within ``ranges_rad`` (m, 2) (default: the
    model's coordinate ranges). ``protocol`` must be bound to ``model`` (its markers' local
    positions are the model's points)."""
    ranges_rad = _ranges_of(model, ranges_rad)
    kin = Kinematics(model)
    fin = _finite_ranges(ranges_rad, model.n_coordinates)
    names = protocol.marker_names
    segs = tuple(m.segment for m in protocol.markers)
    k = len(names)
    q = sample_postures(fin, n_postures, seed=seed)
    pts = kin.points(q, _marker_points(kin, protocol))  # (n, k, 3)

    rel, ratios = [], []
    dmin = np.full((k, k), np.inf)
    dmax = np.zeros((k, k))
    dmed = np.zeros((k, k))
    for a in range(k):
        d = np.linalg.norm(pts - pts[:, a:a + 1, :], axis=2)  # (n, k): |A - j|
        dmin[a] = d.min(axis=0)
        dmed[a] = np.median(d, axis=0)
        dmax[a] = d.max(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = (d[:, None, :] / d[:, :, None]).min(axis=0)  # r[x, y] = min |A-Y| / |A-X|
        gap = (d[:, None, :] - d[:, :, None]).min(axis=0)  # min |A-Y| - |A-X|
        r[gap < SIDE_GAP_MIN_M] = 0.0
        r[a, :] = 0.0
        r[:, a] = 0.0
        np.fill_diagonal(r, 0.0)
        for x, y in zip(*np.nonzero(r >= SIDE_RATIO_MIN)):
            rel.append((a, x, y))
            ratios.append(r[x, y])
    relations = np.array(rel, dtype=int).reshape(-1, 3)

    rigid, rigid_d = [], []
    anatomical = [m.landmark is not None for m in protocol.markers]
    fixed = dmax - dmin < RIGID_MODEL_VARIATION_M

    def axial(a: int, other_segment: str) -> bool:
        """Marker a's declared point keeps its distance to every marker of other_segment (it lies on
        the joint axis between them, as the epicondyles lie on the elbow's)."""
        return all(fixed[a, b] for b in range(k) if segs[b] == other_segment)

    for i, j in itertools.combinations(range(k), 2):
        same = segs[i] == segs[j]
        # across segments a distance is fixed when one marker lies on the joint axis; that marker's
        # declared point must then be trusted: a landmark's. A technical marker's declared point is a
        # guess of where it sits; a guess on the axis (an arm marker tied to the elbow centre) would
        # make it "rigid" with the next segment, which the real marker is not.
        across = False
        if not same and fixed[i, j]:
            on_axis = [a for a, other in ((i, segs[j]), (j, segs[i])) if axial(a, other)]
            across = any(anatomical[a] for a in on_axis) if on_axis else (anatomical[i] and anatomical[j])
        if same or across:
            rigid.append((i, j))
            rigid_d.append(0.5 * (dmax[i, j] + dmin[i, j]))

    coord_seg = np.array([model.segment_names[s] for s in kin.coordinate_segment])
    chains = []
    for seg in model.segments:
        if seg.joint is None:
            continue
        sub = _subtree(model, seg.name)
        mk = np.array([i for i in range(k) if segs[i] in sub], dtype=int)
        if len(mk) < 4 or len({segs[i] for i in mk}) < 2:
            continue
        coords = np.flatnonzero(np.isin(coord_seg, sub[1:]))
        chains.append(ChainDef(root=seg.name, segments=sub, coordinates=coords, markers=mk))
    return LabelExpectations(
        names=names, segments=segs, relations=relations, min_ratio=np.array(ratios, dtype=float),
        rigid=np.array(rigid, dtype=int).reshape(-1, 2), rigid_model_m=np.array(rigid_d, dtype=float),
        model_median_m=dmed, chains=tuple(chains), ranges_rad=np.asarray(ranges_rad, dtype=float), model=model, protocol=protocol,
    )


_EXPECTATIONS_CACHE: OrderedDict[bytes, LabelExpectations] = OrderedDict()
_EXPECTATIONS_CACHE_SIZE = 8


def _content_digest(*objs) -> bytes:
    """A digest of the content of frozen dataclasses, arrays, mappings, sequences and plain values
    (TypeError for anything else): equal digests, equal inputs of :func:`model_expectations`."""
    h = hashlib.sha256()

    def walk(o) -> None:
        if isinstance(o, np.ndarray):
            if o.dtype.hasobject:
                raise TypeError("object array")
            h.update(b"A" + str(o.dtype).encode() + repr(o.shape).encode())
            h.update(np.ascontiguousarray(o).tobytes())
        elif dataclasses.is_dataclass(o) and not isinstance(o, type):
            h.update(b"D" + type(o).__module__.encode() + b"." + type(o).__qualname__.encode())
            for f in dataclasses.fields(o):
                h.update(b"F" + f.name.encode())
                walk(getattr(o, f.name))
        elif isinstance(o, enum.Enum):
            h.update(b"E" + repr(o).encode() + b"\0")
        elif isinstance(o, Mapping):
            h.update(b"M%d" % len(o))
            for key, value in o.items():
                walk(key)
                walk(value)
        elif isinstance(o, (tuple, list)):
            h.update(b"T%d" % len(o))
            for x in o:
                walk(x)
        elif o is None or isinstance(o, (bool, int, float, str, np.generic)):
            h.update(b"V" + type(o).__name__.encode() + b":" + repr(o).encode() + b"\0")
        else:
            raise TypeError(f"no content digest for {type(o).__name__}")

    for o in objs:
        walk(o)
    return h.digest()


def _expectations(model: Model, protocol: Protocol, ranges_rad: np.ndarray | None) -> LabelExpectations:
    """:func:`model_expectations` (default postures and seed), computed once per process for a
    given content of model, protocol and ranges: every trial of a study checks against the same
    generic model, loaded afresh for each. The result is the one a fresh computation gives (same
    inputs, fixed seed), bound to the objects passed; its arrays are shared and read-only."""
    try:
        key = _content_digest(model, protocol, _ranges_of(model, ranges_rad), N_POSTURES, POSTURE_SEED)
    except TypeError:
        return model_expectations(model, protocol, ranges_rad)
    exp = _EXPECTATIONS_CACHE.get(key)
    if exp is None:
        exp = model_expectations(model, protocol, ranges_rad)
        for value in (exp.relations, exp.min_ratio, exp.rigid, exp.rigid_model_m, exp.model_median_m, exp.ranges_rad,
                      *(a for c in exp.chains for a in (c.coordinates, c.markers))):
            value.setflags(write=False)
        _EXPECTATIONS_CACHE[key] = exp
        while len(_EXPECTATIONS_CACHE) > _EXPECTATIONS_CACHE_SIZE:
            _EXPECTATIONS_CACHE.popitem(last=False)
    else:
        _EXPECTATIONS_CACHE.move_to_end(key)
    return dataclasses.replace(exp, model=model, protocol=protocol)


# --------------------------------------------------------------------------------------------
# Chain fits (root free, joints within ranges)
# --------------------------------------------------------------------------------------------
def _skew(v: np.ndarray) -> np.ndarray:
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _kabsch(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (b, 3, 3) and translation t (b, 3) minimising sum w |R src + t - dst|^2."""
    ws = w / w.sum(axis=1, keepdims=True)
    cs = np.einsum("bk,bki->bi", ws, src)
    cd = np.einsum("bk,bki->bi", ws, dst)
    h = np.einsum("bk,bki,bkj->bij", ws, src - cs[:, None], dst - cd[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("bji,bkj->bik", vt, u)))
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    rot = np.einsum("bji,bj,bkj->bik", vt, fix, u)
    return rot, cd - np.einsum("bij,bj->bi", rot, cs)


class _ChainModel:
    """Positions of a chain's marker points in the root segment's frame, and their derivatives
    with respect to the chain's coordinates."""

    def __init__(self, kin: Kinematics, chain: ChainDef, points: PointSet):
        self.kin = kin
        self.chain = chain
        self.root = kin.model.segment_index(chain.root)
        self.points = PointSet(points.segment_index[chain.markers], points.local_m[chain.markers])
        self.m = kin.n_coordinates

    def local(self, qc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = np.zeros(qc.shape[:-1] + (self.m,))
        q[..., self.chain.coordinates] = qc
        fr = self.kin.frames(q)
        p = self.kin.points(q, self.points, frames=fr)
        jac = self.kin.point_jacobian(q, self.points, frames=fr, positions=p)[..., self.chain.coordinates]
        rot = fr.R[..., self.root, :, :]
        org = fr.p[..., self.root, :]
        rel = np.einsum("bji,bkj->bki", rot, p - org[:, None, :])
        jrel = np.einsum("bji,bkjc->bkic", rot, jac)
        return rel, jrel


def _fit_chain(cm: _ChainModel, targets: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares fit of the chain to each target (b, k, 3) from every start ((s, nc), or
    (b, s, nc) per target); the root's placement is solved from each start (Kabsch). Returns the
    per-marker residual (b, k) (m) and the coordinates (b, nc) of the best start. Missing target
    markers (NaN) are ignored."""
    b, k, _ = targets.shape
    starts = np.broadcast_to(starts, (b,) + starts.shape[-2:])
    s, nc = starts.shape[1:]
    tgt = np.repeat(targets, s, axis=0)  # (b*s, k, 3)
    w = np.isfinite(tgt).all(axis=2).astype(float)
    tgt = np.where(w[..., None] > 0, tgt, 0.0)
    qc = starts.reshape(b * s, nc).copy()
    rel, jrel = cm.local(qc)
    rot, t = _kabsch(rel, tgt, np.maximum(w, 1e-12))

    def residual(rot_, t_, rel_):
        return (np.einsum("bij,bkj->bki", rot_, rel_) + t_[:, None, :] - tgt) * w[..., None]

    e = residual(rot, t, rel)
    cost = (e * e).sum(axis=(1, 2))
    mu = np.full(len(qc), 1e-3)
    n_par = 6 + nc
    eye = np.eye(n_par)
    for _ in range(CHAIN_ITERATIONS):
        jw = np.empty(rel.shape[:2] + (3, n_par))
        jw[..., :3] = -np.einsum("bij,bkjl->bkil", rot, _skew(rel))
        jw[..., 3:6] = np.eye(3)
        jw[..., 6:] = np.einsum("bij,bkjc->bkic", rot, jrel)
        jw *= w[..., None, None]
        hess = np.einsum("bkip,bkiq->bpq", jw, jw)
        grad = np.einsum("bkip,bki->bp", jw, e)
        diag = np.einsum("bpp->bp", hess)
        step = -np.linalg.solve(hess + mu[:, None, None] * (eye * (diag[:, None, :] + 1e-9)), grad[..., None])[..., 0]
        big = np.abs(step).max(axis=1)
        step *= np.minimum(1.0, 0.5 / np.maximum(big, 1e-300))[:, None]
        dw = step[:, :3]
        angle = np.linalg.norm(dw, axis=1)
        axis = dw / np.maximum(angle, 1e-300)[:, None]
        rot_new = np.einsum("bij,bjk->bik", rot, _rodrigues(axis, angle))
        t_new = t + step[:, 3:6]
        qc_new = np.clip(qc + step[:, 6:], lo, hi)
        rel_new, jrel_new = cm.local(qc_new)
        e_new = residual(rot_new, t_new, rel_new)
        cost_new = (e_new * e_new).sum(axis=(1, 2))
        ok = cost_new < cost
        done = np.where(ok, cost - cost_new <= 1e-8 * cost + 1e-14, mu >= 1e6)
        rot[ok], t[ok], qc[ok], rel[ok], jrel[ok], e[ok], cost[ok] = (
            rot_new[ok], t_new[ok], qc_new[ok], rel_new[ok], jrel_new[ok], e_new[ok], cost_new[ok])
        mu = np.where(ok, np.maximum(mu / 3.0, 1e-9), np.minimum(mu * 10.0, 1e9))
        if done.all():
            break
    per = np.linalg.norm(e, axis=2).reshape(b, s, k)
    best = cost.reshape(b, s).argmin(axis=1)
    res = per[np.arange(b), best]
    return np.where(np.isfinite(targets).all(axis=2), res, np.nan), qc.reshape(b, s, nc)[np.arange(b), best]


def _rodrigues(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    k = _skew(axis)
    s = np.sin(angle)[:, None, None]
    c = np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def _chain_frames(pos: np.ndarray, markers: np.ndarray) -> np.ndarray:
    full = np.flatnonzero(np.isfinite(pos[:, markers]).all(axis=(1, 2)))
    if full.size == 0:
        return full
    pick = np.unique(np.round(np.linspace(0, full.size - 1, min(CHAIN_FRAMES, full.size))).astype(int))
    return full[pick]


@dataclass(frozen=True)
class _ChainResult:
    rms_m: float  # RMS residual with the labels as given
    residual_m: np.ndarray  # (k,) median residual per protocol marker (NaN outside the chain)
    by_swap: dict  # (i, j) -> RMS residual with labels i and j exchanged


def _chain_scores(exp: LabelExpectations, pos: np.ndarray) -> dict[str, _ChainResult]:
    """Fit every chain to a few frames with the labels as given. In a chain that does not fit
    (RMS > CHAIN_GOOD_RMS_M), fit again with the labels of two of its markers exchanged, for every
    pair whose exchange could make it fit (see CHAIN_RELIEF)."""
    model = exp.model
    kin = Kinematics(model)
    points = _marker_points(kin, exp.protocol)
    fin = _finite_ranges(exp.ranges_rad, model.n_coordinates)
    lo_all = np.asarray(exp.ranges_rad, dtype=float)[:, 0]
    hi_all = np.asarray(exp.ranges_rad, dtype=float)[:, 1]
    seen = np.isfinite(pos).all(axis=2).any(axis=0)
    prepared = []
    for chain in exp.chains:
        mk = chain.markers[seen[chain.markers]]
        if len(mk) < 4 or len({exp.segments[m] for m in mk}) < 2:
            continue
        frames = _chain_frames(pos, mk)
        if frames.size == 0:
            continue
        chain = ChainDef(chain.root, chain.segments, chain.coordinates, mk)
        gen = np.random.default_rng(POSTURE_SEED)
        flo, fhi = fin[chain.coordinates, 0], fin[chain.coordinates, 1]
        starts = np.vstack([0.5 * (flo + fhi), flo + (fhi - flo) * gen.random((CHAIN_STARTS - 1, len(flo)))])
        prepared.append((chain, frames, starts, _ChainModel(kin, chain, points)))

    def fit(item, hyps: list, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        chain, frames, _, cm = item
        targets = []
        for sw in hyps:
            perm = np.arange(pos.shape[1])
            if sw is not None:
                perm[[sw[0], sw[1]]] = perm[[sw[1], sw[0]]]
            targets.append(pos[np.ix_(frames, perm[chain.markers])])
        res, q = _fit_chain(cm, np.concatenate(targets, axis=0), lo_all[chain.coordinates],
                            hi_all[chain.coordinates], starts)
        return res.reshape(len(hyps), frames.size, len(chain.markers)), q

    given = {}
    warm = {}
    searched = []  # (chain root, swap) pairs worth fitting
    for item in prepared:
        chain = item[0]
        mk = chain.markers
        res0, q0 = fit(item, [None], item[2])
        res0 = res0[0]
        warm[chain.root] = q0  # (frames, nc): the given fit, a start for the swap hypotheses
        per_marker = np.full(pos.shape[1], np.nan)
        per_marker[mk] = np.nanmedian(res0, axis=0)
        given[chain.root] = (res0, per_marker)
        if np.sqrt(np.nanmean(res0 ** 2)) <= CHAIN_GOOD_RMS_M:
            continue  # the chain fits: nothing to search
        r2 = np.nanmean(res0 ** 2, axis=0)  # per marker, over the frames
        bounds = sorted((np.sqrt((r2.sum() - r2[x] - r2[y]) / len(mk)) / CHAIN_RELIEF, int(mk[x]), int(mk[y]))
                        for x, y in itertools.combinations(range(len(mk)), 2))
        small = len(bounds) <= CHAIN_MAX_TRIES  # a small chain: every pair (CHAIN_MAX_TRIES says why)
        searched += [(chain.root, (x, y)) for b, x, y in bounds[:CHAIN_MAX_TRIES] if small or b <= CHAIN_GOOD_RMS_M]
    def try_swaps(item, hyps: list) -> dict:
        if not hyps:
            return {}
        generic = item[2][:CHAIN_SWAP_STARTS - 1]
        per_frame = np.concatenate([warm[item[0].root][:, None, :],
                                    np.broadcast_to(generic, (len(item[1]),) + generic.shape)], axis=1)
        rms = np.sqrt(np.nanmean(fit(item, hyps, np.tile(per_frame, (len(hyps), 1, 1)))[0] ** 2, axis=(1, 2)))
        return {sw: float(r) for sw, r in zip(hyps, rms)}

    rms0 = {root: float(np.sqrt(np.nanmean(res ** 2))) for root, (res, _) in given.items()}
    by_swap: dict[str, dict] = {}
    for item in prepared:
        root = item[0].root
        by_swap[root] = try_swaps(item, sorted({tuple(sorted(sw)) for r, sw in searched if r == root}))
    # a swap that makes one chain fit is also tried in every other chain that holds both markers
    # and does not fit, so that rival swaps are compared on the same chains
    winners = {sw for root, d_ in by_swap.items() for sw, r in d_.items() if _chain_fixed(rms0[root], r)}
    for item in prepared:
        root, members = item[0].root, set(int(m) for m in item[0].markers)
        if rms0[root] <= CHAIN_GOOD_RMS_M:
            continue
        extra = sorted(sw for sw in winners if sw not in by_swap[root] and set(sw) <= members)
        by_swap[root].update(try_swaps(item, extra))
    return {root: _ChainResult(rms_m=rms0[root], residual_m=given[root][1], by_swap=by_swap[root])
            for root in given}


# --------------------------------------------------------------------------------------------
# The checks
# --------------------------------------------------------------------------------------------
def _mm(x: float) -> str:
    return f"{x * 1000:.0f} mm"


def _permuted(d: np.ndarray, i: int, j: int) -> np.ndarray:
    p = np.arange(d.shape[0])
    p[[i, j]] = p[[j, i]]
    return d[np.ix_(p, p)]


def _violated(d: np.ndarray, rel: np.ndarray) -> np.ndarray:
    a, x, y = rel.T
    dx, dy = d[a, x], d[a, y]
    return np.isfinite(dx) & np.isfinite(dy) & (dx > dy)


def _rigid_bad(d: np.ndarray, ref: np.ndarray | None, rigid: np.ndarray) -> np.ndarray:
    if ref is None or rigid.size == 0:
        return np.zeros(len(rigid), dtype=bool)
    i, j = rigid.T
    diff = np.abs(d[i, j] - ref[i, j])
    return np.isfinite(diff) & (diff > RIGID_TOLERANCE_M)


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


def _reference_matrix(reference: PairDistances | None, names: Sequence[str]) -> np.ndarray | None:
    if reference is None:
        return None
    k = len(names)
    out = np.full((k, k), np.nan)
    idx = [reference.names.index(n) if n in reference.names else -1 for n in names]
    for a, ia in enumerate(idx):
        for b, ib in enumerate(idx):
            if ia >= 0 and ib >= 0:
                out[a, b] = reference.median_m[ia, ib]
    return out


def _in_protocol_order(trial: MarkerTargets | np.ndarray, marker_names: Sequence[str] | None,
                       protocol: Protocol) -> np.ndarray:
    if isinstance(trial, MarkerTargets):
        pos, names = trial.positions_m, trial.marker_names
    else:
        if marker_names is None:
            raise InputError("check_trial: give marker_names with a positions array")
        pos, names = trial, tuple(marker_names)
    pos = _as_positions(pos, tuple(names))
    if tuple(names) == protocol.marker_names:  # already in protocol order: no copy
        return pos
    out = np.full((pos.shape[0], len(protocol.markers), 3), np.nan)
    for j, name in enumerate(protocol.marker_names):
        if name in names:
            out[:, j] = pos[:, list(names).index(name)]
    return out


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
                  across trials (``ranges_rad`` is then not used). When None they are computed,
                  once per process for a given content of model, protocol and ranges.
    chain_fits:   run the chain fits (a few seconds); the distance checks alone cannot tell
                  mirror-image markers apart.

    Returns the findings, most serious first; an empty tuple when nothing is wrong.
    """
    exp = expectations if expectations is not None else _expectations(model, protocol, ranges_rad)
    if exp.model is not model:
        raise InputError("check_trial: expectations were computed for another model")
    if exp.names != protocol.marker_names:
        raise InputError("check_trial: expectations were computed for another protocol")
    names = exp.names
    segs = exp.segments
    pos = _in_protocol_order(trial, marker_names, protocol)
    pd = pair_distances(pos, names)
    d = pd.median_m
    ref = _reference_matrix(reference, names)
    ref_name = (reference.source if reference is not None else "") or "the reference"
    k = len(names)
    findings: list[LabelFinding] = []

    # -- other subject: the reference disagrees on many markers of several segments
    other_subject = False
    bad_rigid = _rigid_bad(d, ref, exp.rigid)
    if bad_rigid.any():
        # what a few swaps (greedy, up to MAX_SWAPS) do not explain must be covered by few markers
        dd, left = d, bad_rigid
        for _ in range(MAX_SWAPS):
            trials = [(int(_rigid_bad(_permuted(dd, i, j), ref, exp.rigid).sum()), i, j)
                      for i, j in itertools.combinations(range(k), 2)]
            n_bad, i, j = min(trials)
            if n_bad >= int(left.sum()):
                break
            dd = _permuted(dd, i, j)
            left = _rigid_bad(dd, ref, exp.rigid)
        cover = _cover(exp.rigid[left]) if left.any() else []
        if len(cover) >= OTHER_SUBJECT_MIN_MARKERS and len({segs[m] for m in cover}) >= OTHER_SUBJECT_MIN_SEGMENTS:
            other_subject = True
            pairs = exp.rigid[bad_rigid]
            diffs = np.abs(d[pairs[:, 0], pairs[:, 1]] - ref[pairs[:, 0], pairs[:, 1]])
            worst = "; ".join(
                f"{names[pairs[o, 0]]}-{names[pairs[o, 1]]} {_mm(d[pairs[o, 0], pairs[o, 1]])} vs "
                f"{_mm(ref[pairs[o, 0], pairs[o, 1]])}" for o in np.argsort(-diffs)[:3])
            seg_list = sorted({segs[m] for p in pairs for m in p})
            n_ref = int(np.isfinite(ref[exp.rigid[:, 0], exp.rigid[:, 1]]).sum())
            findings.append(_finding(
                "other_subject", tuple(sorted({names[m] for m in cover})),
                f"{int(bad_rigid.sum())} of {n_ref} rigid distances differ from {ref_name} by more than "
                f"{_mm(RIGID_TOLERANCE_M)} on {len(seg_list)} segments ({', '.join(seg_list)}), e.g. {worst}; "
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
        chains = _chain_scores(exp, pos if (perm == np.arange(k)).all() else pos[:, perm]) if chain_fits else {}
        stale: set[str] = set()  # chains fitted before a swap accepted in this pass
        while len(done) < MAX_SWAPS:
            dcur = d[np.ix_(perm, perm)]
            viol = _violated(dcur, exp.relations)
            bad = _rigid_bad(dcur, ref, exp.rigid)
            best = None
            for sw in candidates:
                if sw in done or (sw[0] in used and sw[1] in used):
                    continue  # an exchange once; a marker already exchanged may join one more marker (a cycle)
                ok, reasons, score = _swap_support(exp, dcur, ref, ref_name, viol, bad, chains, stale, sw)
                if ok and (best is None or score > best[0]):
                    best = (score, sw, reasons)
            if best is None:
                break
            _, (i, j), reasons = best
            stale |= {c.root for c in exp.chains if i in c.markers or j in c.markers}
            used |= {i, j}
            done.append((i, j))
            facts = _swap_facts(exp, dcur, ref, i, j)
            perm[[i, j]] = perm[[j, i]]
            swaps.append(((i, j), f"{names[i]} and {names[j]} look swapped: {facts}; swapping them: " + "; ".join(reasons)))
    findings += _permutation_findings(exp, pos, perm, swaps, chain_fits)
    d = d[np.ix_(perm, perm)]  # the remaining checks see the labels with the swaps undone
    spread = pd.spread_m[np.ix_(perm, perm)]

    # -- what no swap explains: reversed relations, rigid distances, spreads
    left = _violated(d, exp.relations)
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
            where = (f"; it is nearest {names[nearest]} ({_mm(d[m, nearest])}), a marker of the {segs[nearest]}, "
                     f"not of its {segs[m]}" if wrong_seg else "")
            findings.append(_finding("wrong_segment" if wrong_seg else "side", (names[m],), (
                f"{names[a_]} is {_mm(d[a_, x])} from {names[x]} and {_mm(d[a_, y])} from {names[y]}; the model "
                f"puts {names[a_]} nearer {names[x]} (min ratio {exp.min_ratio[r]:.1f} over the joint ranges); "
                f"{len(rs)} of the {total} side relations of {names[m]} are reversed and no swap explains "
                f"them{where}")))
            used.add(m)

    bad_left = _rigid_bad(d, ref, exp.rigid)
    if bad_left.any() and ref is not None:
        pairs = exp.rigid[bad_left]
        for m in _cover(pairs):
            if m in used:
                continue
            mine = [p for p in pairs if m in p]
            parts = [f"{names[o]} {_mm(d[m, o])} (reference {_mm(ref[m, o])})" for o in _partners(mine, m)]
            if len(mine) == 1:  # one distance: either marker may have moved
                o = int(mine[0][1] if mine[0][0] == m else mine[0][0])
                who, which = (names[m], names[o]), f"{names[m]} or {names[o]} moved, was re-placed or mislabelled"
            else:
                who, which = (names[m],), "moved, re-placed or mislabelled"
            findings.append(_finding("distance", who, (
                f"{names[m]} is at a different distance from markers that are rigid with it than in {ref_name}: "
                + ", ".join(parts) + f" (tolerance {_mm(RIGID_TOLERANCE_M)}): {which}")))
            used.update(names.index(w) for w in who)

    sd = spread[exp.rigid[:, 0], exp.rigid[:, 1]] if len(exp.rigid) else np.zeros(0)
    jumpy = np.isfinite(sd) & (sd > RIGID_SPREAD_MAX_M)
    if jumpy.any():
        pairs = exp.rigid[jumpy]
        for m in _cover(pairs):
            if m in used:
                continue
            mine = [p for p in pairs if m in p]
            parts = [f"{names[o]} (SD {_mm(spread[m, o])}, median {_mm(d[m, o])})" for o in _partners(mine, m)]
            findings.append(_finding("jump", (names[m],), (
                f"the distance of {names[m]} to markers that are rigid with it varies within the trial: "
                + ", ".join(parts) + f"; skin motion gives at most about {_mm(RIGID_SPREAD_MAX_M)}: the label "
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
            before, after = _chain_scores(exp, pos), _chain_scores(exp, pos[:, perm])
            roots = [c.root for c in exp.chains if set(members) & set(c.markers)]
            parts = [f"the {'-'.join(_chain_label(exp, r))} chain {_mm(before[r].rms_m)} -> {_mm(after[r].rms_m)}"
                     for r in roots if r in before and r in after]
            if parts:
                fit = "; with the relabel, " + ", ".join(parts) + " RMS"
        out.append(LabelFinding("permutation", tuple(names[m] for m in members),
                                f"{len(members)} labels permuted in a cycle ({text}): found as {len(evidence)} "
                                f"exchanges that share a marker: " + " | ".join(evidence) + fit,
                                _SEVERITY["permutation"], relabel))
    return out


def _swap_support(exp: LabelExpectations, d: np.ndarray, ref: np.ndarray | None, ref_name: str,
                  viol: np.ndarray, bad: np.ndarray, chains: dict, stale: set, sw: tuple[int, int]
                  ) -> tuple[bool, list[str], float]:
    """Whether exchanging labels sw = (i, j) resolves the evidence, and why. Not supported when any
    evidence gets worse: a swap that breaks side relations, rigid distances or a chain fit."""
    i, j = sw
    names = exp.names
    reasons: list[str] = []
    score = 0.0
    dp = _permuted(d, i, j)
    expected = int(_violated(_permuted(exp.model_median_m, i, j), exp.relations).sum())
    if exp.segments[i] != exp.segments[j] and expected >= RELATION_MIN_EXPECTED:
        # (within a segment, or for markers the model barely separates, its points do not decide)
        v = _violated(dp, exp.relations)
        fixed, created = int((viol & ~v).sum()), int((v & ~viol).sum())
        if created >= RELATION_MIN_FIXED:
            return False, [], 0.0
        if fixed - created >= max(RELATION_MIN_FIXED, RELATION_SWAP_SHARE * expected):
            reasons.append(f"it restores {fixed} side relation(s) the model gives"
                           + (f" (and reverses {created})" if created else ""))
            score += fixed - created
    if ref is not None:
        b = _rigid_bad(dp, ref, exp.rigid)
        rf, rc = int((bad & ~b).sum()), int((b & ~bad).sum())
        if rc >= rf and rc:
            return False, [], 0.0
        if rf > rc:
            reasons.append(f"it brings {rf} rigid distance(s) back within {_mm(RIGID_TOLERANCE_M)} of {ref_name}")
            score += 10 * rf
    for root, ch in chains.items():
        if sw not in ch.by_swap or root in stale:
            continue
        rms0, rms1 = ch.rms_m, ch.by_swap[sw]
        if rms0 <= CHAIN_GOOD_RMS_M < rms1:  # only a chain that fits can object to a swap
            return False, [], 0.0
        if _chain_fixed(rms0, rms1):
            alt = [(o, r) for o, r in ch.by_swap.items() if o != sw and _chain_fixed(rms0, r)]
            also = ""
            if alt:
                o, r = min(alt, key=lambda t: t[1])
                also = f"; exchanging {names[o[0]]} and {names[o[1]]} instead would leave {_mm(r)}"
            reasons.append(f"the {'-'.join(_chain_label(exp, root))} chain (root free, joints within their "
                           f"ranges) then fits with an RMS residual of {_mm(rms1)} instead of {_mm(rms0)}{also}")
            # the largest chain a swap fixes decides between rival swaps (it holds the most
            # constraints), then the residual it removes there
            size = len(next(c for c in exp.chains if c.root == root).markers)
            score = max(score, 1e6 * size + 1e3 * (rms0 - rms1))
    return bool(reasons), reasons, score


def _chain_fixed(rms0: float, rms1: float) -> bool:
    return rms1 <= CHAIN_GOOD_RMS_M and rms1 <= CHAIN_SWAP_RATIO * rms0 and rms0 - rms1 >= CHAIN_MIN_GAIN_M


def _chain_label(exp: LabelExpectations, root: str) -> tuple[str, ...]:
    chain = next(c for c in exp.chains if c.root == root)
    return tuple(s for s in chain.segments if s in {exp.segments[m] for m in chain.markers})


def _swap_facts(exp: LabelExpectations, d: np.ndarray, ref: np.ndarray | None, i: int, j: int) -> str:
    """The most telling distances of a swap of i and j: the marker whose distances to i and j the
    model orders most clearly (median over the sampled postures) while the trial orders them the
    other way; else a rigid distance of i that the reference contradicts."""
    names = exp.names
    mm = exp.model_median_m
    best, best_gap = None, 0.0
    for n in range(len(names)):
        if n in (i, j) or not (np.isfinite(d[n, i]) and np.isfinite(d[n, j])):
            continue
        gap = mm[n, j] - mm[n, i]  # > 0: the model puts i nearer n
        if gap * (d[n, j] - d[n, i]) < 0 and abs(gap) > max(best_gap, MODEL_POINT_TOLERANCE_M):
            best, best_gap = n, abs(gap)
    if best is not None:
        n = best
        near, far = (i, j) if mm[n, i] < mm[n, j] else (j, i)
        return (f"{names[n]} is {_mm(d[n, near])} from {names[near]} and {_mm(d[n, far])} from {names[far]}, "
                f"the model puts {names[near]} nearer (median {_mm(mm[n, near])} vs {_mm(mm[n, far])} over "
                f"the joint ranges)")
    if ref is not None:
        for a, b in exp.rigid:
            if (a in (i, j)) != (b in (i, j)) and np.isfinite(ref[a, b]) and abs(d[a, b] - ref[a, b]) > RIGID_TOLERANCE_M:
                return f"{names[a]}-{names[b]} is {_mm(d[a, b])}, {_mm(ref[a, b])} in the reference"
    return f"{names[i]}-{names[j]} {_mm(d[i, j])}"


def _finding(kind: str, markers: tuple[str, ...], evidence: str) -> LabelFinding:
    return LabelFinding(kind=kind, markers=markers, evidence=evidence, severity=_SEVERITY[kind])


def format_findings(findings: Sequence[LabelFinding], /, *, source: str = "") -> str:
    """One line per finding (or a line saying there is none)."""
    where = f"{source}: " if source else ""
    if not findings:
        return f"{where}labels look right (no finding)"
    return "\n".join(f"{where}{f.severity} [{f.kind}] {', '.join(f.markers)}: {f.evidence}" for f in findings)
