"""The reconstruction methods and their registry: each method is a function
``run(model, protocol, targets, *, options, progress) -> Reconstruction`` with one frozen options
dataclass, and its streaming form ``stream(model, protocol, targets, sink, *, options, progress,
chunk_frames) -> (timings_s, info)`` that hands the result to ``sink`` in chunks
(exubio.methods.common). The registry names them for the pipeline, the CLI and the API; a method's module (and
with PF, Exudyn) is imported only when the method is used."""
from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from typing import Any, Callable

from exubio.errors import InputError

__all__ = ["MethodSpec", "REGISTRY", "method_spec"]


@dataclass(frozen=True)
class MethodSpec:
    name: str
    description: str
    module: str
    options: str  # the options dataclass in ``module``
    function: str  # the reconstruction function in ``module``
    stream: str  # the same, handing the result to a sink in chunks: (timings_s, info)

    def load(self) -> tuple[type, Callable[..., Any]]:
        mod = importlib.import_module(self.module)
        return getattr(mod, self.options), getattr(mod, self.function)

    def load_stream(self) -> Callable[..., Any]:
        return getattr(importlib.import_module(self.module), self.stream)

    def make_options(self, values: "dict[str, Any] | Any" = None) -> Any:
        """The method's options from keyword values (or an options object, checked to be this
        method's type); an unknown key is an InputError naming it and the valid ones."""
        options_type, _ = self.load()
        if values is None:
            return options_type()
        if dataclasses.is_dataclass(values) and not isinstance(values, type):
            if not isinstance(values, options_type):
                raise InputError(f"method {self.name}: options of type {type(values).__name__} given; "
                                 f"expected {options_type.__name__}")
            return values
        fields = {f.name for f in dataclasses.fields(options_type)}
        unknown = sorted(set(values) - fields)
        if unknown:
            raise InputError(f"method {self.name}: unknown option(s) {unknown}; its options are {sorted(fields)}")
        return options_type(**values)


REGISTRY: dict[str, MethodSpec] = {
    "pf": MethodSpec("pf", "potential field: marker springs and dampers, forward dynamics on Exudyn",
                     "exubio.methods.pf", "PFOptions", "reconstruct_pf", "stream_pf"),
    "ls": MethodSpec("ls", "constrained least squares per frame (the paper's reference)",
                     "exubio.methods.ls", "LSOptions", "reconstruct_ls", "stream_ls"),
}


def method_spec(name: str) -> MethodSpec:
    try:
        return REGISTRY[str(getattr(name, "value", name))]
    except KeyError:
        raise InputError(f"unknown method '{name}'; valid methods are {sorted(REGISTRY)}") from None
