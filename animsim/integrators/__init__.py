"""Integrators behind one contract (:mod:`animsim.integrators.base`).

The name registry lives here, at the edge: the scene names a method once,
the compiler turns it into a class, and the loop never sees a string.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping

from animsim.integrators.base import Integrator
from animsim.integrators.runge_kutta import RK4, Euler, Heun, Midpoint
from animsim.integrators.symplectic import EulerAverage, SymplecticEuler, Verlet


class _Methods(Mapping[str, type[Integrator]]):
    """Method name -> class. A method in a module of its own (implicit Euler, whose module
    is the largest) is imported when its name is first looked up: a run with another
    method never compiles that module's source (a few ms of every command's start)."""

    def __init__(self, classes: tuple[type[Integrator], ...], elsewhere: dict[str, str]):
        self._classes = {cls.name: cls for cls in classes}
        self._elsewhere = elsewhere

    def add(self, cls: type[Integrator]) -> None:
        self._classes[cls.name] = cls

    def __getitem__(self, name: str) -> type[Integrator]:
        if name not in self._classes and name in self._elsewhere:
            importlib.import_module(self._elsewhere[name])  # the module registers its class
        return self._classes[name]

    def __iter__(self) -> Iterator[str]:
        yield from self._classes
        yield from (name for name in self._elsewhere if name not in self._classes)

    def __len__(self) -> int:
        return len(self._classes.keys() | self._elsewhere.keys())

    def __contains__(self, name: object) -> bool:
        return name in self._classes or name in self._elsewhere


REGISTRY = _Methods(
    (Euler, SymplecticEuler, EulerAverage, Midpoint, Heun, RK4, Verlet),
    {"implicit_euler": "animsim.integrators.implicit", "xpbd": "animsim.integrators.xpbd"},
)

#: the fixed-step methods, in the order the spec's table lists them
FIXED_STEP = ("euler", "symplectic_euler", "euler_average", "midpoint", "heun", "rk4", "verlet")


def register(cls: type[Integrator]) -> type[Integrator]:
    """Add a method to the registry (used by methods that live in their own module)."""
    REGISTRY.add(cls)
    return cls


def integrator_class(name: str) -> type[Integrator]:
    return REGISTRY[name]
