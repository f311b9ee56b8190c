"""exubio from Python (a notebook, a script): the few functions a lab needs, on loaded objects.

    import exubio
    model = exubio.load_model()                          # generic model (or a calibrated YAML)
    protocol = exubio.load_protocol(model=model)         # the 21-marker protocol, bound to the model
    trial = exubio.read_trial("trial.c3d")               # C3D or TRC: labels, positions (m), time (s)
    model, protocol, report = exubio.calibrate(exubio.read_trial("static.c3d"), model, protocol)
    rec = exubio.reconstruct(trial, model, protocol, method="ls")   # an exubio.Reconstruction
    df = exubio.to_dataframe(rec, model=model)           # pandas: coordinates and ISB angles in degrees
    exubio.write_results(rec, "out", "trial", model=model)   # CSV, .mot, ISB CSV, .npz (atomic)

Everything is SI inside (m, s, rad); degrees only in the DataFrame and the files, labelled. The
command line (``exubio reconstruct``) does the same plus the quality verdict and the report.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from exubio.types import MarkerTargets, Model, Protocol, Reconstruction, Trajectories

if TYPE_CHECKING:  # pandas is imported when a DataFrame is asked for
    import pandas

__all__ = ["read_trial", "load_model", "load_protocol", "calibrate", "reconstruct", "isb_angles", "to_dataframe",
           "write_results"]


def read_trial(path: str | Path, /) -> Trajectories:
    """A C3D or TRC trial: labels (subject prefixes stripped), positions (m, NaN in gaps), time (s)."""
    from exubio.io.trial import read_trial as _read

    return _read(path)


def load_model(path: str | Path | None = None, /, *, body_mass_kg: float | None = None) -> Model:
    """A model YAML (default: the shipped generic right-arm model), or a calibrated one."""
    from exubio.model import load_model as _load

    return _load(path, body_mass_kg=body_mass_kg) if path is not None else _load(body_mass_kg=body_mass_kg)


def load_protocol(path: str | Path | None = None, /, *, model: Model | None = None) -> Protocol:
    """A protocol YAML (default: the shipped 21-marker protocol) checked against ``model`` (default:
    the generic model); on a calibrated model, bound to its registered marker points."""
    from exubio.pipeline import protocol_for_model

    return protocol_for_model(model if model is not None else load_model(), path)


def calibrate(static: Trajectories, model: Model | None = None, protocol: Protocol | None = None, /, *,
              frames: slice | None = None, functional: Trajectories | None = None):
    """Fit the model to the subject from a static trial (optionally a functional trial for the
    glenohumeral centre): (calibrated model, protocol bound to it, CalibrationReport)."""
    from exubio.calibration import calibrate_model, calibrated_protocol
    from exubio.preprocess import prepare_targets

    model = model if model is not None else load_model()
    protocol = protocol if protocol is not None else load_protocol(model=model)
    fun = prepare_targets(functional, protocol) if functional is not None else None
    calibrated, report = calibrate_model(model, protocol, static, frames=frames, functional=fun)
    return calibrated, calibrated_protocol(protocol, calibrated), report


def reconstruct(trial: Trajectories | MarkerTargets | str | Path, model: Model | None = None,
                protocol: Protocol | None = None, /, *, method: str = "pf", **options: Any) -> Reconstruction:
    """Joint kinematics of one trial by one method ("pf" or "ls"); ``options`` go to the method's
    options (e.g. ``step_s`` for PF). ``trial``: a file, a read trial or prepared targets."""
    from exubio.pipeline import reconstruct as _reconstruct
    from exubio.preprocess import prepare_targets

    model = model if model is not None else load_model()
    protocol = protocol if protocol is not None else load_protocol(model=model)
    if isinstance(trial, (str, Path)):
        trial = read_trial(trial)
    targets = trial if isinstance(trial, MarkerTargets) else prepare_targets(trial, protocol)
    return _reconstruct(model, protocol, targets, method=method, **options)


def isb_angles(model: Model, reconstruction: Reconstruction | np.ndarray, /) -> dict[str, np.ndarray]:
    """ISB angles (radians, (n, 3) per joint: SC, AC, ST, GH, HT; sequences and signs in
    exubio.angles) of a reconstruction or of coordinates q (n, m)."""
    from exubio.angles import isb_angles as _isb

    q = reconstruction.q_rad if isinstance(reconstruction, Reconstruction) else reconstruction
    return _isb(model, q)


def to_dataframe(reconstruction: Reconstruction, /, *, model: Model | None = None) -> "pandas.DataFrame":
    """The reconstruction as a pandas DataFrame indexed by time (s): one column per model
    coordinate in degrees (``<coordinate>_deg``), and with ``model`` the ISB angles too
    (``<joint>_<axis>_<angle>_deg``)."""
    import pandas as pd

    from exubio.angles import isb_table

    r = reconstruction
    data = {f"{n}_deg": np.degrees(r.q_rad[:, i]) for i, n in enumerate(r.coordinate_names)}
    if model is not None:
        names, ang = isb_table(model, r.q_rad)
        data.update({f"{n}_deg": np.degrees(ang[:, i]) for i, n in enumerate(names)})
    df = pd.DataFrame(data, index=pd.Index(r.time_s, name="time_s"))
    df.attrs.update({"method": r.method, "units": "deg", "source": "exubio"})
    return df


def write_results(reconstruction: Reconstruction, out_dir: str | Path, stem: str, /, *, model: Model | None = None,
                  overwrite: bool = False) -> dict[str, Path]:
    """Write ``<stem>.<method>.csv``, ``.mot``, ``.npz`` (and with ``model`` the ISB angles
    ``.isb.csv``) into out_dir, as one set complete or absent; refuses to replace earlier results unless
    ``overwrite``. Returns the paths by kind."""
    from exubio.angles import isb_table
    from exubio.io import results
    from exubio.pipeline import write_outputs

    full = f"{stem}.{reconstruction.method}"
    results.prepare_output_dir(out_dir, [full], overwrite=overwrite)
    isb = isb_table(model, reconstruction.q_rad) if model is not None else None
    meta = {"written_by": "exubio.write_results", "method": reconstruction.method,
            "units": {"angles_in_files": "deg", "positions_in_npz": "m", "time": "s"}}
    return write_outputs(reconstruction, out_dir, full, metadata=meta, summary_data={"method": reconstruction.method},
                         isb=isb, overwrite=overwrite)
