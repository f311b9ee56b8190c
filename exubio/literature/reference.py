"""Published in vivo shoulder kinematics shipped with exubio.

* Ludewig et al. 2009 mean curves (``exubio/data/ludewig2009.csv``; the file's header cites the
  sources), used by ``exubio.synth.simulate`` for the shoulder rhythm;
* the corpus of the Spartacus shoulder kinematics dataset (``exubio/data/spartacus/``, built by
  ``models/sources/spartacus_corpus.py``; cite Moissenet et al. 2025, doi
  10.1016/j.jbiomech.2025.112642, and each study shown): 16 studies' SC, AC, ST and GH rotation
  curves against humerothoracic elevation, each with how the study built its segment frames
  (``Study.frames``, in the grammar of ``exubio.model.frame_definitions``) and its Euler sequence.

Numbers are the raw Euler angles of the study's own frames and sequence: the published value
times the study's sign correction (``corrections.csv``), so that the same decomposition of the
same rotation gives the same number. A study's frame correction method (e.g. Ludewig's
``kolz_AC_to_PA``) is recorded, not applied: comparing in the study's own frames needs none.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from exubio.model.frame_definitions import JOINT_SEGMENTS, FrameDefinition, JointDefinition, sequence_letters
from exubio.io.resources import shipped_file

__all__ = ["Study", "ReferenceCurve", "load_corpus", "load_ludewig2009", "ludewig2009_at", "study_definition",
           "JOINT_CODES", "PLANES", "CORPUS_CITATION", "LUDEWIG_ID"]

CORPUS_CITATION = ("Spartacus shoulder kinematics dataset: Moissenet F, Puchaud P, Naaim A, Holzer N, Begon M, "
                   "J Biomech 2025, doi 10.1016/j.jbiomech.2025.112642 (Zenodo 10.5281/zenodo.11455521)")
LUDEWIG_ID = "#11"
JOINT_CODES = {"sternoclavicular": "SC", "acromioclavicular": "AC", "scapulothoracic": "ST", "glenohumeral": "GH"}
PLANES = {"frontal plane elevation": "frontal", "sagittal plane elevation": "sagittal",
          "scapular plane elevation": "scapular"}
"""Humeral motions that are arm elevation in a plane, by the name exubio uses for the plane."""
_SEGMENTS = ("thorax", "clavicle", "scapula", "humerus")


def _flag(v: str) -> bool:
    return v.strip().lower() == "true"


@dataclass(frozen=True)
class Study:
    """One study of the corpus: citation, method and how it built each segment frame (None where
    the metadata gives none; a thorax that is the imaging device's frame is ``thorax_is_global``)."""

    id: str
    authors: str
    year: int
    doi: str
    in_vivo: bool
    method: str
    n_shoulders: int
    active: bool
    posture: str
    thorax_is_global: bool
    side_as_right: bool
    frames: dict[str, FrameDefinition | None] = field(default_factory=dict, compare=False, hash=False)

    @property
    def label(self) -> str:
        return f"{self.authors} {self.year}"

    @property
    def citation(self) -> str:
        return f"{self.authors} {self.year} ({self.method}, {self.n_shoulders} shoulders; doi {self.doi})"


@dataclass(frozen=True)
class ReferenceCurve:
    """One joint's rotations during one humeral motion of one study (a mean curve, or one
    shoulder's): ``dofs`` holds, per Euler angle in sequence order, (ht_deg, angle_deg) arrays or
    None where the study did not publish that angle."""

    study: Study
    joint: str  # SC, AC, ST, GH
    motion: str  # "frontal", "sagittal", "scapular" or the metadata's humeral motion
    sequence: str  # as published, e.g. "yx'z''"
    is_mean: bool
    shoulder: str
    files: tuple[str, str, str]
    dofs: tuple[tuple[np.ndarray, np.ndarray] | None, ...] = field(compare=False, hash=False)


def _read(name: str) -> list[dict[str, str]]:
    path = shipped_file("exubio.data", f"spartacus/{name}", "exubio/data")
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _frame(row: dict[str, str], segment: str) -> FrameDefinition | None:
    x, y, z = (row[f"{segment}_{a}_direction"].strip() for a in "xyz")
    if not (x or y or z):
        return None
    return FrameDefinition(segment, x=x, y=y, z=z, origin=row[f"{segment}_origin"].strip(),
                           correction=row[f"{segment}_correction_method"].strip())


@lru_cache(maxsize=1)
def _corpus() -> tuple[dict[str, Study], tuple[ReferenceCurve, ...]]:
    studies: dict[str, Study] = {}
    for r in _read("studies.csv"):
        studies[r["dataset_id"]] = Study(
            id=r["dataset_id"], authors=r["dataset_authors"], year=int(r["dataset_year"]),
            doi=r["dataset_doi"].strip('"'), in_vivo=_flag(r["in_vivo"]), method=r["experimental_mean"],
            n_shoulders=int(r["number_of_shoulders"]), active=_flag(r["active"]), posture=r["posture"],
            thorax_is_global=_flag(r["thorax_is_global"]), side_as_right=_flag(r["side_as_right"]),
            frames={s: _frame(r, s) for s in _SEGMENTS})
    values: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for r in _read("curves.csv"):
        values.setdefault((r["folder"], r["file"]), []).append((float(r["ht_deg"]), float(r["value_deg"])))
    factor = {(r["folder"], r["file"]): float(r["factor"]) for r in _read("corrections.csv")}
    curves = []
    for r in _read("joint_data.csv"):
        files = (r["dof_1st_euler"], r["dof_2nd_euler"], r["dof_3rd_euler"])
        dofs = []
        for name in files:
            pts = values.get((r["folder"], name)) if name else None
            if not pts:
                dofs.append(None)
                continue
            a = np.array(sorted(pts))
            dofs.append((a[:, 0], a[:, 1] * factor.get((r["folder"], name), 1.0)))
        if all(d is None for d in dofs) or not r["euler_sequence"].strip():
            continue
        curves.append(ReferenceCurve(
            study=studies[r["dataset_id"]], joint=JOINT_CODES[r["joint"]],
            motion=PLANES.get(r["humeral_motion"], r["humeral_motion"]), sequence=r["euler_sequence"].strip(),
            is_mean=_flag(r["is_data_mean"]), shoulder=r["shoulder_id"], files=files, dofs=tuple(dofs)))
    return studies, tuple(curves)


def load_corpus() -> tuple[dict[str, Study], tuple[ReferenceCurve, ...]]:
    """(studies by id, every rotation curve) of the shipped Spartacus corpus."""
    return _corpus()


def study_definition(study: Study, joint: str, sequence: str) -> JointDefinition | None:
    """The joint-angle definition of ``study`` (its frames of the joint's two segments and
    ``sequence``), or None when the metadata lacks one of the frames."""
    parent, child = JOINT_SEGMENTS[joint]
    p, c = study.frames.get(parent), study.frames.get(child)
    if p is None or c is None:
        return None
    sequence_letters(sequence)
    return JointDefinition(joint, p, c, sequence, study.label)


def load_ludewig2009() -> dict[str, dict[str, np.ndarray]]:
    """Ludewig et al. 2009 mean curves from ``exubio/data/ludewig2009.csv``:
    {plane: {"ht_elevation_deg": (n,), "<column>": (n,) deg}}."""
    path = shipped_file("exubio.data", "ludewig2009.csv", "exubio/data")
    lines = [ln for ln in path.read_text(encoding="utf-8").splitlines() if ln and not ln.startswith("#")]
    header = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    out: dict[str, dict[str, np.ndarray]] = {}
    for plane in dict.fromkeys(r[0] for r in rows):
        sel = np.array([[float(v) for v in r[1:]] for r in rows if r[0] == plane])
        out[plane] = {name: sel[:, i] for i, name in enumerate(header[1:])}
    return out


def ludewig2009_at(ht_deg, columns, planes=("frontal", "sagittal")) -> dict[str, dict[str, tuple[float, ...]]]:
    """{plane: {column without its axis suffix: values at ``ht_deg``}}, e.g. "SC_elevation" from
    the file's "SC_elevation_X"."""
    data = load_ludewig2009()
    out: dict[str, dict[str, tuple[float, ...]]] = {}
    for plane in planes:
        cols = data[plane]
        ht = cols["ht_elevation_deg"]
        rows = [int(np.flatnonzero(ht == h)[0]) for h in ht_deg]
        out[plane] = {}
        for col in columns:
            name = next(n for n in cols if n.rsplit("_", 1)[0] == col)
            out[plane][col] = tuple(float(cols[name][i]) for i in rows)
    return out
