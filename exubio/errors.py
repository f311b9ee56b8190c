"""The exception hierarchy of exubio: one root, one subclass per kind of failure.

Messages say what came, what was expected and where (file, marker, key), so that a
lab user can fix the input without reading the code. The CLI maps InputError,
ProtocolError and ModelError to exit code 2 (bad input) and ReconstructionError to 1.
"""
from __future__ import annotations


class ExubioError(Exception):
    """Root of every error exubio raises on purpose."""


class InputError(ExubioError):
    """A trial file (C3D/TRC) or an output location is missing, unreadable or inconsistent."""


class ProtocolError(ExubioError):
    """A protocol YAML is invalid: unknown key, unknown segment, bad value, missing marker."""


class ModelError(ExubioError):
    """A model YAML is invalid or a model is used inconsistently."""


class ReconstructionError(ExubioError):
    """A reconstruction could not produce a trustworthy result (divergence, solver failure)."""


class PartialReconstructionError(ReconstructionError):
    """Some of the methods asked for failed, the others' results were written: ``outputs`` holds the
    written ones (exubio.run.pipeline.reconstruct_file's outcome per method, exubio.run.outcome.MethodOutcome),
    ``failures`` each failed method's reason ({"pf": "..."})."""

    def __init__(self, message: str, /, *, outputs: list, failures: dict[str, str]) -> None:
        super().__init__(message)
        self.outputs, self.failures = outputs, failures
