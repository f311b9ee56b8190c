"""The files of one reconstruction: the angles CSV, the .mot (with the thorax's free-joint columns),
the .npz, summary.json and, with the joint moments, their CSV, .sto and the thorax's motion, written
as one result set (exubio.io.results.ResultSet: all or nothing); the angles' header lines."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from exubio.io import results
from exubio.io.result_names import set_names
from exubio.types import Reconstruction


@dataclass(frozen=True)
class AngleOutputs:
    """The anatomical angles of one reconstruction as the files carry them: names
    (exubio.model.angles.ANATOMICAL_COLUMNS), values (n, a) rad, status (n, a) AngleStatus codes, the
    comment lines that describe them (``angle_header``)."""

    names: tuple[str, ...]
    values_rad: np.ndarray
    status: np.ndarray
    comments: tuple[str, ...] = ()
    undetermined: np.ndarray | None = None  # (n, m) per model coordinate: not determined by the markers
    uncertainty_rad: np.ndarray | None = None  # (n, a) standard uncertainty (exubio.trust.angle_uncertainty)
    moments: Any = None  # the joint moments of the same frames (exubio.dynamics.moments.Moments) or None: <stem>.moments.csv
    thorax_coordinates: np.ndarray | None = None  # (n, 6) the trunk in the lab (exubio.export.thorax); None: 0 in the .mot
    signs: str = "isb"  # the files' sign convention (exubio.model.signs); values_rad stay ISB


def write_outputs(recon: Reconstruction, out_dir: str | Path, stem: str, /, *,
                  metadata: dict[str, Any], summary_data: dict[str, Any], angles: AngleOutputs,
                  streamed: dict[str, Any] | None = None,
                  overwrite: bool = True) -> dict[str, Path]:
    """Write <stem>.csv and .mot (the anatomical angles ``angles`` in degrees, each one's status in
    the header), .npz (everything: the model coordinates, ``angles.undetermined`` (n, m) per coordinate and
    the angles' status per frame) and .summary.json into out_dir as one result set, complete or
    absent (exubio.io.results.ResultSet: written in a hidden staging folder, renamed into place,
    summary.json last; without ``overwrite`` no existing file is ever replaced); ``streamed``:
    arrays the reconstruction left on disk (exubio.io.streamed), copied into the .npz; with
    ``angles.moments`` (exubio.dynamics.moments.Moments) also <stem>.moments.csv and the generalized forces
    as OpenSim's ID tool writes them, <stem>.moments.sto (exubio.export.sto), in the same set.
    The angles are written in ``angles.signs`` (exubio.model.signs: the ISB values times each
    angle's sign, flipped here and nowhere else); the .mot header, the .npz (``angle_signs``, the
    metadata's ``signs``) and the CSV header (``angles.comments``) say which."""
    from exubio.model.signs import convert, factors, mot_note

    moments = angles.moments
    written = angles.values_rad if angles.signs == "isb" else convert(angles.names, angles.values_rad, "isb", angles.signs)
    out = Path(out_dir)
    names = set_names(stem, moments=moments is not None, thorax=getattr(moments, "thorax", None) is not None)
    notes = [f"exubio_{line.split(':', 1)[0].replace(' ', '_')}={line.split(':', 1)[1].strip()}"
             for line in angles.comments if line.startswith("status ")]
    if summary_data.get("quality"):
        notes.append(f"exubio_quality={summary_data['quality']['verdict']}")
    notes.append(mot_note(angles.signs))
    metadata = {**metadata, "signs": angles.signs}
    extra = {"angle_status": np.asarray(angles.status, dtype=np.int8), "angle_names": np.array(angles.names),
             "angle_signs": factors(angles.names, angles.signs).astype(np.int8)}
    if angles.undetermined is not None:
        extra["undetermined"] = angles.undetermined
    if angles.uncertainty_rad is not None:
        extra["angle_uncertainty_rad"] = np.asarray(angles.uncertainty_rad, dtype=float)
    with results.ResultSet(out, stem, overwrite=overwrite) as result_set:
        staged = {kind: result_set.path(name) for kind, name in names.items()}
        results.write_angles_csv(staged["csv"], recon.time_s, [f"{n}_deg" for n in angles.names], written,
                                 comments=angles.comments, uncertainty_rad=angles.uncertainty_rad)
        _write_mot(staged["mot"], recon, angles.names, written, angles.thorax_coordinates, stem, notes)
        results.write_npz(staged["npz"], recon, metadata=metadata, extra_arrays=extra, streamed=streamed)
        if moments is not None:
            from exubio.dynamics.moments_file import write_moments_csv
            from exubio.export.sto import write_generalized_forces_sto
            from exubio.run.moments_outputs import moments_comments

            write_moments_csv(staged["moments"], moments, comments=moments_comments(moments))
            write_generalized_forces_sto(staged["moments_sto"], moments, name=f"{stem} generalized forces")
            if "thorax" in staged:
                from exubio.dynamics.thorax_file import write_thorax_csv

                write_thorax_csv(staged["thorax"], moments.thorax)
        results.write_json(staged["summary"], summary_data)
        placed = result_set.commit(last=names["summary"])
    return {kind: placed[name] for kind, name in names.items()}


def _write_mot(path: Path, recon: Reconstruction, names: tuple[str, ...], written: np.ndarray,
               thorax_coordinates: np.ndarray | None, stem: str, notes: list[str]) -> None:
    """The .mot: the anatomical angles as written (their sign convention) and the thorax's free-joint
    coordinates (exubio.export.thorax: the exported .osim's, so OpenSim's tools run on the file with the
    trunk's motion; 0 without it)."""
    from exubio.export.thorax import THORAX_TRANSLATIONS, thorax_mot_columns

    thorax_names, values = thorax_mot_columns(recon.n_frames, thorax_coordinates)
    if thorax_coordinates is None:
        notes = [*notes, "exubio_thorax_columns=0 (the thorax-fixed model: the ground is the thorax frame)"]
    else:
        notes = [*notes, "exubio_thorax_columns=measured (the thorax's pose in the lab, the lab turned so that Y is up)"]
    results.write_mot(path, recon.time_s, (*names, *thorax_names), written, more=values,
                      name=stem, notes=notes, metres=THORAX_TRANSLATIONS)


def mot_thorax(moments: Any) -> np.ndarray | None:
    """The .mot's thorax columns from the thorax's motion measured in the lab (None: a still thorax or a
    left arm, whose mirrored model the .osim does not hold: the columns stay 0, said in the header)."""
    motion = getattr(moments, "thorax", None)
    if motion is None or getattr(motion, "mirrored", False):
        return None
    from exubio.export.thorax import lab_thorax_coordinates

    return lab_thorax_coordinates(motion.rotation, motion.origin_m, motion.gravity_m_s2)


MAX_STATUS_RUNS = 12
"""An angle whose status changes more often than this is summarised by shares in the file headers
(its every frame is in the .npz)."""


def angle_header(det, trial: str, method: str, side: str, signs: str = "isb") -> tuple[str, ...]:
    """Comment lines of ``<trial>.<method>.csv``: what the angles are (definition, sign in the
    convention ``signs``, exubio.model.signs), and each one's status
    (exubio.trust.observability.AngleStatus) with the frame ranges where it changes."""
    from exubio.model.angles import ANATOMICAL_ANGLES
    from exubio.model.signs import header_line, meaning
    from exubio.trust.observability import AngleStatus

    lines = [f"exubio anatomical joint angles of {trial} ({method.upper()}); angles in degrees, time in seconds",
             "ISB frames (Wu et al. 2005) from the model's landmarks, intrinsic sequences, "
             + ("raw signs" if signs == "isb" else "clinical signs") + "; GH in ISB Y-X'-Y'' and in Phadke's X-Z'-Y''",
             header_line(signs)]
    lines += [f"{n}: {d}; {meaning(n, signs)}" for n, d, _ in ANATOMICAL_ANGLES]
    if side == "left":
        lines.append("LEFT arm: its markers were mirrored through the thorax's sagittal plane (Z -> -Z of the ISB thorax "
                     "frame) onto the right-arm model, so every angle carries the right arm's sign (Wu et al. 2005)")
    else:
        lines.append("right arm, signs of Wu et al. 2005" if signs == "isb" else
                     "right arm, signs of Wu et al. 2005 but for the reversed ones named in the signs line")
    lines.append("status: measured = the markers determine it; modelled = set by a named protocol rule; not measured = "
                 "neither (read it as no measurement)")
    if getattr(det, "uncertainty_rad", None) is not None:
        from exubio.trust.angle_uncertainty import UNCERTAINTY_DEFINITION

        lines.append(f"<angle>_u_deg: {UNCERTAINTY_DEFINITION}; the truth lies within +-2u in about 95 % of frames "
                     "(coverage measured on bone pins and bone-pin artefact simulations: studies/README.md)")
        if getattr(det, "uncertainty_model", ""):
            lines.append(f"<angle>_u_deg: the STA amplitude model is the lab's, not the shipped one: {det.uncertainty_model}")
    for j, n in enumerate(det.names):
        col = np.asarray(det.status[:, j])
        rule = f" ({det.rule[n]})" if n in det.rule else ""
        change = np.flatnonzero(np.diff(col)) + 1
        if not change.size:
            lines.append(f"status {n}: {AngleStatus(int(col[0])).label if col.size else 'measured'}{rule}")
            continue
        if change.size > MAX_STATUS_RUNS:
            share = ", ".join(f"{AngleStatus(k).label} {100 * np.mean(col == k):.0f} %" for k in np.unique(col))
            lines.append(f"status {n}: changes {change.size} times: {share} of the frames (every frame: the .npz, "
                         f"angle_status){rule}")
            continue
        starts = np.concatenate([[0], change])
        ends = np.concatenate([change, [col.size]])
        runs = ", ".join(f"{AngleStatus(int(col[a])).label} {a}-{b - 1}" for a, b in zip(starts, ends))
        lines.append(f"status {n}: by frame: {runs}{rule}")
    return tuple(lines)
