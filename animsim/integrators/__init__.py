"""Integrators behind one contract (:mod:`animsim.integrators.base`).

The name registry lives here, at the edge: the scene names a method once,
the compiler turns it into a class, and the loop never sees a string.
"""

from __future__ import annotations

from animsim.integrators.base import Integrator
from animsim.integrators.runge_kutta import RK4, Euler, Heun, Midpoint
from animsim.integrators.symplectic import EulerAverage, SymplecticEuler, Verlet

REGISTRY: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (Euler, SymplecticEuler, EulerAverage, Midpoint, Heun, RK4, Verlet)
}

#: the fixed-step methods, in the order the spec's table lists them
FIXED_STEP = ("euler", "symplectic_euler", "euler_average", "midpoint", "heun", "rk4", "verlet")


def register(cls: type[Integrator]) -> type[Integrator]:
    """Add a method to the registry (used by methods that live in their own module)."""
    REGISTRY[cls.name] = cls
    return cls


def integrator_class(name: str) -> type[Integrator]:
    return REGISTRY[name]


# Registered last: implicit.py imports the package's base module.
from animsim.integrators.implicit import ImplicitEuler  # noqa: E402

register(ImplicitEuler)
