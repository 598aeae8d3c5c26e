"""What the named integrator really computes on a scene, when that is another method.

Backward Euler here is linearised with the Jacobians of the forces that offer
them (springs, penalty planes, drag, wind; Baraff and Witkin 1998, Eq. 6).
Gravity, attractors and turbulence enter explicitly. With no force that has a
Jacobian the linear system is M dv = dt f: v += dt a(t); x += dt v(t + dt),
which is symplectic Euler step for step (same arithmetic, same results).
A user who asked for an implicit method must be told.
"""

from __future__ import annotations

# ``compiled`` below is animsim.compile.Compiled: Any, since measures may not import compile (layers)
from typing import Any

from animsim import methods


def effective_integrator(compiled: Any) -> str:
    """The method the run's steps amount to on this scene (usually the one named): an implicit
    method with no implicit term computes its declared explicit fallback."""
    name: str = compiled.integrator_name
    fallback = methods.get(name).explicit_fallback
    if fallback is not None and not compiled.integrator.implicit_terms:
        return fallback
    return name


def fallback_note(compiled: Any) -> str | None:
    """One line saying that the named integrator runs as another method here, or None."""
    effective = effective_integrator(compiled)
    if effective == compiled.integrator_name:
        return None
    return (
        f"{compiled.integrator_name} runs as {effective} on this scene: no force has a Jacobian "
        "(gravity, attractors and turbulence are explicit), so each step is v += dt*a(t); "
        "x += dt*v(t+dt)"
    )
