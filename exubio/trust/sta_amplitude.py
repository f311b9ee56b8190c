"""The soft-tissue-artefact amplitude model behind every angle's uncertainty: per segment, the
standard deviation per unit of motion of its markers' rigid cluster rotation (rad per rad, about the
segment's ISB axes), of the cluster's translation (m per rad) and of what no rigid motion explains
(m per rad, per coordinate of each marker), with their 6 x 6 second moment per rad^2 and the
scapula's and humerus's cross moment, all per unit of the skin's driver (``skin_driver``: the humerus's
rotation from rest, as shipped; saturating beyond ``saturation_rad`` where a file sets it). Fitted
on bone-referenced trials by ``exubio.truth.sta_amplitude`` (how, and the driver of the motion,
there); the shipped coefficients are those of the S2M intracortical-pin trials
(``exubio/data/sta_amplitude_s2m.json``, with its citation).

The unseen trunk's motion (what a run that assumes the thorax still cannot see,
``exubio.truth.trunk_amplitude``) is a table against the driver (``trunk_at``; one node: a
constant, as shipped), interpolated by ``exubio.synth.driver_table.interpolate``; a file from
before carries a second moment per rad^2 (``trunk``), used where no table is.

What the model's girdle cannot follow of the bones (``exubio.truth.girdle``: the scapula's and the
humerus's ISB frames off the bones' with no skin at all, with its covariance with what the skin adds)
is a symmetric 6 x 6 per rad^2 of the driver plus an offset (``girdle``, ``girdle_offset_rad``: the
two frames' rotation vectors in their own axes, not positive definite; the error's spread grows with
theta + theta_0, theta_0 = 0 in a file from before), where the file has one.

Segments without bone data take the humerus's coefficients: the clavicle driven like the scapula by
the humerus's rotation, the ulna, radius and hand by their own joint's rotation (from their parent
segment): an assumption, said in every output's definition.

A protocol may name a lab's own model (``uncertainty_model:``, a JSON written by ``exubio
uncertainty-fit``): ``amplitude_of`` gives a run's model, that file's or the shipped one, kept on the
run's binding.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from functools import lru_cache
from typing import Any, Mapping

import numpy as np

from exubio.errors import InputError
from exubio.synth.driver_table import interpolate

__all__ = ["STAAmplitude", "load_sta_amplitude", "shipped_amplitude", "amplitude_of", "saturating", "SEGMENTS_WITH_DATA",
           "BORROWED_FROM", "SHIPPED"]

SEGMENTS_WITH_DATA = ("scapula", "humerus")
BORROWED_FROM = "humerus"
"""The segment whose coefficients a segment without bone data takes."""
SHIPPED = "sta_amplitude_s2m.json"


@dataclass(frozen=True, eq=False)
class STAAmplitude:
    """Per segment (3,) arrays: ``rotation`` rad/rad, ``translation`` m/rad, ``nonrigid`` m/rad."""

    rotation: Mapping[str, np.ndarray]
    translation: Mapping[str, np.ndarray]
    nonrigid: Mapping[str, np.ndarray]
    rigid: Mapping[str, np.ndarray] = field(default_factory=dict)  # (6, 6): rotation + translation second moment
    cross: Mapping[str, np.ndarray] = field(default_factory=dict)  # "a|b" -> (6, 6): a's rigid motion x b's
    trunk: np.ndarray | None = None  # (6, 6): the unseen trunk's rotation + IJ displacement (thorax axes) per rad^2
    trunk_source: str = ""
    source: str = ""
    citation: str = ""
    extra: Mapping[str, object] = field(default_factory=dict)
    trunk_nodes: np.ndarray | None = None  # (nt,) rad: the driver at the trunk table's nodes
    trunk_table: np.ndarray | None = None  # (nt, 6, 6): the unseen trunk's rotation + IJ displacement second moment
    girdle: np.ndarray | None = None  # (6, 6): var(g) + 2 cov(g, s) of the model's frames off the bones', per rad^2
    girdle_source: str = ""
    girdle_offset_rad: float = 0.0  # theta_0: the girdle's second moment is per rad^2 of theta + theta_0
    saturation_rad: float | None = None  # the skin's driver theta_s tanh(theta / theta_s); None: theta itself
    path: str = ""  # the file it was read from, where it is a lab's (empty: the shipped model)
    judgement: Mapping[str, Any] = field(default_factory=dict)  # exubio uncertainty-fit's one-trial-out judgement

    def judgement_line(self) -> str:
        """The one-trial-out judgement a lab's fit recorded, in one line ('' where none was)."""
        j = self.judgement
        if not j:
            return ""
        return (f"judged one trial out on {len(j.get('trials', {}))} trials: of {j.get('cells', 0)} angle cells "
                f"(trial x ST, GH, HT angle), {j.get('below_90', 0)} held the bone within +-2u in under 90 % of "
                f"their measured frames, {j.get('above_99', 0)} in over 99 %"
                + (f"; the RMS of error / u, median over the cells, {j['median_rms_error_over_u']:.2f} (about 1 where u "
                   "is the error's size)" if "median_rms_error_over_u" in j else "")
                + (f"; pooled over the trials not failed, {j.get('pooled_below_90', 0)} of {len(j['pooled'])} angles "
                   f"under 90 %, {j.get('pooled_above_99', 0)} over 99 %" if j.get("pooled") else ""))

    def skin_driver(self, theta: np.ndarray, /) -> np.ndarray:
        """The driver the skin's coefficients are per unit of: theta_s tanh(theta / theta_s) (the artefact
        grows with the humerus's rotation theta from rest and levels off beyond theta_s), or theta where
        the model has no ``saturation_rad`` (a file from before)."""
        return saturating(theta, self.saturation_rad)

    def girdle_driver(self, theta: np.ndarray, /) -> np.ndarray:
        """theta + theta_0 (rad): what ``girdle`` is per rad^2 of (exubio.truth.girdle)."""
        return np.asarray(theta, dtype=float) + self.girdle_offset_rad

    @property
    def has_trunk(self) -> bool:
        return self.trunk_table is not None or self.trunk is not None

    def trunk_at(self, theta: np.ndarray, /) -> np.ndarray:
        """(b, 6, 6): the unseen trunk's rotation vector (rad) and IJ displacement (m) second moment at
        ``theta`` (ValueError where the model has none)."""
        t = np.asarray(theta, dtype=float)
        if self.trunk_table is not None and self.trunk_nodes is not None:
            return interpolate(self.trunk_nodes, self.trunk_table, t)
        if self.trunk is None:
            raise ValueError("the STA amplitude model has no trunk motion")
        return np.asarray(self.trunk, dtype=float)[None] * (t ** 2)[:, None, None]

    def of(self, segment: str) -> tuple[np.ndarray, np.ndarray, bool]:
        """(rigid 6 x 6 second moment per rad^2 of driver, nonrigid SD per axis, from bone data) of
        ``segment``, borrowed where it has none. Without a stored second moment, the per-axis SDs
        make a diagonal one."""
        seg = segment if segment in self.rotation else (BORROWED_FROM if BORROWED_FROM in self.rotation
                                                         else next(iter(self.rotation)))
        if seg in self.rigid:
            C = np.asarray(self.rigid[seg], dtype=float)
        else:
            C = np.diag(np.r_[np.asarray(self.rotation[seg]) ** 2, np.asarray(self.translation[seg]) ** 2])
        return C, np.asarray(self.nonrigid[seg]), seg == segment

    def cross_of(self, a: str, b: str) -> np.ndarray | None:
        """(6, 6) second moment per rad^2 of driver between segment a's rigid cluster motion (rows)
        and b's (columns), both from bone data in the same frames; None where not measured."""
        if f"{a}|{b}" in self.cross:
            return np.asarray(self.cross[f"{a}|{b}"], dtype=float)
        if f"{b}|{a}" in self.cross:
            return np.asarray(self.cross[f"{b}|{a}"], dtype=float).T
        return None

    def to_json(self) -> dict:
        r = lambda d: {k: [round(float(x), 6) for x in np.asarray(v)] for k, v in d.items()}
        return {"schema": "exubio sta amplitude 1", "source": self.source,
                "units": {"rotation": "rad per rad of driver (SD per ISB axis X, Y, Z of the segment)",
                          "translation": "m per rad of driver (SD per axis)",
                          "nonrigid": "m per rad of driver (SD per coordinate of each marker)"},
                "driver": ("the humerus's rotation angle from its rest orientation (rad)" if self.saturation_rad is None
                           else "theta_s tanh(theta / theta_s), theta the humerus's rotation angle from its rest "
                                "orientation (rad), theta_s = driver_saturation_rad (the skin's coefficients are per "
                                "unit of it; the girdle's and the trunk's per rad of theta itself)"),
                **({"driver_saturation_rad": float(self.saturation_rad)} if self.saturation_rad is not None else {}),
                "rotation": r(self.rotation), "translation": r(self.translation), "nonrigid": r(self.nonrigid),
                "rigid_second_moment": {k: [[float(f"{x:.6g}") for x in row] for row in np.asarray(v)]
                                        for k, v in self.rigid.items()},
                "rigid_second_moment_units": "(rotation vector rad, translation m) x same, per rad^2 of driver",
                **({"rigid_cross_second_moment": {k: [[float(f"{x:.6g}") for x in row] for row in np.asarray(v)]
                                                  for k, v in self.cross.items()},
                    "rigid_cross_second_moment_units": "'A|B': A's (rotation vector rad, translation m) x B's, per "
                                                       "rad^2 of driver, pooled over the frames where both bones "
                                                       "are seen (the two clusters' artefacts move together)"}
                   if self.cross else {}),
                **({"trunk_second_moment": [[float(f"{x:.6g}") for x in row] for row in np.asarray(self.trunk)],
                    "trunk_second_moment_units": "the thorax's rotation vector from its start (rad, its ISB axes) and "
                                                 "IJ's displacement (m, same axes) x same, per rad^2 of driver: the "
                                                 "trunk motion a run that assumes the thorax still cannot see "
                                                 "(exubio.truth.trunk_amplitude)",
                    "trunk_source": self.trunk_source} if self.trunk is not None else {}),
                **({"trunk_table_nodes_rad": [float(f"{x:.6g}") for x in self.trunk_nodes],
                    "trunk_table": _nested(self.trunk_table),
                    "trunk_table_units": "the second moment of the thorax's rotation vector from its start (rad, its "
                                         "ISB axes) and IJ's displacement (m, same axes) x same at each node of the "
                                         "driver (rad), interpolated between them: the trunk motion a run that assumes "
                                         "the thorax still cannot see (exubio.truth.trunk_amplitude)",
                    "trunk_source": self.trunk_source}
                   if self.trunk_table is not None else {}),
                **({"girdle_second_moment": _nested(self.girdle),
                    "girdle_second_moment_units": "g g^T + g s^T + s g^T per rad^2 of driver: g the model's scapula "
                                                  "and humerus ISB frames turned onto the bones' with skin markers "
                                                  "carried rigidly by the bones, s what the skin markers add (rotation "
                                                  "vectors, rad, in the model frames' own axes: scapula X Y Z, humerus "
                                                  "X Y Z; exubio.truth.girdle); not positive definite; the driver "
                                                  "here is theta + girdle_driver_offset_rad",
                    "girdle_driver_offset_rad": float(f"{self.girdle_offset_rad:.6g}"),
                    "girdle_source": self.girdle_source} if self.girdle is not None else {}),
                **({"judged_one_trial_out": dict(self.judgement)} if self.judgement else {})}


def saturating(theta: np.ndarray, saturation_rad: float | None, /) -> np.ndarray:
    """theta_s tanh(theta / theta_s) with theta_s = ``saturation_rad``, or theta itself where it is None."""
    t = np.asarray(theta, dtype=float)
    return t if saturation_rad is None else saturation_rad * np.tanh(t / saturation_rad)


def _nested(a) -> list:
    a = np.asarray(a, dtype=float)
    return [float(f"{x:.6g}") for x in a] if a.ndim == 1 else [_nested(x) for x in a]


@lru_cache(maxsize=1)
def shipped_amplitude() -> STAAmplitude:
    """The shipped model (S2M pins), read once per process."""
    return load_sta_amplitude()


def amplitude_of(binding: Any, /) -> STAAmplitude:
    """The STA amplitude model of a run with ``binding`` (exubio.protocol.bind.Binding): the file its
    protocol's ``uncertainty_model`` names, else the shipped one; read once and kept on the binding
    (InputError naming the file where it is not a model)."""
    amp = binding.fact("sta_amplitude")
    if amp is None:
        path = getattr(binding.protocol, "uncertainty_model", None)
        amp = binding.keep("sta_amplitude", load_sta_amplitude(path) if path else shipped_amplitude())
    return amp


def load_sta_amplitude(path: str | Path | None = None, /) -> STAAmplitude:
    """The shipped model (S2M pins) or a lab's JSON written by ``exubio.truth.sta_amplitude``
    (``exubio uncertainty-fit``)."""
    if path is None:
        text = resources.files("exubio.data").joinpath(SHIPPED).read_text()
        where = f"exubio/data/{SHIPPED}"
    else:
        where = str(path)
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise InputError(f"{path}: cannot read the STA amplitude model ({exc.strerror})") from None
    try:
        data = json.loads(text)
        out = {}
        for key in ("rotation", "translation", "nonrigid"):
            out[key] = {seg: np.asarray(v, dtype=float).reshape(3) for seg, v in data[key].items()}
        rigid = {seg: np.asarray(v, dtype=float).reshape(6, 6) for seg, v in data.get("rigid_second_moment", {}).items()}
        cross = {pair: np.asarray(v, dtype=float).reshape(6, 6)
                 for pair, v in data.get("rigid_cross_second_moment", {}).items()}
        trunk = (np.asarray(data["trunk_second_moment"], dtype=float).reshape(6, 6)
                 if "trunk_second_moment" in data else None)
        tables: dict = {}
        if "trunk_table_nodes_rad" in data:
            tn = np.asarray(data["trunk_table_nodes_rad"], dtype=float).reshape(-1)
            if tn.size == 0 or np.any(np.diff(tn) <= 0):
                raise ValueError("trunk_table_nodes_rad must be one or more increasing values")
            tables.update(trunk_nodes=tn, trunk_table=np.asarray(data["trunk_table"], dtype=float).reshape(tn.size, 6, 6))
        if "driver_saturation_rad" in data:
            sat = float(data["driver_saturation_rad"])
            if not (np.isfinite(sat) and sat > 0):
                raise ValueError(f"driver_saturation_rad must be a positive number of rad, got {sat!r}")
            tables.update(saturation_rad=sat)
        if "girdle_second_moment" in data:
            offset = float(data.get("girdle_driver_offset_rad", 0.0))  # absent: a file from before, no offset
            if not (np.isfinite(offset) and offset >= 0):
                raise ValueError(f"girdle_driver_offset_rad must be a number of rad >= 0, got {offset!r}")
            tables.update(girdle=np.asarray(data["girdle_second_moment"], dtype=float).reshape(6, 6),
                          girdle_source=str(data.get("girdle_source", "")), girdle_offset_rad=offset)
        judgement = data.get("judged_one_trial_out", {})
        if not isinstance(judgement, dict):
            raise ValueError("judged_one_trial_out must be a mapping")
        tables.update(judgement=judgement)
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise InputError(f"{where}: not an STA amplitude model ({type(exc).__name__}: {exc}); expected the JSON "
                         "that 'exubio uncertainty-fit' writes") from None
    bad = [pair for pair in cross if pair.count("|") != 1]
    if bad:
        raise InputError(f"{where}: 'rigid_cross_second_moment' keys must be 'A|B' (two segments), got {bad}")
    return STAAmplitude(out["rotation"], out["translation"], out["nonrigid"], rigid, cross, trunk,
                        str(data.get("trunk_source", "")), str(data.get("source", "")), str(data.get("citation", "")),
                        **tables, path="" if path is None else str(Path(path).resolve()))
