"""The compiled model (static arrays) and the state that stepping changes.

Structure of arrays, named ``<entity>_<quantity>``. Particles are indexed in
creation order: listed particles first, then structures, then the emitter
pools, whose slots are dead until born.

The model (:class:`System`) is frozen once compiled: nothing writes it while
stepping. Whatever a run changes lives in :class:`State`, including the
masses of emitter pool slots, which births and deaths switch on and off.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class RigidShape(Protocol):
    """What every rigid body's shape answers, in its body frame about its centre of mass.

    The shapes themselves (Box, Sphere, Capsule) are the plain frozen dataclasses of
    animsim.bodies.shapes, a layer above this one, which the model does not import (not even
    for types, the layer contract counts those too): code that needs one kind narrows
    with ``isinstance`` against those classes.
    """

    @property
    def kind(self) -> str:
        """Its name: ``box``, ``sphere`` or ``capsule``."""
        ...

    @property
    def volume(self) -> float:
        """m^3."""
        ...

    @property
    def bounding_radius(self) -> float:
        """Of the smallest sphere about the centre of mass that holds the shape, m."""
        ...

    @property
    def thickness(self) -> float:
        """Its thinnest extent, m: what another body must cross to pass through it."""
        ...

    def inertia(self, mass: float) -> tuple[float, float, float]:
        """Principal moments along the body axes, kg m^2, for a uniform solid of ``mass``."""
        ...

    def contact_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) centres in the body frame and (K,) radii of the spheres contacts see."""
        ...

    def describe(self) -> str:
        """One line for ``explain`` (its kind and sizes)."""
        ...


@dataclass
class System:
    """What does not change during a run.

    particle_mass: (N,) kg; 0 for pinned particles and (initially dead) pool slots.
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
    # structure, so spring kernels can work on the grid by slices.
    structure_grids: list[tuple[int, tuple[int, ...], int, int]] = field(default_factory=list)
    # Rigid bodies (animsim.bodies): body b's centre of mass is particle row body_first + b,
    # with particle_mass = the body's mass (inverse 0 when pinned).
    body_first: int = 0
    body_count: int = 0
    body_ids: list[str] = field(default_factory=list)
    #: (B, 3) principal moments in the body frame, kg m^2; inverse 0 for pinned bodies
    body_inertia: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    body_inv_inertia: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: one plain frozen shape per body (animsim.bodies.shapes)
    body_shape: tuple[RigidShape, ...] = ()

    @property
    def body_rows(self) -> slice:
        return slice(self.body_first, self.body_first + self.body_count)

    @property
    def point_rows(self) -> np.ndarray:
        """(N,) bool: True for rows that are not bodies (particle-only machinery uses these)."""
        rows = np.ones(self.particle_count, dtype=bool)
        rows[self.body_rows] = False
        return rows

    @property
    def particle_count(self) -> int:
        return int(self.particle_mass.shape[0])

    @property
    def spring_count(self) -> int:
        return int(self.spring_index.shape[0])

    def freeze(self) -> None:
        """Make every array read-only: a write while stepping is a bug, and now an error."""
        for value in self.__dict__.values():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False


@dataclass
class State:
    """What a step changes.

    particle_position: (N, 3) m.   particle_velocity: (N, 3) m/s.
    time: s.   step: steps taken.
    particle_alive: (N,) bool, or None when the scene has no emitters (all alive).
    particle_mass, particle_inv_mass: (N,) the live masses (kg, 1/kg). Without
    emitters they are the model's own (read-only) arrays; with emitters the
    state owns copies that births and deaths change.
    revision: bumped whenever something outside the integrator changes the
    state (a collision, a birth), so integrators that cache a force know it is stale.
    """

    particle_position: np.ndarray
    particle_velocity: np.ndarray
    particle_mass: np.ndarray
    particle_inv_mass: np.ndarray
    time: float = 0.0
    step: int = 0
    particle_alive: np.ndarray | None = None
    revision: int = 0
    #: (S,) bool, False for a spring that tore; None unless some spring can tear
    spring_intact: np.ndarray | None = None
    #: (B, 4) unit quaternions [w, x, y, z], body to world; None without bodies
    body_orientation: np.ndarray | None = None
    #: (B, 3) angular velocities, world frame, rad/s; None without bodies
    body_angular_velocity: np.ndarray | None = None

    def copy(self) -> State:
        owns = self.particle_alive is not None  # only pools change masses
        return State(
            self.particle_position.copy(),
            self.particle_velocity.copy(),
            self.particle_mass.copy() if owns else self.particle_mass,
            self.particle_inv_mass.copy() if owns else self.particle_inv_mass,
            self.time,
            self.step,
            None if self.particle_alive is None else self.particle_alive.copy(),
            self.revision,
            None if self.spring_intact is None else self.spring_intact.copy(),
            None if self.body_orientation is None else self.body_orientation.copy(),
            None if self.body_angular_velocity is None else self.body_angular_velocity.copy(),
        )

    def assign(self, src: State) -> None:
        """Become ``src`` in place (arrays copied into this state's own, so references stay valid)."""
        # plain copies (slice assignment: cheaper to call than np.copyto, which a tiny
        # scene pays at every watchdog check)
        self.particle_position[...] = src.particle_position
        self.particle_velocity[...] = src.particle_velocity
        if self.particle_alive is not None and src.particle_alive is not None:
            np.copyto(self.particle_alive, src.particle_alive)
            np.copyto(self.particle_mass, src.particle_mass)
            np.copyto(self.particle_inv_mass, src.particle_inv_mass)
        if self.spring_intact is not None and src.spring_intact is not None:
            np.copyto(self.spring_intact, src.spring_intact)
        if self.body_orientation is not None and src.body_orientation is not None:
            np.copyto(self.body_orientation, src.body_orientation)
        if self.body_angular_velocity is not None and src.body_angular_velocity is not None:
            np.copyto(self.body_angular_velocity, src.body_angular_velocity)
        self.time, self.step, self.revision = src.time, src.step, src.revision


def kept_copies(kept: list[np.ndarray] | None, arrays: list[np.ndarray]) -> list[np.ndarray]:
    """Copies of ``arrays`` written into ``kept`` (the last call's copies) where their shapes
    and types still match, else made anew: a replay's snapshot of the books is taken at
    every passing check, and only the latest is ever restored, so its buffers are reused
    instead of allocating (and first touching) a fresh 100,000-slot array each time."""
    if kept is None or len(kept) != len(arrays):
        return [a.copy() for a in arrays]
    out = []
    for buf, a in zip(kept, arrays, strict=True):
        if buf.shape == a.shape and buf.dtype == a.dtype:
            np.copyto(buf, a)
            out.append(buf)
        else:
            out.append(a.copy())
    return out
