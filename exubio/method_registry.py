"""The list of reconstruction methods: their names, what they are, where their code is, and how the
outputs show them. Everything that names the methods (the CLI's choices, a study file's ``methods``,
the study table's columns, the reports' line styles, the viewer) reads this one list, so adding a
method is one module (``run``, ``stream`` and an options dataclass, see exubio.methods) and one line
in ``REGISTRY``. A method's module (and with PF, Exudyn) is imported only when the method is used:
the list names it by its import path, so this module imports nothing of the solvers and sits in the
lowest layer, beside exubio.types, where the report may read it."""
from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from typing import Any, Callable

from exubio.errors import InputError

__all__ = ["Method", "MethodSpec", "Style", "REGISTRY", "method_spec", "method_names", "method_style"]


@dataclass(frozen=True)
class Style:
    """How the outputs draw and name a method: a short label ("PF"), a title, and its line in the
    report's figures (matplotlib colour, line style, width, alpha)."""

    label: str
    title: str
    colour: str = "tab:blue"
    linestyle: Any = "-"
    linewidth: float = 1.5
    alpha: float = 1.0


@dataclass(frozen=True)
class MethodSpec:
    name: str
    description: str
    module: str
    options: str  # the options dataclass in ``module``
    function: str  # the reconstruction function in ``module``
    stream: str  # the same, handing the result to a sink in chunks: (timings_s, info)
    style: Style = Style("?", "?")

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
                     "exubio.methods.pf", "PFOptions", "reconstruct_pf", "stream_pf",
                     Style("PF", "PF (potential field)", "black", "-", 2.0, 0.75)),
    "ls": MethodSpec("ls", "constrained least squares per frame (the paper's reference)",
                     "exubio.methods.ls", "LSOptions", "reconstruct_ls", "stream_ls",
                     Style("LS", "LS (least squares)", "tab:red", (0, (4, 2)), 1.1, 1.0)),
}


def method_spec(name: str) -> MethodSpec:
    try:
        return REGISTRY[str(getattr(name, "value", name))]
    except KeyError:
        raise InputError(f"unknown method '{name}'; valid methods are {sorted(REGISTRY)}") from None


def method_names() -> tuple[str, ...]:
    """The methods' names in the registry's order (pf, ls, then any added)."""
    return tuple(REGISTRY)


def method_style(name: str) -> Style:
    """A method's style; a name the registry does not know (an old result file) gets a plain one."""
    spec = REGISTRY.get(str(name))
    return spec.style if spec is not None else Style(str(name).upper(), str(name).upper())


class Method(str):
    """A reconstruction method's name, one of exubio.method_registry.REGISTRY ("pf", "ls", and any
    method added there); prints and formats as the name. ``Method.PF`` and ``Method.LS`` are the two
    shipped."""

    PF: "Method"
    LS: "Method"

    @property
    def value(self) -> str:
        return str.__str__(self)

    def __repr__(self) -> str:
        return f"Method({str.__str__(self)!r})"

    @classmethod
    def parse(cls, value: "str | Method") -> "Method":
        return cls(method_spec(str(getattr(value, "value", value))).name)


Method.PF, Method.LS = Method("pf"), Method("ls")
