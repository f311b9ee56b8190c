"""The reconstruction methods and their registry: each method is a function
``run(model, protocol, targets, *, options, progress) -> Reconstruction`` with one frozen options
dataclass, and its streaming form ``stream(binding, targets, sink, *, options, progress,
chunk_frames) -> (timings_s, info)`` that hands the result to ``sink`` in chunks
(exubio.methods.common); ``binding`` is the session's model bound to its protocol
(exubio.protocol.bind.Binding: kinematics, tracked points, held and locked coordinates). The registry (exubio.method_registry) names them for the pipeline, the CLI, the API and the outputs; a method's module (and
with PF, Exudyn) is imported only when the method is used."""
from __future__ import annotations

from exubio.method_registry import REGISTRY, MethodSpec, method_spec

__all__ = ["MethodSpec", "REGISTRY", "method_spec"]
