"""The right-hand side every integrator sees: a(x, v, t) = F(x, v, t) / m.

It sums the scene's force elements (only those it uses) and counts
evaluations, the machine-independent cost that ``compare`` reports. Masses
are the live ones of the run's state (:meth:`bind`): pool births switch them on.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from animsim.elements import DISSIPATIVE, ELASTIC, RELEASING, ForceElement
from animsim.system import System


class Dynamics:
    def __init__(self, system: System, terms: Sequence[ForceElement]):
        self.system = system
        self.terms = tuple(terms)
        self.evaluations = 0
        self.mass = system.particle_mass
        self.inv_mass = system.particle_inv_mass
        # Pinned particles are driven, never pushed: an infinite force on one
        # times its zero inverse mass would be NaN and poison a moving anchor.
        self._pinned = np.flatnonzero(system.particle_pinned)
        #: keyframe drives (animsim.keyframes.KeyframeDrive): driven rows are put on their
        #: path before every force evaluation, so springs to them see the path inside a step
        self.drivers: tuple[Any, ...] = ()

    def bind(self, state: Any) -> None:
        """Use ``state``'s live masses, and hand it to every element that reads state arrays."""
        self.mass = state.particle_mass
        self.inv_mass = state.particle_inv_mass
        for term in self.terms:
            term.bind(state)

    def force(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        out.fill(0.0)
        for term in self.terms:
            term.accumulate(x, v, t, out)
        return out

    def acceleration(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        """Write a = F/m into ``out``; pinned particles and dead slots get 0 (inverse mass 0)."""
        self.evaluations += 1
        for drive in self.drivers:
            drive.drive(t, x, v)
        self.force(x, v, t, out)
        inv_mass = self.inv_mass
        for j in range(out.shape[1]):  # per column: much faster than broadcasting (N, 1)
            out[:, j] *= inv_mass
        if len(self._pinned):
            out[self._pinned] = 0.0
        return out

    def potential_energy(self, x: np.ndarray) -> float:
        total = 0.0
        for term in self.terms:
            u = term.potential(x)
            if u is not None:
                total += u
        return total

    def kinetic_energy(self, v: np.ndarray) -> float:
        # Pinned particles are driven, not dynamic: they carry no kinetic energy here.
        m = np.where(self.inv_mass > 0, self.mass, 0.0)
        return float(0.5 * np.dot(m, np.einsum("ij,ij->i", v, v)))

    def energy(self, x: np.ndarray, v: np.ndarray) -> float:
        return self.kinetic_energy(v) + self.potential_energy(x)

    @property
    def has_damping(self) -> bool:
        return any(term.has_damping for term in self.terms)

    @property
    def conservative(self) -> bool:
        """True when every term is conservative (elastic or releasing) and none damps."""
        return all(t.watch_role in (ELASTIC, RELEASING) for t in self.terms) and not self.has_damping

    @property
    def dissipative_only(self) -> bool:
        """Every non-conservative term only removes energy."""
        return all(t.watch_role in (ELASTIC, RELEASING, DISSIPATIVE) for t in self.terms)
