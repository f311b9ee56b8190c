"""exubio: upper-extremity joint kinematics from skin markers (potential-field and least-squares
multibody kinematics optimisation, built on Exudyn).

The Python face (exubio.api), data first::

    trial = exubio.read_trial("trial.c3d")
    model, protocol, report = exubio.calibrate(exubio.read_trial("static.c3d"))
    rec = exubio.reconstruct(trial, model, protocol, method="pf")
    rec.verdict, rec.quality.reasons            # the CLI's verdict for the same trial, and why
    exubio.to_dataframe(rec, model=model)       # the anatomical angles (deg) and their status
    exubio.write_results(rec, "out", "trial", model=model)

Functions: ``read_trial``, ``load_model``, ``load_protocol``, ``calibrate``, ``reconstruct``,
``assess``, ``angles``, ``angle_status``, ``to_dataframe``, ``write_results``, ``simulate``,
``moments`` (the joint moments, inverse dynamics), ``rhythm``, ``load_study``. Types:
``Trajectories``, ``Model``, ``Protocol``, ``Reconstruction``; the errors (``ExubioError`` and its
kinds). Loaded on first use, so ``import exubio`` stays light; ``dir(exubio)`` and IDEs see them all
(``__dir__`` and the stub ``__init__.pyi``)."""
from __future__ import annotations

__version__ = "0.1.0"

from exubio.errors import ExubioError, InputError, ModelError, ProtocolError, ReconstructionError

_API = ("read_trial", "load_model", "load_protocol", "calibrate", "reconstruct", "assess", "angles", "angle_status",
        "to_dataframe", "write_results", "simulate", "moments", "rhythm", "load_study")
_TYPES = ("Trajectories", "Model", "Protocol", "Reconstruction")

__all__ = [
    *_API,
    *_TYPES,
    "ExubioError",
    "InputError",
    "ModelError",
    "ProtocolError",
    "ReconstructionError",
    "__version__",
]


def __getattr__(name: str):
    if name in _API:
        from exubio import api

        return getattr(api, name)
    if name in _TYPES:
        from exubio import types

        return getattr(types, name)
    raise AttributeError(f"module 'exubio' has no attribute '{name}'")


def __dir__() -> list[str]:
    return sorted(__all__)
