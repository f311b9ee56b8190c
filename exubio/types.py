"""The data that travels between exubio's layers, as frozen dataclasses.

Conventions everywhere: numpy float64, time first, SI units (m, s, rad, kg), NaN marks a
missing marker sample (never 0). Inputs are not mutated. Millimetres and degrees appear only in
files and labels, never inside these objects.
"""
from __future__ import annotations

import copyreg
import enum
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal, Mapping

import numpy as np

from exubio.errors import InputError, ModelError
from exubio.short_repr import short_repr
from exubio.method_registry import Method  # noqa: F401 - a method's name, one of the registry's (re-exported)

# The read-only mappings inside Model and Protocol pickle as what they show, so that loaded objects
# travel to pool and Dask workers (a session's model and protocol are parsed once, not per trial).
def _read_only(mapping: dict) -> MappingProxyType:
    return MappingProxyType(mapping)


copyreg.pickle(MappingProxyType, lambda view: (_read_only, (dict(view),)))


# --------------------------------------------------------------------------------------------
# Marker trajectories
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Trajectories:
    """Marker trajectories of one trial.

    labels:      marker labels, prefixes such as ``Subject:`` already stripped.
    positions_m: (n_frames, n_markers, 3) positions in metres; NaN where a sample is missing.
    rate_hz:     sampling rate.
    time_s:      (n_frames,) sample times in seconds (first sample at 0 unless the file says).
    source:      the file it came from ("" for data made in memory).
    ignored_labels: labels present in the file but dropped (unlabelled ``*12`` markers, ...).
    units_in_file: the length unit the file declared ("mm", "m", ...).
    input_findings: what the reader found wrong in the file and read around (a header count the
                 data rows contradict, ...), one sentence each naming the field; they go into the
                 result's summary.json (``input_findings``) and its verdict reasons.
    """
    __repr__ = short_repr  # arrays as their shape: a notebook prints the object in a few lines

    labels: tuple[str, ...]
    positions_m: np.ndarray
    rate_hz: float
    time_s: np.ndarray
    source: str = ""
    ignored_labels: tuple[str, ...] = ()
    units_in_file: str = "m"
    input_findings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions_m, dtype=float)
        if pos.ndim != 3 or pos.shape[2] != 3:
            raise InputError(
                f"{self.source or 'trajectories'}: positions must have shape (n_frames, n_markers, 3), "
                f"got {pos.shape}"
            )
        if pos.shape[1] != len(self.labels):
            raise InputError(
                f"{self.source or 'trajectories'}: {len(self.labels)} labels for {pos.shape[1]} markers"
            )
        if len(set(self.labels)) != len(self.labels):
            dup = sorted({lab for lab in self.labels if self.labels.count(lab) > 1})
            raise InputError(f"{self.source or 'trajectories'}: duplicate marker labels {dup}")
        time = np.asarray(self.time_s, dtype=float)
        if time.shape != (pos.shape[0],):
            raise InputError(
                f"{self.source or 'trajectories'}: time has shape {time.shape}, expected ({pos.shape[0]},)"
            )
        if not (self.rate_hz > 0 and np.isfinite(self.rate_hz)):
            raise InputError(f"{self.source or 'trajectories'}: sampling rate must be finite and > 0, got "
                             f"{self.rate_hz}")
        object.__setattr__(self, "labels", tuple(self.labels))
        object.__setattr__(self, "positions_m", pos)
        object.__setattr__(self, "time_s", time)
        object.__setattr__(self, "ignored_labels", tuple(self.ignored_labels))
        object.__setattr__(self, "input_findings", tuple(self.input_findings))

    @property
    def n_frames(self) -> int:
        return int(self.positions_m.shape[0])

    @property
    def n_markers(self) -> int:
        return int(self.positions_m.shape[1])

    def index(self, label: str) -> int:
        """Column of ``label``; an InputError naming the file and the known labels otherwise."""
        try:
            return self.labels.index(label)
        except ValueError:
            raise InputError(
                f"{self.source or 'trajectories'}: no marker '{label}'; the trial has {list(self.labels)}"
            ) from None

    def marker(self, label: str) -> np.ndarray:
        """(n_frames, 3) trajectory of one marker, in metres."""
        return self.positions_m[:, self.index(label), :]


# --------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------
class JointKind(str, enum.Enum):
    SPHERICAL = "spherical"  # three rotations about intersecting axes (an intrinsic sequence)
    REVOLUTE = "revolute"  # one rotation
    CARDAN = "cardan"  # two rotations about intersecting axes (universal joint)

    @property
    def n_coordinates(self) -> int:
        return {"spherical": 3, "revolute": 1, "cardan": 2}[self.value]


@dataclass(frozen=True)
class Joint:
    """The joint between a segment and its parent.

    centre_m: the joint centre in the parent's frame (m).
    axes:     (k, 3) unit rotation axes of the intrinsic sequence q_1, q_2, ... Each axis is
              expressed in the parent frame at q = 0, where parent and child frames coincide.
    coordinates: the names of the k joint coordinates, in sequence order.
    ranges_rad: (k, 2) range of motion [lower, upper] of each coordinate (rad); -inf/+inf where
              the model gives none.
    axes_frame: where the axes came from: "isb" = the axes of the child segment's ISB frame (Wu et
              al. 2005) in the reference posture; None = given directly in the thorax frame.
    """

    name: str
    kind: JointKind
    coordinates: tuple[str, ...]
    axes: np.ndarray
    centre_m: np.ndarray
    ranges_rad: np.ndarray | None = None
    axes_frame: str | None = None

    def __post_init__(self) -> None:
        k = len(self.coordinates)
        if self.ranges_rad is None:
            rng = np.tile([-np.inf, np.inf], (k, 1))
        else:
            rng = np.asarray(self.ranges_rad, dtype=float).reshape(k, 2)
        object.__setattr__(self, "ranges_rad", rng)


@dataclass(frozen=True)
class Segment:
    """A rigid segment. Its frame is at its joint centre and parallel to the thorax frame in the
    model's reference posture (all coordinates zero).

    mass_kg, com_m (local), inertia_kgm2 (3x3 about the centre of mass, local axes).
    points: named local positions (m) of anatomical landmarks and default model points.
    """

    name: str
    parent: str | None
    joint: Joint | None
    mass_kg: float
    com_m: np.ndarray
    inertia_kgm2: np.ndarray
    points: Mapping[str, np.ndarray]


@dataclass(frozen=True)
class Ellipsoid:
    """The thorax ellipsoid g = (r - centre)^T A (r - centre) - 1 with A = diag(1/radii^2).

    contact_points: (segment, point name) of the two scapula points held on its surface.
    """

    centre_m: np.ndarray
    radii_m: np.ndarray
    contact_points: tuple[tuple[str, str], ...]

    @property
    def a_diag(self) -> np.ndarray:
        return 1.0 / np.asarray(self.radii_m, dtype=float) ** 2


@dataclass(frozen=True)
class Model:
    """A kinematic tree of segments (thorax fixed first, parents before children) with the
    scapulothoracic ellipsoid constraint."""
    __repr__ = short_repr  # arrays as their shape: a notebook prints the object in a few lines

    name: str
    segments: tuple[Segment, ...]
    ellipsoid: Ellipsoid
    body_mass_kg: float
    source: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = [s.name for s in self.segments]
        if len(set(names)) != len(names):
            raise ModelError(f"{self.source or self.name}: duplicate segment names in {names}")
        seen: set[str] = set()
        for seg in self.segments:
            if seg.parent is not None and seg.parent not in seen:
                raise ModelError(
                    f"{self.source or self.name}: segment '{seg.name}' names parent '{seg.parent}', "
                    f"which must be defined before it; defined so far: {sorted(seen)}"
                )
            seen.add(seg.name)
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))

    @property
    def segment_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.segments)

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        out: list[str] = []
        for seg in self.segments:
            if seg.joint is not None:
                out.extend(seg.joint.coordinates)
        return tuple(out)

    @property
    def n_coordinates(self) -> int:
        return len(self.coordinate_names)

    @property
    def coordinate_ranges_rad(self) -> np.ndarray:
        """(m, 2) range of motion [lower, upper] of every coordinate (rad; +-inf where none)."""
        rows = [seg.joint.ranges_rad for seg in self.segments if seg.joint is not None]
        return np.concatenate(rows, axis=0) if rows else np.zeros((0, 2))

    def segment(self, name: str) -> Segment:
        for seg in self.segments:
            if seg.name == name:
                return seg
        raise ModelError(
            f"{self.source or self.name}: no segment '{name}'; valid segments are {list(self.segment_names)}"
        )

    def segment_index(self, name: str) -> int:
        return self.segment_names.index(self.segment(name).name)


# --------------------------------------------------------------------------------------------
# Protocol
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MarkerSpec:
    """One protocol marker: the trial label(s) it is found under, the segment it sits on, its
    local position on that segment (m) and its spring-damper constants (the LS weight is the
    spring constant relative to the protocol default)."""

    name: str
    segment: str
    local_position_m: np.ndarray
    aliases: tuple[str, ...] = ()
    stiffness_n_per_m: float = 1500.0
    damping_ns_per_m: float = 300.0
    optional: bool = False
    landmark: str | None = None  # the bony landmark (model point of ``segment``) the marker is placed over
    cluster: str | None = None  # the rigid marker cluster it belongs to (e.g. an acromion cluster)
    landmark_offset_mm: float | None = None  # a lab's placement, accepted once: the landmark distance allowed
    point: str | None = None  # the model point its protocol file names (``point:``), None when given by position


@dataclass(frozen=True)
class ThoraxFrameSpec:
    """How the ISB thorax frame is built: from the trial labels of IJ, PX, C7 and T8; or from IJ and
    the two midpoints IJ-C7 and PX-T8 (which define the same frame); or, with no labels, the data
    are already expressed in a thorax-fixed frame (identity)."""

    ij: str | None = None
    px: str | None = None
    c7: str | None = None
    t8: str | None = None
    ij_c7_midpoint: str | None = None
    px_t8_midpoint: str | None = None

    @property
    def is_identity(self) -> bool:
        return self.ij is None

    @property
    def keys(self) -> tuple[str, ...]:
        """The landmark keys this frame is built from (empty for identity)."""
        if self.is_identity:
            return ()
        if self.ij_c7_midpoint is not None:
            return ("ij", "ij_c7_midpoint", "px_t8_midpoint")
        return ("ij", "px", "c7", "t8")


@dataclass(frozen=True)
class Protocol:
    """A marker set: tracked markers, the thorax frame landmarks and the filter settings.

    cutoff_hz: the low-pass cut-off of the marker trajectories (Hz); ``"auto"``: chosen per marker
    and trial by Winter's residual analysis (:func:`exubio.prep.targets.residual_cutoffs`; the
    cut-offs applied are in ``MarkerTargets.cutoff_hz``); None: no filter.
    filter_order: order of the Butterworth design (run forward and backward).
    """
    __repr__ = short_repr  # arrays as their shape: a notebook prints the object in a few lines

    name: str
    markers: tuple[MarkerSpec, ...]
    thorax_frame: ThoraxFrameSpec
    cutoff_hz: float | Literal["auto"] | None = 2.0
    filter_order: int = 2
    default_stiffness_n_per_m: float = 1500.0
    default_damping_ns_per_m: float = 300.0
    source: str = ""
    held_coordinates: tuple[str, ...] = ()  # not observable with this marker set: held at 0
    relabel: Mapping[str, str] = field(default_factory=dict)  # trial label -> label it is read as
    side: Literal["right", "left"] = "right"  # left: markers mirrored onto the (right-arm) model
    thorax_aliases: Mapping[str, tuple[str, ...]] = field(default_factory=dict)  # thorax_frame label -> other labels
    other_arm: str | None = None  # the protocol file of the other arm of this marker set (--both-arms)
    analog_loads: tuple = ()  # exubio.protocol.analog_loads.AnalogLoadSpec: loads from a C3D's analog channels
    pf_inertia_scale: float | None = None  # defaults.pf_inertia_scale: PF's inertia scale (None: PF's default)
    signs: Literal["isb", "clinical"] = "isb"  # sign convention of the written angles (exubio.model.signs)
    uncertainty_model: str | None = None  # a lab's STA amplitude model (JSON, absolute path); None: the shipped one
    files: tuple[str, ...] = ()  # the files it was read from: its own first, then those of its extends chain giving keys

    @property
    def marker_names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.markers)

    @property
    def weights(self) -> np.ndarray:
        """LS weight per marker: its spring constant relative to the protocol default."""
        return np.array([m.stiffness_n_per_m for m in self.markers]) / self.default_stiffness_n_per_m


# --------------------------------------------------------------------------------------------
# Preprocessed input and results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Gap:
    """A run of missing samples of one marker: frames [start, stop)."""

    marker: str
    start: int
    stop: int

    @property
    def n_frames(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class MarkerTargets:
    """Protocol markers in the thorax frame, filtered, with spline derivatives, ready for a method.

    positions_m, velocities_m_s, accelerations_m_s2: (n_frames, n_markers, 3), NaN in gaps.
    marker_names: protocol marker names, in protocol order.
    cutoff_hz:    marker name -> low-pass cut-off actually applied (Hz), in protocol order; only
                  markers of which at least one run of samples was filtered (empty: unfiltered).
    """
    __repr__ = short_repr  # arrays as their shape: a notebook prints the object in a few lines

    time_s: np.ndarray
    marker_names: tuple[str, ...]
    positions_m: np.ndarray
    velocities_m_s: np.ndarray
    accelerations_m_s2: np.ndarray
    gaps: tuple[Gap, ...] = ()
    source: str = ""
    cutoff_hz: Mapping[str, float] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.positions_m.shape[0])

    @property
    def present(self) -> np.ndarray:
        """(n_frames, n_markers) True where the marker was measured."""
        return ~np.isnan(self.positions_m).any(axis=2)


class _Word(str, enum.Enum):
    """A string enum that prints and formats as its value ("ok", not "Verdict.OK"), as the files
    and the console write it."""

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)


class Verdict(_Word):
    """A result's verdict: ok (believe it), check (look at the reasons first), fail (do not use it)."""

    OK = "ok"
    CHECK = "check"
    FAIL = "fail"


class Severity(_Word):
    """How much a reason weighs: a note leaves the verdict as it is, a check makes it 'check' at
    least, a fail makes it 'fail' (ordered as declared: NOTE < CHECK < FAIL)."""

    NOTE = "note"
    CHECK = "check"
    FAIL = "fail"

    @property
    def rank(self) -> int:
        return tuple(Severity).index(self)


class StopReason(enum.IntEnum):
    """Why one problem's iteration stopped (stored as int8 codes in result arrays)."""

    CONVERGED = 0  # a kept step whose largest component is at most the step tolerance
    STALLED = 1  # a kept step that no longer lowers the merit (relative decrease <= stall_rtol): a flat
    # valley, the objective does not care where along it the solution lies; accepted as converged
    MAX_ITERATIONS = 2  # still iterating after max_iterations
    DAMPING_EXHAUSTED = 3  # the damping grew beyond its cap: no step along the gradient lowers the merit
    # (a wrong gradient; or, with an acceptance test without slack, a minimum whose rounding-level
    # steps raise the cost by an ulp)
    NOT_FINITE = 4  # the cost or the step at the current point is NaN (stops at once), or the
    # problem ran out of iterations or damping at a point whose cost or constraints are not finite

    @property
    def label(self) -> str:
        """Lower-case name, as in reports: 'converged', 'max_iterations', ..."""
        return self.name.lower()

    @property
    def converged(self) -> bool:
        """True for CONVERGED and STALLED: the iterate is a solution."""
        return self <= StopReason.STALLED


class FrameStatus(enum.IntEnum):
    CONVERGED = 0
    NOT_CONVERGED = 1
    TOO_FEW_MARKERS = 2


@dataclass(frozen=True)
class Reconstruction:
    """Joint kinematics of one trial by one method.

    q_rad, qd_rad_s, qdd_rad_s2: (n_frames, n_coordinates).
    model_points_m: (n_frames, n_markers, 3) model points R_i at the reconstructed q; None in a
                    reconstruction streamed to its result files (exubio.io.streamed): they are
                    in its .npz.
    measured_m:     (n_frames, n_markers, 3) the targets the method tracked (NaN in gaps); None when
                    read from a result file without its points (exubio.io.results.read_npz).
    residuals_m:    (n_frames, n_markers) |R_i - M_i|, NaN where the marker was missing.
    constraint:     (n_frames, 2) ellipsoid constraint g (dimensionless).
    constraint_velocity: (n_frames, 2) G q̇ (1/s).
    status:         (n_frames,) FrameStatus values.
    timings_s:      named wall times (build, initial, solve, ... total).
    info:           method-specific figures (iterations, mean spring deflection, ...).
    quality:        the verdict and its reasons, once the trial is assessed (``verdict``).
    resumed_from:   the summary.json it was read back from when a re-run kept an earlier run's
                    complete result set of the same inputs (exubio.run.resume), else None.
    """
    __repr__ = short_repr  # arrays as their shape: a notebook prints the object in a few lines

    method: str
    time_s: np.ndarray
    coordinate_names: tuple[str, ...]
    q_rad: np.ndarray
    qd_rad_s: np.ndarray
    qdd_rad_s2: np.ndarray
    marker_names: tuple[str, ...]
    model_points_m: np.ndarray | None
    measured_m: np.ndarray | None
    residuals_m: np.ndarray
    constraint: np.ndarray
    constraint_velocity: np.ndarray
    status: np.ndarray
    timings_s: Mapping[str, float] = field(default_factory=dict)
    info: Mapping[str, Any] = field(default_factory=dict)
    gaps: tuple[Gap, ...] = ()
    quality: Any = None  # once assessed (exubio.reconstruct): its verdict and reasons, exubio.trust.quality.Quality
    resumed_from: str | None = None  # read back from this summary.json: kept from an earlier run (exubio.run.resume)

    @property
    def n_frames(self) -> int:
        return int(self.q_rad.shape[0])

    @property
    def verdict(self) -> str | None:
        """"ok", "check" or "fail" once assessed (the CLI's verdict for the same trial), else None."""
        return None if self.quality is None else self.quality.verdict
