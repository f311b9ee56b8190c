"""A third reconstruction method, as a contributor would add one (tests/methods/test_third_method.py): its
options dataclass, its run and its streaming form. It is a stub that raises: what the test checks is
that one module and one registry line make the CLI, a study and the reports list it."""
from __future__ import annotations

from dataclasses import dataclass

from exubio.errors import ReconstructionError

MESSAGE = "the stub method reconstructs nothing (a test of the method registry)"


@dataclass(frozen=True)
class StubOptions:
    tolerance: float = 1e-6


def reconstruct_stub(model, protocol, targets, *, options=None, progress=None):  # noqa: ARG001
    raise ReconstructionError(MESSAGE)


def stream_stub(binding, targets, sink, *, options=None, progress=None, chunk_frames=None):  # noqa: ARG001
    raise ReconstructionError(MESSAGE)
