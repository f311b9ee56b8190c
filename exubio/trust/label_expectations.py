"""What the model and the protocol say about a trial's markers (exubio.trust.labels, points 1 to 3):
the model posed in N_POSTURES postures sampled within the coordinate ranges gives the side
relations, the rigid pairs and the chains to fit; computed once per binding of a model and a
protocol and held by it (:func:`expectations_of`, exubio.protocol.bind)."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import Kinematics, PointSet
from exubio.protocol.bind import Binding
from exubio.types import Model, Protocol

__all__ = [
    "MODEL_POINT_TOLERANCE_M",
    "N_POSTURES",
    "POSTURE_SEED",
    "RIGID_MODEL_VARIATION_M",
    "SIDE_GAP_MIN_M",
    "SIDE_RATIO_MIN",
    "ChainDef",
    "LabelExpectations",
    "SideRelation",
    "expectations_of",
    "finite_ranges",
    "marker_points",
    "model_expectations",
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

# -- rigid pairs
RIGID_MODEL_VARIATION_M = 0.005
"""A pair of markers on different segments counts as rigid when its model distance varies by less
than 5 mm over the sampled postures (a marker on a joint axis: the epicondyles and the points of
the ulna). 5 mm is well below the skin-motion tolerance, so treating such a pair as rigid adds no
false finding."""


# --------------------------------------------------------------------------------------------
# Data types
# --------------------------------------------------------------------------------------------
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
# What the model says
# --------------------------------------------------------------------------------------------
def _ranges_of(model: Model, ranges_rad: np.ndarray | None) -> np.ndarray:
    if ranges_rad is not None:
        return np.asarray(ranges_rad, dtype=float)
    rng = getattr(model, "coordinate_ranges_rad", None)
    if rng is None:
        raise InputError(f"model '{model.name}' gives no coordinate ranges; pass ranges_rad (m, 2)")
    return np.asarray(rng, dtype=float)


def finite_ranges(ranges_rad: np.ndarray, n: int) -> np.ndarray:
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
    fin = finite_ranges(rng_, rng_.shape[0] if rng_.ndim == 2 else -1)
    gen = np.random.default_rng(seed)
    return fin[:, 0] + (fin[:, 1] - fin[:, 0]) * gen.random((n, fin.shape[0]))


def marker_points(kin: Kinematics, protocol: Protocol) -> PointSet:
    return kin.point_set([(m.segment, m.local_position_m) for m in protocol.markers])


def _subtree(model: Model, root: str) -> tuple[str, ...]:
    out = [root]
    for seg in model.segments:
        if seg.parent in out:
            out.append(seg.name)
    return tuple(out)


def model_expectations(model: Model, protocol: Protocol, ranges_rad: np.ndarray | None = None, /, *,
                       n_postures: int = N_POSTURES, seed: int = POSTURE_SEED,
                       kinematics: Kinematics | None = None) -> LabelExpectations:
    """Side relations, rigid pairs and chains of ``protocol`` on ``model`` (see the module
    docstring), from ``n_postures`` postures sampled within ``ranges_rad`` (m, 2) (default: the
    model's coordinate ranges). ``protocol`` must be bound to ``model`` (its markers' local
    positions are the model's points); ``kinematics``: the model's, where the caller has it."""
    ranges_rad = _ranges_of(model, ranges_rad)
    kin = kinematics if kinematics is not None else Kinematics(model)
    fin = finite_ranges(ranges_rad, model.n_coordinates)
    names = protocol.marker_names
    segs = tuple(m.segment for m in protocol.markers)
    k = len(names)
    q = sample_postures(fin, n_postures, seed=seed)
    pts = kin.points(q, marker_points(kin, protocol))  # (n, k, 3)

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


def expectations_of(binding: Binding, /) -> LabelExpectations:
    """:func:`model_expectations` of the binding's model and protocol (default postures, seed and the
    model's ranges), computed on first use and held by the binding (exubio.protocol.bind): every
    trial of a session checks against the same generic binding. Its arrays are read-only."""
    key = (__name__, "expectations")
    exp = binding.fact(key)
    return exp if exp is not None else binding.keep(key, _expectations(binding))


def _expectations(binding: Binding) -> LabelExpectations:
    exp = model_expectations(binding.model, binding.protocol, kinematics=binding.kin)
    for value in (exp.relations, exp.min_ratio, exp.rigid, exp.rigid_model_m, exp.model_median_m, exp.ranges_rad,
                  *(a for c in exp.chains for a in (c.coordinates, c.markers))):
        value.setflags(write=False)
    return exp
