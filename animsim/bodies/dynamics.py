"""The rotational half of rigid-body dynamics, beside the engine's particle dynamics.

A body's centre of mass is a particle row, so forces on it (gravity, drag, wind,
attractors, turbulence) and its translation need nothing here. What is added:
forces that act at points of bodies (:class:`animsim.bodies.springs.BodySprings`),
whose torques about the centres of mass drive

    omega' = I_w^-1 (tau - omega x (I_w omega)),    q' = 1/2 (0, omega) (x) q

(Baraff 1997, :mod:`animsim.bodies.quaternion`), and the rotational energy.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from animsim.bodies import quaternion as quat


class BodyDynamics:
    """Accelerations (linear and angular) of a scene with bodies."""

    def __init__(self, system: Any, terms: Sequence[Any], backend: str = "numpy") -> None:
        self.system = system
        self.rows = system.body_rows
        self.count = system.body_count
        self.inertia = np.ascontiguousarray(system.body_inertia, dtype=np.float64)
        self.inv_inertia = np.ascontiguousarray(system.body_inv_inertia, dtype=np.float64)
        self.terms = tuple(terms)
        self._force = np.zeros((system.particle_count, 3))
        self._torque = np.zeros((self.count, 3))
        self._no_spin = np.zeros((self.count, 3))
        self.numba = backend == "numba"

    def accelerations(
        self,
        dynamics: Any,
        x: np.ndarray,
        v: np.ndarray,
        q: np.ndarray,
        w: np.ndarray,
        t: float,
        a_out: np.ndarray,
        alpha_out: np.ndarray,
        gyroscopic: bool = True,
    ) -> None:
        """a (N,3) and the bodies' angular accelerations (B,3) at (x, v, q, w, t), into the outs.

        The particle forces go through ``dynamics.acceleration`` (so evaluations are counted and
        the numba backend's kernels run); forces at points of bodies are added on top. With
        ``gyroscopic`` False the angular acceleration is the torques' part alone, I_w^-1 tau
        (for an integrator that advances the free rotation itself).
        """
        dynamics.acceleration(x, v, t, a_out)
        torque = self._torque
        torque.fill(0.0)
        if self.terms:
            f = self._force
            f.fill(0.0)
            for term in self.terms:
                term.accumulate_bodies(x, v, q, w, t, f, torque)
            a_out += f * dynamics.inv_mass[:, None]
        spin = w if gyroscopic else self._no_spin
        if self.numba:
            quat.numba_angular_acceleration()(
                np.ascontiguousarray(q),
                np.ascontiguousarray(spin),
                self.inertia,
                self.inv_inertia,
                torque,
                alpha_out,
            )
        else:
            alpha_out[:] = quat.angular_acceleration(q, spin, self.inertia, self.inv_inertia, torque)

    def rotational_energy(self, q: np.ndarray, w: np.ndarray) -> float:
        """sum 1/2 omega . I_w omega over free bodies (pinned ones are driven, as pinned particles)."""
        free = self.inv_inertia[:, 0] > 0
        return float(np.sum(quat.rotational_energy(q, w, self.inertia)[free]))

    def rotational_energy_per_body(self, q: np.ndarray, w: np.ndarray) -> np.ndarray:
        return quat.rotational_energy(q, w, self.inertia)

    def potential(self, x: np.ndarray, q: np.ndarray) -> float:
        """Stored energy of the forces at points of bodies (springs)."""
        return float(sum(t.potential_bodies(x, q) for t in self.terms))

    def angular_momentum(
        self, x: np.ndarray, v: np.ndarray, q: np.ndarray, w: np.ndarray, mass: np.ndarray
    ) -> np.ndarray:
        """Total angular momentum about the origin: sum of x_b x m_b v_b + I_w omega_b over bodies
        (plus particles' x x m v, so springs between bodies and particles conserve it)."""
        spin = quat.angular_momentum(q, w, self.inertia)
        orbital = np.cross(x, mass[:, None] * v).sum(axis=0)
        return orbital + spin.sum(axis=0)
