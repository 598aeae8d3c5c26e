"""The right-hand side every integrator sees: a(x, v, t) = F(x, v, t) / m.

It sums the scene's force terms (only those it uses) and counts evaluations,
the machine-independent cost that ``compare`` reports.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from animsim.forces import ForceTerm
from animsim.system import System


class Dynamics:
    def __init__(self, system: System, terms: Sequence[ForceTerm]):
        self.system = system
        self.terms = tuple(terms)
        self.evaluations = 0
        self._force = np.zeros((system.particle_count, 3))
        # Pinned particles are driven, never pushed: an infinite force on one
        # times its zero inverse mass would be NaN and poison a moving anchor.
        self._pinned = np.flatnonzero(system.particle_pinned)

    def force(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        out.fill(0.0)
        for term in self.terms:
            term.accumulate(x, v, t, out)
        return out

    def acceleration(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        """Write a = F/m into ``out``; pinned particles and dead slots get 0 (inverse mass 0)."""
        self.evaluations += 1
        self.force(x, v, t, out)
        inv_mass = self.system.particle_inv_mass
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
        m = np.where(self.system.particle_inv_mass > 0, self.system.particle_mass, 0.0)
        return float(0.5 * np.dot(m, np.einsum("ij,ij->i", v, v)))

    def energy(self, x: np.ndarray, v: np.ndarray) -> float:
        return self.kinetic_energy(v) + self.potential_energy(x)

    @property
    def conservative(self) -> bool:
        """True when no term dissipates or injects energy (all have a potential)."""
        zero = np.zeros((self.system.particle_count, 3))
        return all(term.potential(zero) is not None for term in self.terms) and not any(
            getattr(term, "has_damping", False) for term in self.terms
        )
