"""exubio from Python (a notebook, a script): the few functions a lab needs, on loaded objects,
data first (the trial, then the model and the protocol it is read with).

    import exubio
    model = exubio.load_model()                          # generic model (or a calibrated YAML)
    protocol = exubio.load_protocol(model=model)         # the 21-marker protocol, bound to the model
    trial = exubio.read_trial("trial.c3d")               # C3D or TRC: labels, positions (m), time (s)
    model, protocol, report = exubio.calibrate(exubio.read_trial("static.c3d"), model, protocol)
    rec = exubio.reconstruct(trial, model, protocol, method="ls")   # an exubio.Reconstruction
    rec.verdict                                          # "ok" / "check" / "fail": the CLI's verdict
    rec.quality.reasons                                  # ... and why
    both = exubio.assess(trial, [rec, exubio.reconstruct(trial, model, protocol)], model, protocol)
    angles = exubio.angles(rec, model)                   # anatomical angles (rad) by name
    df = exubio.to_dataframe(rec, model=model)           # pandas: the angles in degrees and their status
    exubio.write_results(rec, "out", "trial", model=model)   # CSV, .mot, .npz, summary.json (atomic)
    sim = exubio.simulate("abduction", model)            # a trial with a known truth (sim.q_true)

Everything is SI inside (m, s, rad); degrees only in the DataFrame and the files, labelled. The
command line (``exubio reconstruct``) runs the same steps and adds the trial report.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.types import MarkerTargets, Model, Protocol, Reconstruction, Trajectories

if TYPE_CHECKING:  # pandas is imported when a DataFrame is asked for
    import pandas

    from exubio.synth.simulate import SimulatedTrial
    from exubio.trust.assess import TrialAssessment

__all__ = ["read_trial", "load_model", "load_protocol", "calibrate", "reconstruct", "assess", "angles", "angle_status",
           "to_dataframe", "write_results", "simulate", "rhythm", "load_study"]


def read_trial(path: str | Path, /) -> Trajectories:
    """A C3D or TRC trial: labels (subject prefixes stripped), positions (m, NaN in gaps), time (s)."""
    from exubio.io.trial import read_trial as _read

    return _read(path)


def load_model(path: str | Path | None = None, /, *, body_mass_kg: float | None = None) -> Model:
    """A model YAML (default: the shipped generic right-arm model), or a calibrated one."""
    from exubio.model.load import load_model as _load

    return _load(path, body_mass_kg=body_mass_kg) if path is not None else _load(body_mass_kg=body_mass_kg)


def load_protocol(path: str | Path | None = None, /, *, model: Model | None = None) -> Protocol:
    """A protocol YAML (default: the shipped 21-marker protocol) checked against ``model`` (default:
    the generic model); on a calibrated model, bound to its registered marker points."""
    from exubio.run.inputs import protocol_for_model

    return protocol_for_model(model if model is not None else load_model(), path)


_CALIBRATIONS: dict[int, Any] = {}
"""id(calibrated model) -> the calibration exubio.calibrate made it with (its session left out, so
the model is not kept alive by it), for as long as that model object lives: reconstruct, assess
and write_results read it, as ``exubio reconstruct --static`` reads its session's calibration."""


def _calibration_of(model: Model | None, /) -> Any:
    return _CALIBRATIONS.get(id(model)) if model is not None else None


def calibrate(static: Trajectories, model: Model | None = None, protocol: Protocol | None = None, /, *,
              frames: slice | None = None, functional: Trajectories | None = None,
              scapula_motion: Trajectories | None = None):
    """Fit the model to the subject from a static trial (optionally a functional trial for the
    glenohumeral centre, and a movement trial whose scapula postures the thorax ellipsoid is fitted
    through): (calibrated model, protocol bound to it, CalibrationReport). The calibration is that
    of ``exubio reconstruct --static`` (exubio.run.session), and the calibrated model carries it:
    ``reconstruct``, ``assess`` and ``write_results`` with this model give the CLI's verdict for
    the same static and trial, its calibration and static-label reasons included."""
    import weakref

    from exubio.run.session import StaticSpec, calibrate_in_memory

    if frames is not None and (not isinstance(frames, slice) or frames.step not in (None, 1)):
        raise InputError(f"frames: expected a slice of the static's frames like slice(0, 50), got {frames!r}")
    spec = StaticSpec(frames=None if frames is None else f"{frames.start or ''}:{'' if frames.stop is None else frames.stop}",
                      functional=functional, scapula_trials=() if scapula_motion is None else (scapula_motion,))
    cal = calibrate_in_memory(static, _session(model, protocol), spec)
    calibrated, bound = cal.session.model, cal.session.protocol
    _CALIBRATIONS[id(calibrated)] = dataclasses.replace(cal, session=None)
    weakref.finalize(calibrated, _CALIBRATIONS.pop, id(calibrated), None)
    return calibrated, bound, cal.report


def _session(model: Model | None, protocol: Protocol | None, /):
    """The run layer's Session for loaded objects (for a calibrated model, its generic model, which
    the label checks expect, is read from the file the calibration recorded)."""
    from exubio.run.inputs import Session, generic_of

    model = model if model is not None else load_model()
    protocol = protocol if protocol is not None else load_protocol(model=model)
    return Session(model, protocol, *generic_of(model, protocol))


def _inputs(trial: Trajectories | MarkerTargets | str | Path, session, /):
    """The trial through the run's checks and preparation (exubio.run.pipeline.load_inputs), or,
    given as prepared targets, as they are."""
    from exubio.run.pipeline import TrialInfo, TrialInputs, load_inputs

    if isinstance(trial, MarkerTargets):
        info = TrialInfo(source=trial.source, labels=trial.marker_names, ignored_labels=(), units_in_file="m",
                         rate_hz=float(1.0 / np.median(np.diff(trial.time_s))) if trial.n_frames > 1 else 0.0)
        return TrialInputs(info, session.model, session.protocol, trial, generic_model=session.generic_model,
                           generic_protocol=session.generic_protocol)
    return load_inputs(trial, session)


def reconstruct(trial: Trajectories | MarkerTargets | str | Path, model: Model | None = None,
                protocol: Protocol | None = None, /, *, method: str = "pf", **options: Any) -> Reconstruction:
    """Joint kinematics of one trial by one method ("pf" or "ls"), assessed as ``exubio
    reconstruct`` assesses it: the result's ``verdict`` ("ok", "check", "fail") and ``quality``
    (with its reasons) are the CLI's for the same trial, model and protocol. ``options`` go to the
    method's options (e.g. ``step_s`` for PF). ``trial``: a file, a read trial or prepared targets."""
    from exubio.run.pipeline import assess_inputs
    from exubio.run.pipeline import reconstruct as _reconstruct

    session = _session(model, protocol)
    inputs = _inputs(trial, session)
    if method == "pf" and "inertia_scale" not in options and inputs.protocol.pf_inertia_scale is not None:
        options["inertia_scale"] = inputs.protocol.pf_inertia_scale  # the protocol's defaults.pf_inertia_scale
    rec = _reconstruct(inputs.model, inputs.protocol, inputs.targets, method=method, **options)
    cal = _calibration_of(model)
    quality = assess_inputs(inputs, [rec], cal).quality[rec.method]
    return dataclasses.replace(rec, quality=_with_input_notes(quality, inputs, cal))


def _with_input_notes(quality: Any, inputs: Any, calibration: Any, /) -> Any:
    """The verdict as the CLI's summary gives it: with a note per finding of the trial's and the
    static's readers (exubio.run.summary_file.trial_quality)."""
    from exubio.run.summary_file import _file_findings, input_notes

    return quality.with_reasons(input_notes(_file_findings(inputs, calibration)))


def assess(trial: Trajectories | MarkerTargets | str | Path, reconstructions: Sequence[Reconstruction],
           model: Model | None = None, protocol: Protocol | None = None, /) -> "TrialAssessment":
    """The assessment of a trial's reconstructions together (a PF and an LS one: their agreement
    enters each verdict, as with ``exubio reconstruct --method both``): per method its quality
    (``.quality[method].verdict``), determinacy, range limits, angle status; the label findings."""
    from exubio.run.pipeline import assess_inputs

    session = _session(model, protocol)
    return assess_inputs(_inputs(trial, session), list(reconstructions), _calibration_of(model))


def angles(reconstruction: Reconstruction | np.ndarray, model: Model | None = None, /, *,
           signs: str = "isb") -> dict[str, np.ndarray]:
    """The anatomical angles (exubio.model.angles.ANATOMICAL_ANGLES: ISB SC, AC, ST, GH, HT, GH in
    Phadke's sequence, elbow, forearm, wrist) of a reconstruction or of coordinates q (n, m), in
    radians, by name; definitions and ISB signs in exubio.model.angles; ``signs="clinical"``:
    elevation, abduction and upward rotation positive (exubio.model.signs)."""
    from exubio.model.angles import anatomical_table
    from exubio.model.signs import check_signs, convert

    signs = check_signs(signs, "signs")
    q = reconstruction.q_rad if isinstance(reconstruction, Reconstruction) else np.asarray(reconstruction, dtype=float)
    names, table = anatomical_table(model if model is not None else load_model(), np.atleast_2d(q))
    table = convert(names, table, "isb", signs)
    return {n: table[:, j] for j, n in enumerate(names)}


def _signs(signs: str | None, protocol: Protocol | None, /) -> str:
    """The convention asked for: ``signs``, else the protocol's ``signs`` key, else isb."""
    from exubio.model.signs import check_signs

    if signs is not None:
        return check_signs(signs, "signs")
    return protocol.signs if protocol is not None else "isb"


def simulate(motion: str = "abduction", model: Model | None = None, /, *, duration_s: float = 10.0,
             rate_hz: float = 100.0, noise_mm: float = 0.0, sta_mm: float = 0.0, seed: int = 0) -> "SimulatedTrial":
    """A simulated trial with a known truth (exubio.synth.simulate.simulate_trial): ``motion``
    "abduction", "flexion" or "scaption"; ``.trajectories`` the markers (m), ``.q_true`` (rad)."""
    from exubio.synth.simulate import simulate_trial

    return simulate_trial(model if model is not None else load_model(), motion, duration_s=duration_s, rate_hz=rate_hz,
                          noise_mm=noise_mm, sta_mm=sta_mm, seed=seed)


def angle_status(reconstruction: Reconstruction, model: Model | None = None, protocol: Protocol | None = None, /):
    """Every anatomical angle's status per frame (exubio.trust.observability.AngleDeterminacy: measured,
    modelled by a named rule, or not measured) for a reconstruction made with ``protocol``; the
    frames where a marker was missing are those whose residual is NaN."""
    from exubio.protocol.bind import bind
    from exubio.trust.observability import angle_determinacy
    from exubio.trust.sta_amplitude import amplitude_of

    model = model if model is not None else load_model()
    protocol = protocol if protocol is not None else load_protocol(model=model)
    b = bind(model, protocol)
    present = np.isfinite(reconstruction.residuals_m)
    dt = float(np.median(np.diff(reconstruction.time_s))) if reconstruction.n_frames > 1 else 1.0
    return angle_determinacy(b.kin, b.points, reconstruction.q_rad, present, protocol.weights,
                             held=b.held, locked=b.locked, amplitude=amplitude_of(b),
                             every=max(1, int(round(0.05 / dt))), residuals_m=reconstruction.residuals_m,
                             marker_positions_m=reconstruction.measured_m)


def to_dataframe(reconstruction: Reconstruction, /, *, model: Model | None = None,
                 protocol: Protocol | None = None, signs: str | None = None) -> "pandas.DataFrame":
    """The reconstruction's anatomical angles (exubio.model.angles.ANATOMICAL_ANGLES) as a pandas
    DataFrame indexed by time (s): ``<angle>_deg`` in degrees, ``<angle>_u_deg`` its standard
    uncertainty (exubio.trust.angle_uncertainty) and ``<angle>_status`` (measured, modelled, not
    measured: a categorical column), as in the CSV; ``df.attrs`` holds the method, units, the
    sign convention (``signs``: "isb" or "clinical", exubio.model.signs; default the protocol's
    ``signs`` key, else isb) and each angle's definition with its sign in it. The model
    coordinates stay in the reconstruction."""
    import pandas as pd

    from exubio.model.angles import ANATOMICAL_ANGLES, anatomical_table
    from exubio.model.signs import convert, meaning
    from exubio.trust.observability import AngleStatus

    r = reconstruction
    signs = _signs(signs, protocol)
    model = model if model is not None else load_model()
    names, ang = anatomical_table(model, r.q_rad)
    ang = convert(names, ang, "isb", signs)
    det = angle_status(r, model, protocol)
    status = det.status
    labels = pd.Categorical.from_codes(np.zeros(0, dtype=int), categories=[s.label for s in AngleStatus])
    data = {}
    for i, n in enumerate(names):
        data[f"{n}_deg"] = np.degrees(ang[:, i])
        if det.uncertainty_rad is not None:
            data[f"{n}_u_deg"] = np.degrees(det.uncertainty_rad[:, i])
    data.update({f"{n}_status": pd.Categorical.from_codes(status[:, i].astype(int), categories=labels.categories)
                 for i, n in enumerate(names)})
    df = pd.DataFrame(data, index=pd.Index(r.time_s, name="time_s"))
    df.attrs.update({"method": r.method, "units": "deg", "source": "exubio", "signs": signs,
                     "definitions": {n: f"{d}; {meaning(n, signs)}" for n, d, _ in ANATOMICAL_ANGLES}})
    return df


def moments(reconstruction: Reconstruction, model: Model | None = None, /, *,
            hand_load_kg: float = 0.0, thorax=None, loads=()) -> "pandas.DataFrame":
    """The reconstruction's net joint moments (exubio.dynamics.moments: GH, elbow, forearm, wrist in
    the ISB frames, N m and N m/kg; every coordinate's generalized force; the scapulothoracic contact
    forces, N) as a pandas DataFrame indexed by time (s), the columns of <stem>.<method>.moments.csv.
    The inertia is Dumas et al. 2007's scaled by ``model``'s segment lengths and body mass (load it
    with ``body_mass_kg``), plus ``hand_load_kg`` in the hand; ``thorax``: the thorax's motion in the
    lab (exubio.prep.thorax_motion.measure_thorax_motion; None: still and upright), ``loads``:
    external loads (exubio.dynamics.loads.ExternalLoad); ``df.attrs`` says so."""
    import pandas as pd

    from exubio.dynamics.moments import reconstruction_moments

    model = model if model is not None else load_model()
    m = reconstruction_moments(model, reconstruction, hand_load_kg=hand_load_kg, thorax=thorax, loads=tuple(loads))
    df = pd.DataFrame(m.values, columns=list(m.columns), index=pd.Index(m.time_s, name="time_s"))
    df.attrs.update({"method": reconstruction.method, "units": "N m, N m/kg, N", "source": "exubio",
                     "body_mass_kg": m.body_mass_kg, "hand_load_kg": m.hand_load_kg,
                     "inertia_source": m.inertia_source, **m.info})
    return df


def write_results(reconstruction: Reconstruction, out_dir: str | Path, stem: str, /, *, model: Model | None = None,
                  protocol: Protocol | None = None, trial: Trajectories | str | Path | None = None,
                  overwrite: bool = False, signs: str | None = None) -> dict[str, Path]:
    """Write ``<stem>.<method>.csv`` and ``.mot`` (the anatomical angles, each one's status in the
    header), ``.npz`` and ``.summary.json`` into out_dir, as one set complete or absent; refuses to
    replace earlier results unless ``overwrite``. Returns the paths by kind. Given the ``trial``
    it was reconstructed from (its file, or the read trial), the files are those ``exubio
    reconstruct`` writes for it (the same assessment, verdict, label checks and header lines; only
    the wall-clock timings differ); without it, the reconstruction with its angles' status and
    the verdict it carries (exubio.reconstruct). ``signs``: the angles' sign convention in every
    file ("isb" or "clinical", exubio.model.signs; default the protocol's ``signs`` key, else isb)."""
    from exubio.io import results
    from exubio.io.result_names import method_stem
    from exubio.model.angles import anatomical_table
    from exubio.run.pipeline import AngleOutputs, angle_header, assess_inputs, write_assessed, write_outputs
    from exubio.run.summary_file import RunNotes, reconstruction_summary
    from exubio.types import Method

    full = method_stem(stem, reconstruction.method)
    if trial is not None:
        session = _session(model, protocol)
        session = session.with_signs(_signs(signs, session.protocol))
        inputs = _inputs(trial, session)
        cal = _calibration_of(model)
        assessment = assess_inputs(inputs, [reconstruction], cal)
        results.prepare_output_dir(out_dir, [full], overwrite=overwrite)
        source = str(trial) if isinstance(trial, (str, Path)) else inputs.trial.source
        done = [(Method.parse(reconstruction.method), full, reconstruction, None)]
        key = None  # the fingerprint `exubio reconstruct` gives the same run (exubio.run.resume)
        if isinstance(trial, (str, Path)) and isinstance(reconstruction.info.get("options"), Mapping):
            from exubio.run.resume import run_key

            key = run_key(trial, session.model, session.protocol, reconstruction.method,
                          options=dict(reconstruction.info["options"]))
        return write_assessed(inputs, source, out_dir, done, assessment, overwrite=overwrite,
                              notes=RunNotes(cal, inputs_sha256=key))[0].paths
    model = model if model is not None else load_model()
    protocol = protocol if protocol is not None else load_protocol(model=model)
    signs = _signs(signs, protocol)
    results.prepare_output_dir(out_dir, [full], overwrite=overwrite)
    det = angle_status(reconstruction, model, protocol)
    names, values = anatomical_table(model, reconstruction.q_rad)
    meta = {"written_by": "exubio.write_results", "method": reconstruction.method,
            "units": {"angles_in_files": "deg", "positions_in_npz": "m", "time": "s"}}
    summ = reconstruction_summary(reconstruction, det, source=stem, signs=signs)
    angles = AngleOutputs(names, values, det.status, angle_header(det, stem, reconstruction.method, protocol.side, signs),
                          uncertainty_rad=det.uncertainty_rad, signs=signs)
    return write_outputs(reconstruction, out_dir, full, metadata=meta, summary_data=summ, angles=angles,
                         overwrite=overwrite)


def rhythm(source: "Reconstruction | str | Path", model: Model | None = None, protocol: Protocol | None = None, /, *,
           method: str | None = None, signs: str | None = None) -> "pandas.DataFrame":
    """The scapulohumeral rhythm (exubio.scapulohumeral): ST, SC and GH angles against HT elevation,
    raising and lowering apart, with the in vivo corridor in the same frames for the plane of the
    raising, as a long DataFrame (the table behind the report's rhythm page).

    ``source``: a Reconstruction (with the model and protocol it was made with), a result file of
    ``exubio reconstruct`` (``<trial>.<method>.npz`` or ``.csv``): one row per frame of a cycle and
    angle (time_s, phase, cycle, ht_elevation_deg, angle, value_deg, u_deg, measured,
    corridor_lo_deg, corridor_hi_deg); or the output folder of ``exubio study`` (``method``: only
    that method's trials): one row per method, plane, level (group, subject), subject, phase, HT
    grid point and angle (mean_deg, sd_deg, n, corridor). ``df.attrs``: the plane, how it was found,
    the studies in the corridor and those left out with the reason, ``signs``. Degrees, in the
    convention ``signs`` ("isb" or "clinical", exubio.model.signs; default: a result file's or a
    study's own, else the protocol's ``signs`` key, else isb): value_deg, mean_deg and the corridor
    flip with it (HT elevation is positive in both; SD and uncertainty are the same)."""
    import pandas as pd

    from exubio.scapulohumeral import files, reference, table

    categorical = ("phase", "angle", "method", "plane", "level", "subject")
    if signs is not None:
        from exubio.model.signs import check_signs

        signs = check_signs(signs, "signs")
    if isinstance(source, Reconstruction):
        model = model if model is not None else load_model()
        df = to_dataframe(source, model=model, protocol=protocol, signs="isb")  # ISB inside, flipped at the table
        names = [c.removesuffix("_deg") for c in df.columns if c.endswith("_deg") and not c.endswith("_u_deg")]
        vals = np.column_stack([df[f"{n}_deg"].to_numpy() for n in names])
        u = np.column_stack([df[f"{n}_u_deg"].to_numpy() if f"{n}_u_deg" in df else np.full(len(df), np.nan)
                             for n in names])
        ok = np.column_stack([(df[f"{n}_status"] == "measured").to_numpy() for n in names])
        r = table.trial_rhythm(df.index.to_numpy(), names, vals, u, ok, signs=_signs(signs, protocol))
        plane, deg, why = reference.trial_plane(r)
        ref = reference.reference(model, plane, plane_deg=deg, why=why)
        cols = files.trial_columns(r, ref)
        shown = r.signs
    else:
        path = Path(source)
        if path.is_dir():
            groups = files.study_rhythm(path, method=method)
            if signs is not None:
                groups = [dataclasses.replace(g, signs=signs) for g in groups]
            cols = files.study_columns(groups)
            shown = groups[0].signs if groups else (signs or "isb")
            ref = groups[0].reference if groups else None
        elif path.suffix in (".npz", ".csv") and path.is_file():
            npz = path.with_suffix(".npz")
            r = files.read_trial_rhythm(npz)
            r = dataclasses.replace(r, signs=signs) if signs is not None else r
            ref, _ = files.trial_reference(npz, r)
            cols = files.trial_columns(r, ref)
            shown = r.signs
        else:
            raise InputError(f"{path}: expected a result of exubio reconstruct (<trial>.<method>.npz or .csv) or the "
                             f"output folder of exubio study (with study.json)")
    out = pd.DataFrame({c: (pd.Categorical(v) if c in categorical else v) for c, v in cols.items()})
    out.attrs["signs"] = shown
    if ref is not None:
        out.attrs.update({"plane": ref.plane, "plane_how": ref.why, "units": "deg", "signs": shown,
                          "corridor_studies": sorted({s for v in ref.studies.values() for s, _, _ in v}),
                          "corridor_left_out": ref.excluded})
    return out


def load_study(folder: str | Path, /, *, table: str = "angles") -> "pandas.DataFrame":
    """The angles of a study that ``exubio study`` ran into ``folder``: its ``angles.parquet``, one
    row per trial, method, frame and angle (subject, session, trial, task, method, time_s, angle,
    value_deg, u_deg, status, verdict; exubio.run.study_table), text columns categorical.
    ``table="moments"``: its joint moments, ``moments.parquet`` (sessions with a body mass; one row
    per trial, method, frame and quantity: ... quantity, value (SI), unit, body_mass_kg,
    hand_load_kg, verdict; exubio.run.study_moments)."""
    from exubio.errors import InputError

    if table == "moments":
        from exubio.run.study_moments import read_moments_table

        return read_moments_table(folder)
    if table != "angles":
        raise InputError(f"load_study: table must be 'angles' or 'moments', got {table!r}")
    from exubio.run.study_table import read_study_table

    return read_study_table(folder)
