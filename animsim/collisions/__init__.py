"""Impulse collisions with infinite one-sided planes, and the response rules contacts share.

* :mod:`~animsim.collisions.stage`: the step stage (:class:`PlaneColliders`, Lander's rule
  with the time of impact inside the step), its meeting of a block of rows inside the
  integrator's step, and the builder of the scene's planes (penalty planes become forces);
* :mod:`~animsim.collisions.numpy_rule`: the rule in NumPy, a block of contact rows at a time;
* :mod:`~animsim.collisions.kernels`: the rule as numba kernels, row by row, to the same bits;
* :mod:`~animsim.collisions.response`: what a bounce keeps (e^2 of the energy the method
  conserves), when a contact rests, and Coulomb friction; planes, solid colliders and rigid
  bodies share them.

The names other modules use are handed on here.
"""

from __future__ import annotations

from animsim.collisions.numpy_rule import ImpulsePlane
from animsim.collisions.response import (
    RESTING_STEPS,
    apply_friction,
    energy_shift,
    hold_by_static_friction,
    kept_bounce_speed,
    kept_end_speed,
    static_friction_holds,
)
from animsim.collisions.stage import PlaneColliders

__all__ = [
    "RESTING_STEPS",
    "ImpulsePlane",
    "PlaneColliders",
    "apply_friction",
    "energy_shift",
    "hold_by_static_friction",
    "kept_bounce_speed",
    "kept_end_speed",
    "static_friction_holds",
]
