"""exubio: upper-extremity joint kinematics from skin markers (potential-field and least-squares
multibody kinematics optimisation, built on Exudyn).

The Python API (exubio.api): ``read_trial``, ``load_model``, ``load_protocol``, ``calibrate``,
``reconstruct``, ``isb_angles``, ``angle_status``, ``to_dataframe``, ``write_results`` and the result type
``Reconstruction``; loaded on first use, so ``import exubio`` stays light."""
from __future__ import annotations

__version__ = "0.1.0"

from exubio.errors import ExubioError, InputError, ModelError, ProtocolError, ReconstructionError

_API = ("read_trial", "load_model", "load_protocol", "calibrate", "reconstruct", "isb_angles", "angle_status", "to_dataframe",
        "write_results")

__all__ = [
    *_API,
    "Reconstruction",
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
    if name == "Reconstruction":
        from exubio.types import Reconstruction

        return Reconstruction
    raise AttributeError(f"module 'exubio' has no attribute '{name}'")
