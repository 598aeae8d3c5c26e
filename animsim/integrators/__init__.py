"""Integrators behind one contract (:mod:`animsim.integrators.base`).

Which methods exist, and what each one is, is declared once in
:mod:`animsim.methods`; this module turns a method's name into the class that
steps it: the one tableau engine for an explicit Runge-Kutta method, or the
method's own stepper class, imported when its name is first looked up (a run
with another method never compiles implicit Euler's module, a few ms of every
command's start).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping
from typing import Any

from animsim import methods
from animsim.integrators.base import Integrator
from animsim.integrators.runge_kutta import runge_kutta_class


def _stepper(method: methods.Method) -> type[Integrator]:
    if method.tableau is not None:
        return runge_kutta_class(method)
    assert method.stepper is not None  # a Method without a tableau names its stepper
    cls = _load(method.stepper)
    if not (isinstance(cls, type) and issubclass(cls, Integrator)) or cls.method != method:
        raise TypeError(f"{method.stepper} does not step the method {method.name!r}")
    return cls


def spring_constraints(name: str) -> Callable[..., Any] | None:
    """The builder of the watchdog's energy term for the springs a method holds as
    constraints (Method.spring_constraints: (system, label, dt, substeps) -> term), or None
    when its springs are forces."""
    path = methods.get(name).spring_constraints
    if path is None:
        return None
    built: Callable[..., Any] = _load(path)
    return built


def _load(path: str) -> Any:
    """The object a descriptor names as "module:name", imported when first asked for."""
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


class _Methods(Mapping[str, type[Integrator]]):
    """Method name -> the class that steps it, for every method in :mod:`animsim.methods`."""

    def __init__(self) -> None:
        self._classes: dict[methods.Method, type[Integrator]] = {}

    def __getitem__(self, name: str) -> type[Integrator]:
        method = methods.get(name)
        cls = self._classes.get(method)
        if cls is None:
            cls = self._classes[method] = _stepper(method)
        return cls

    def __iter__(self) -> Iterator[str]:
        return iter(methods.names())

    def __len__(self) -> int:
        return len(methods.names())

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in methods.names()


REGISTRY = _Methods()


def listed_methods() -> tuple[str, ...]:
    """The methods ``compare`` and the parity tests run by default, in table order."""
    return tuple(m.name for m in methods.all_methods() if m.listed)


#: the listed methods as the package was imported (test tables parametrize over it)
FIXED_STEP = listed_methods()


def integrator_class(name: str) -> type[Integrator]:
    return REGISTRY[name]
