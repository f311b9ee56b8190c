"""exubio: upper-extremity joint kinematics from skin markers (potential-field and least-squares
multibody kinematics optimisation, built on Exudyn)."""
from __future__ import annotations

__version__ = "0.1.0"

from exubio.errors import ExubioError, InputError, ModelError, ProtocolError, ReconstructionError

__all__ = [
    "ExubioError",
    "InputError",
    "ModelError",
    "ProtocolError",
    "ReconstructionError",
    "__version__",
]
