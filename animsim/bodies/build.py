"""Compile-time glue: scene bodies -> particle rows, body arrays and the body elements.

This is the only module of the package that reads the pydantic scene models.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.bodies import shapes as sh
from animsim.bodies.contact_detection import PlaneTable
from animsim.bodies.contacts import BodyContacts
from animsim.bodies.dynamics import BodyDynamics
from animsim.bodies.particles import ParticleBodyContacts
from animsim.bodies.sleep import Sleep
from animsim.bodies.springs import BodySprings
from animsim.elements import ForceElement, PlaneProjector, StepStage
from animsim.scene import models as m
from animsim.system import System


class SolidShape(Protocol):
    """What the bodies read of a collider shape (animsim.colliders.Shape)."""

    @property
    def restitution(self) -> float: ...

    @property
    def friction(self) -> float: ...

    @property
    def thickness(self) -> float: ...

    def signed_distance(
        self, x: np.ndarray, offset: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]: ...


class SolidColliders(Protocol):
    """What the bodies read of the scene's colliders stage (animsim.colliders.Colliders), a
    sibling package the bodies may not import."""

    @property
    def shapes(self) -> Sequence[SolidShape]: ...

    @property
    def injects(self) -> bool: ...

    def offsets(self, t: float) -> np.ndarray: ...


def has_body_end(spring: m.Spring) -> bool:
    return any(isinstance(e, m.BodyPoint) for e in spring.between)


def particle_springs(scene: m.Scene) -> list[m.Spring]:
    """The springs between two particles (the engine's spring element takes these)."""
    return [sp for sp in scene.springs if not has_body_end(sp)]


@dataclass(frozen=True)
class BodyRows:
    """The bodies as particle rows plus their rotational state, in scene order."""

    ids: list[str]
    position: np.ndarray  # (B, 3)
    velocity: np.ndarray  # (B, 3)
    mass: np.ndarray  # (B,)
    pinned: np.ndarray  # (B,) bool
    orientation: np.ndarray  # (B, 4)
    angular_velocity: np.ndarray  # (B, 3)
    inertia: np.ndarray  # (B, 3)
    inv_inertia: np.ndarray  # (B, 3), 0 for pinned
    shapes: tuple[sh.BodyShape, ...]


def orientation_of(body: m.Body) -> np.ndarray:
    o = body.orientation
    if isinstance(o, m.AxisAngle):
        return quat.from_axis_angle(np.array(o.axis), math.radians(o.angle))
    q = np.array(o, dtype=np.float64)
    return q / np.linalg.norm(q)


def body_rows(scene: m.Scene) -> BodyRows:
    bodies = scene.bodies
    shapes = tuple(sh.from_model(b.shape) for b in bodies)
    mass = np.array(
        [b.mass if b.mass is not None else b.density * s.volume for b, s in zip(bodies, shapes, strict=True)],
        dtype=np.float64,
    ).reshape(-1)
    inertia = np.array(
        [
            b.inertia if b.inertia is not None else s.inertia(mm)
            for b, s, mm in zip(bodies, shapes, mass, strict=True)
        ],
        dtype=np.float64,
    ).reshape(-1, 3)
    pinned = np.array([b.pinned for b in bodies], dtype=bool)
    inv_inertia = np.where(pinned[:, None], 0.0, 1.0 / np.where(inertia > 0, inertia, 1.0))
    return BodyRows(
        ids=[b.id for b in bodies],
        position=np.array([b.position for b in bodies], dtype=np.float64).reshape(-1, 3),
        velocity=np.array([b.velocity for b in bodies], dtype=np.float64).reshape(-1, 3),
        mass=mass,
        pinned=pinned,
        orientation=np.array([orientation_of(b) for b in bodies], dtype=np.float64).reshape(-1, 4),
        angular_velocity=np.array([b.angular_velocity for b in bodies], dtype=np.float64).reshape(-1, 3),
        inertia=inertia,
        inv_inertia=inv_inertia,
        shapes=shapes,
    )


def build_body_elements(
    scene: m.Scene,
    system: System,
    index_of: dict[str, int],
    x0: np.ndarray,
    q0: np.ndarray,
    backend: str,
    solid: SolidColliders | None = None,
    radius: np.ndarray | None = None,
    planes_stage: PlaneProjector | None = None,
    forces: Sequence[ForceElement] = (),
) -> tuple[BodyDynamics, list[StepStage], list[str], list[str]]:
    """(rotational dynamics, post-step stages, labels for explain, left-out notes for explain).

    ``solid``: the scene's colliders stage (animsim.colliders.Colliders), whose shapes and
    keyframed motion the bodies meet as the particles do. ``radius``: every row's contact
    radius (animsim.contact_stages); ``planes_stage``: the impulse planes, which particles
    pushed out of a body are kept in front of; ``forces``: the scene's force elements (which
    of them let bodies sleep, when the scene has ``sleep``)."""
    body_index = {bid: b for b, bid in enumerate(system.body_ids)}
    labels: list[str] = []
    left_out: list[str] = []
    springs = _body_springs(scene, system, index_of, body_index)
    if springs is not None:
        auto_rest(springs, scene, x0, q0)
    terms = [springs] if springs is not None else []
    if springs is not None:
        labels.append(springs.label)
    dyn = BodyDynamics(system, terms, backend)
    labels.append(
        f"rigid bodies: {system.body_count} ({', '.join(s.describe() for s in system.body_shape[:4])}"
        + (", ..." if system.body_count > 4 else "")
        + "); omega' = I_w^-1 (tau - omega x I_w omega), q' = 1/2 (0, omega) q, q renormalised each step"
    )
    stages: list[StepStage] = []
    sleep: Sleep | None = None
    planes = list(scene.planes)
    solids = list(solid.shapes) if solid is not None else []
    if planes or solids or system.body_count > 1:
        table = PlaneTable(
            np.array([p.point for p in planes], dtype=np.float64).reshape(-1, 3),
            np.array(
                [np.array(p.normal) / np.linalg.norm(p.normal) for p in planes], dtype=np.float64
            ).reshape(-1, 3),
            np.array([p.restitution for p in planes], dtype=np.float64),
            np.array([p.friction for p in planes], dtype=np.float64),
        )
        contact = BodyContacts(
            system.body_first,
            system.particle_inv_mass[system.body_rows],
            system.body_inv_inertia,
            system.body_shape,
            table,
            np.array([b.restitution for b in scene.bodies]),
            np.array([b.friction for b in scene.bodies]),
            backend=backend,
            colliders=tuple((shape.signed_distance, shape.restitution, shape.friction) for shape in solids),
            collider_thickness=min((shape.thickness for shape in solids), default=math.inf),
            collider_offsets=solid.offsets if solid is not None and solid.injects else None,
            rolling=np.array([b.rolling_friction for b in scene.bodies], dtype=np.float64),
        )
        stages.append(contact)
        left_out.extend(contact.left_out)
        if scene.sleep is not None:
            contact.sleep = sleep = _sleep(scene.sleep, system, contact.bound, [*forces, *terms])
            labels.append(sleep.label())
    else:
        left_out.append("body contacts: no planes and a single body")
        if scene.sleep is not None:
            left_out.append("sleeping: a single body with nothing to touch never sleeps")
    point_rows = system.point_rows
    if point_rows.any():
        joined: set[tuple[int, int]] = set()
        if springs is not None:  # a particle held by a spring to a body does not touch that body
            for ra, rb, ba, bb in zip(
                springs.rows_a, springs.rows_b, springs.body_a, springs.body_b, strict=True
            ):
                if ba >= 0 and bb < 0:
                    joined.add((int(rb), int(ba)))
                if bb >= 0 and ba < 0:
                    joined.add((int(ra), int(bb)))
        touch = ParticleBodyContacts(
            system.body_first,
            system.body_shape,
            system.particle_inv_mass[system.body_rows],
            system.body_inv_inertia,
            np.array([b.restitution for b in scene.bodies]),
            np.array([b.friction for b in scene.bodies]),
            point_rows,
            np.zeros(system.particle_count) if radius is None else radius,
            joined,
        )
        touch.planes = planes_stage
        touch.sleep = sleep  # a particle wakes a sleeping body
        stages.append(touch)
    else:
        left_out.append("particle-body contacts: no particles")
    return dyn, stages, labels, left_out


def _sleep(spec: m.Sleep, system: System, bound: np.ndarray, forces: Sequence[ForceElement]) -> Sleep:
    """The scene's ``sleep`` rule: pinned bodies, and those a force keeps awake, never sleep."""
    count = system.body_count
    pinned = system.particle_inv_mass[system.body_rows] == 0.0
    kept = np.zeros(count, dtype=bool)
    for force in forces:
        kept |= force.bodies_kept_awake(count)
    return Sleep(spec.speed, spec.after, bound, ~kept, pinned)


def counts_text(system: System, body_dynamics: BodyDynamics | None) -> str:
    """ "N particles, M bodies, K springs" for a run's summary: body centres are rows of the particle
    arrays but not particles, and springs to bodies are springs; a part the scene lacks is left out
    unless it is the particles of a scene without bodies."""
    bodies = system.body_count
    particles = system.particle_count - bodies
    to_bodies = 0
    if bodies and body_dynamics is not None:
        terms = body_dynamics.terms
        to_bodies = sum(int(t.rows_a.size) for t in terms if isinstance(t, BodySprings))
    springs = system.spring_count + to_bodies
    parts = []
    if particles or not bodies:
        parts.append(f"{particles} particle{'' if particles == 1 else 's'}")
    if bodies:
        parts.append(f"{bodies} bod{'y' if bodies == 1 else 'ies'}")
    parts.append(f"{springs} spring{'' if springs == 1 else 's'}")
    return ", ".join(parts)


def _body_springs(
    scene: m.Scene, system: System, index_of: dict[str, int], body_index: dict[str, int]
) -> BodySprings | None:
    specs = [sp for sp in scene.springs if has_body_end(sp)]
    if not specs:
        return None
    rows = [[], []]
    bodies = [[], []]
    ats = [[], []]
    for sp in specs:
        for k, end in enumerate(sp.between):
            if isinstance(end, m.BodyPoint):
                b = body_index[end.body]
                rows[k].append(system.body_first + b)
                bodies[k].append(b)
                ats[k].append(end.at)
            else:
                rows[k].append(index_of[end])
                bodies[k].append(-1)
                ats[k].append((0.0, 0.0, 0.0))
    springs = BodySprings(
        np.array(rows[0]),
        np.array(rows[1]),
        np.array(bodies[0]),
        np.array(bodies[1]),
        np.array(ats[0], dtype=np.float64),
        np.array(ats[1], dtype=np.float64),
        np.zeros(len(specs)),
        np.array([sp.ks for sp in specs]),
        np.array([sp.kd for sp in specs]),
        system.body_count,
    )
    springs.inv_inertia = system.body_inv_inertia
    return springs


def auto_rest(springs: BodySprings, scene: m.Scene, x0: np.ndarray, q0: np.ndarray) -> None:
    """Set rest lengths: written ones, or the initial distance for ``auto``."""
    specs = [sp for sp in scene.springs if has_body_end(sp)]
    initial = springs.rest_lengths_auto(x0, q0)
    springs.rest[:] = [initial[i] if sp.rest == "auto" else sp.rest for i, sp in enumerate(specs)]
