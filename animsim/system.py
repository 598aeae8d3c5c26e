"""The compiled system: static arrays, and the state that changes.

Structure of arrays, named ``<entity>_<quantity>``. Particles are indexed in
creation order: listed particles first, then structures, then the emitter
pools (issue 3), whose slots are dead until born.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class System:
    """What does not change during a step (pools may change it between steps).

    particle_mass: (N,) kg; 0 for pinned particles and dead pool slots.
    particle_inv_mass: (N,) 1/kg; 0 for pinned and dead slots, so no force moves them.
    particle_pinned: (N,) bool.
    spring_index: (S, 2) int64 particle indices (a, b).
    spring_rest_length: (S,) m.
    spring_ks: (S,) N/m.   spring_kd: (S,) N*s/m.
    """

    ids: list[str]
    particle_mass: np.ndarray
    particle_inv_mass: np.ndarray
    particle_pinned: np.ndarray
    spring_index: np.ndarray
    spring_rest_length: np.ndarray
    spring_ks: np.ndarray
    spring_kd: np.ndarray
    # (family label, first spring, end spring): contiguous runs of generated springs.
    spring_families: list[tuple[str, int, int]] = field(default_factory=list)
    # (first particle, grid shape, first family, end family) of each generated
    # structure, so spring kernels can work on the grid by slices (issue 8).
    structure_grids: list[tuple[int, tuple[int, ...], int, int]] = field(default_factory=list)

    @property
    def particle_count(self) -> int:
        return int(self.particle_mass.shape[0])

    @property
    def spring_count(self) -> int:
        return int(self.spring_index.shape[0])


@dataclass
class State:
    """What a step changes.

    particle_position: (N, 3) m.   particle_velocity: (N, 3) m/s.
    time: s.   step: steps taken.
    particle_alive: (N,) bool, or None when the scene has no emitters (all alive).
    revision: bumped whenever something outside the integrator changes the
    state (a collision, a birth), so integrators that cache a force know it is stale.
    """

    particle_position: np.ndarray
    particle_velocity: np.ndarray
    time: float = 0.0
    step: int = 0
    particle_alive: np.ndarray | None = None
    revision: int = 0

    def copy(self) -> State:
        return State(
            self.particle_position.copy(),
            self.particle_velocity.copy(),
            self.time,
            self.step,
            None if self.particle_alive is None else self.particle_alive.copy(),
            self.revision,
        )
