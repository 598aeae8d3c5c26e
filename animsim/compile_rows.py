"""The rows a scene compiles to, and the frozen :class:`~animsim.system.System` they make.

Particle rows come in this order: the listed particles, each structure's, each rigid
body's centre of mass, then the emitter pools' slots (dead at the start). Spring rows:
the listed springs between two particles, then each structure's families. Ids become
indices here, once; structures expand here. :func:`animsim.compile.compile_scene` calls
:func:`gather_particles`, :func:`gather_springs`, :func:`emitter_pools`,
:func:`particle_arrays` and :func:`make_system`, in that order.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.bodies.build import BodyRows, body_rows, particle_springs
from animsim.emitters import Emitters, build_emitters
from animsim.scene import models as m
from animsim.scene.structures import Expanded, expand
from animsim.system import System


@dataclass
class ParticleRows:
    """The fixed particle rows as they are gathered, in row order, before they become arrays."""

    ids: list[str] = field(default_factory=list)
    index_of: dict[str, int] = field(default_factory=dict)
    position: list[np.ndarray] = field(default_factory=list)  # (n, 3) m per part
    velocity: list[np.ndarray] = field(default_factory=list)  # (n, 3) m/s per part
    mass: list[np.ndarray] = field(default_factory=list)  # (n,) kg per part
    pinned: list[np.ndarray] = field(default_factory=list)  # (n,) bool per part
    #: each structure with its expansion and its first row
    structures: list[tuple[m.Structure, Expanded, int]] = field(default_factory=list)
    bodies: BodyRows | None = None  # when the scene has rigid bodies
    body_first: int = 0  # the first body's row (when there are bodies)

    def append(
        self,
        ids: list[str],
        position: np.ndarray,
        velocity: np.ndarray,
        mass: np.ndarray,
        pinned: np.ndarray,
    ) -> int:
        """Add the rows of ``ids`` after those gathered so far; the first of them."""
        first = len(self.ids)
        for k, pid in enumerate(ids):
            self.index_of[pid] = first + k
        self.ids.extend(ids)
        self.position.append(position)
        self.velocity.append(velocity)
        self.mass.append(mass)
        self.pinned.append(pinned)
        return first


@dataclass
class SpringRows:
    """The spring rows as they are gathered, family by family, before they become arrays."""

    pairs: list[np.ndarray] = field(default_factory=list)  # (k, 2) int64 rows per family
    ks: list[np.ndarray] = field(default_factory=list)  # N/m
    kd: list[np.ndarray] = field(default_factory=list)  # N*s/m
    rest: list[np.ndarray] = field(default_factory=list)  # m; NaN: auto (the distance at the start)
    #: (family label, first spring, end spring)
    families: list[tuple[str, int, int]] = field(default_factory=list)
    #: (first particle, grid shape, first family, end family) of each structure
    grids: list[tuple[int, tuple[int, ...], int, int]] = field(default_factory=list)
    count: int = 0

    def append(
        self, family: str, pairs: np.ndarray, ks: np.ndarray, kd: np.ndarray, rest: np.ndarray
    ) -> None:
        """Add one family of springs after those gathered so far."""
        k = len(pairs)
        self.pairs.append(pairs)
        self.ks.append(ks)
        self.kd.append(kd)
        self.rest.append(rest)
        self.families.append((family, self.count, self.count + k))
        self.count += k


@dataclass(frozen=True)
class Particles:
    """The particle arrays at the start, emitter pools included."""

    position: np.ndarray  # (N, 3) m
    velocity: np.ndarray  # (N, 3) m/s
    mass: np.ndarray  # (N,) kg; 0 where pinned and in pool slots
    inv_mass: np.ndarray  # (N,) 1/kg; 0 where the mass is 0
    pinned: np.ndarray  # (N,) bool
    alive: np.ndarray | None  # (N,) bool when the scene has emitters, else None (all alive)


def gather_particles(scene: m.Scene) -> ParticleRows:
    """The listed particles, then each structure's, then each rigid body's centre of mass."""
    rows = ParticleRows()
    rows.append(
        [p.id for p in scene.particles],  # type: ignore[misc]  # m.Id validates to str
        np.array([p.position for p in scene.particles], dtype=np.float64).reshape(-1, 3),
        np.array([p.velocity for p in scene.particles], dtype=np.float64).reshape(-1, 3),
        np.array([p.mass or 0.0 for p in scene.particles], dtype=np.float64),
        np.array([p.pinned for p in scene.particles], dtype=bool),
    )
    for s in scene.structures:
        e = expand(s)
        first = rows.append(e.ids, e.position, e.velocity, e.mass, e.pinned)
        rows.structures.append((s, e, first))
    if scene.bodies:
        bodies = body_rows(scene)
        rows.bodies = bodies
        rows.body_first = rows.append(
            bodies.ids, bodies.position, bodies.velocity, bodies.mass, bodies.pinned
        )
    return rows


def listed_springs(scene: m.Scene) -> list[Any]:
    """Springs between two particles (springs to points of bodies are the bodies' element)."""
    if not scene.bodies:
        return list(scene.springs)
    return particle_springs(scene)


def gather_springs(scene: m.Scene, rows: ParticleRows) -> SpringRows:
    """The listed springs between two particles, then each structure's families."""
    springs = SpringRows()
    listed = listed_springs(scene)
    if listed:
        pairs = np.array(
            [[rows.index_of[a], rows.index_of[b]] for a, b in (sp.between for sp in listed)], dtype=np.int64
        )
        springs.append(
            "listed springs",
            pairs,
            np.array([sp.ks for sp in listed]),
            np.array([sp.kd for sp in listed]),
            np.array([np.nan if sp.rest == "auto" else sp.rest for sp in listed]),
        )
    for _, e, first in rows.structures:
        springs.grids.append(
            (first, e.grid_shape, len(springs.families), len(springs.families) + len(e.springs))
        )
        for group in e.springs:
            k = len(group.index)
            springs.append(
                group.family,
                group.index + first,
                np.full(k, group.ks),
                np.full(k, group.kd),
                np.full(k, np.nan),
            )
    return springs


def emitter_pools(scene: m.Scene, first_index: int, left_out: list[str]) -> Emitters | None:
    """The scene's emitters, their pools starting at row ``first_index`` (after every fixed
    particle), or None (said in ``left_out``)."""
    if not scene.emitters:
        left_out.append("emitters: no births, deaths, ageing or over-life attributes")
        return None
    return build_emitters(scene, first_index=first_index)


def particle_arrays(rows: ParticleRows, emitters: Emitters | None) -> Particles:
    """The fixed rows as arrays, followed by the emitters' pool slots (dead, massless)."""
    fixed_count = len(rows.ids)
    position = np.concatenate(rows.position) if rows.position else np.zeros((0, 3))
    velocity = np.concatenate(rows.velocity) if rows.velocity else np.zeros((0, 3))
    mass = np.concatenate(rows.mass)
    pinned = np.concatenate(rows.pinned)
    alive = None
    if emitters is not None:
        extra = emitters.capacity
        position = np.concatenate([position, np.zeros((extra, 3))])
        velocity = np.concatenate([velocity, np.zeros((extra, 3))])
        mass = np.concatenate([mass, np.zeros(extra)])
        pinned = np.concatenate([pinned, np.zeros(extra, dtype=bool)])
        alive = np.concatenate([np.ones(fixed_count, dtype=bool), np.zeros(extra, dtype=bool)])

    mass = np.where(pinned, 0.0, mass)
    with np.errstate(divide="ignore"):
        inv_mass = np.where(mass > 0, 1.0 / np.where(mass > 0, mass, 1.0), 0.0)
    return Particles(position, velocity, mass, inv_mass, pinned, alive)


def spring_arrays(
    springs: SpringRows, position: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(index (S, 2), rest length, ks, kd) of every spring; an auto rest length is the
    springs' length at ``position``."""
    if not springs.pairs:
        empty = np.zeros(0)  # read-only once the System is frozen: the three may share it
        return np.zeros((0, 2), dtype=np.int64), empty, empty, empty
    index = np.concatenate(springs.pairs)
    rest = np.concatenate(springs.rest)
    auto = np.isnan(rest)
    d = position[index[auto, 0]] - position[index[auto, 1]]
    rest[auto] = np.sqrt(np.einsum("ij,ij->i", d, d))
    return index, rest, np.concatenate(springs.ks), np.concatenate(springs.kd)


def make_system(rows: ParticleRows, particles: Particles, springs: SpringRows) -> System:
    """The frozen :class:`System`: masses, springs, structure grids and the bodies' arrays."""
    spring_index, rest, ks, kd = spring_arrays(springs, particles.position)
    system = System(
        ids=rows.ids,
        particle_mass=particles.mass,
        particle_inv_mass=particles.inv_mass,
        particle_pinned=particles.pinned,
        spring_index=spring_index,
        spring_rest_length=rest,
        spring_ks=ks,
        spring_kd=kd,
        spring_families=springs.families,
        structure_grids=springs.grids,
    )
    bodies = rows.bodies
    if bodies is not None:
        system.body_first = rows.body_first
        system.body_count = len(bodies.ids)
        system.body_ids = list(bodies.ids)
        system.body_inertia = bodies.inertia
        system.body_inv_inertia = bodies.inv_inertia
        system.body_shape = bodies.shapes
    system.freeze()
    return system
