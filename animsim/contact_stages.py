"""Build the post-step stages for keyframes, solid colliders, particle contacts and tearing.

The compiler calls :func:`build` once; it is the only code here that reads the
scene's models. It returns the stages in the order they run after each step:

    keyframes -> colliders -> (planes) -> particle contacts -> tearing -> (emitters)

Planes come after the colliders: a particle squeezed between a moving
collider and a plane ends on the plane's side (planes keep their promise that
nothing ends a step behind them).

and the lines ``explain`` prints for what the scene leaves out.

Conventions fixed here (documented for users in docs/scene-language):

* a particle's radius: its own ``radius``, else its structure's ``radius``,
  else ``particle_collisions.radius``, else 0 (a point). Colliders grow by the
  radius; contacts use it.
* a structure's ``pin_motion`` moves all its pinned particles together: the
  keyframed offset is added to each pin's initial position.
* a collider's ``motion`` keyframes its centre (a capsule's: the midpoint of a
  and b); the shape translates without turning.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.colliders import BOX, CAPSULE, SPHERE, Colliders, Shape, axis_angle_quaternion, quaternion_matrix
from animsim.keyframes import KeyframeDrive, PathEvaluator
from animsim.particle_contacts import ParticleContacts, spring_exclusions
from animsim.paths import make_paths
from animsim.scene import models as m
from animsim.scene.structures import expand, pinned_rows, structure_spring_count, tears
from animsim.tearing import Tearing

if TYPE_CHECKING:  # types only
    from animsim.elements import StepStage
    from animsim.forces.springs import Springs
    from animsim.integrators.base import Integrator
    from animsim.system import System


@dataclass
class Built:
    front: list[StepStage] = field(default_factory=list)  # before planes: keyframes, colliders
    back: list[StepStage] = field(default_factory=list)  # after planes: contacts, tearing
    contacts: ParticleContacts | None = None
    colliders: Colliders | None = None
    drivers: list[KeyframeDrive] = field(default_factory=list)  # keyframe drives (forces see the path)
    left_out: list[str] = field(default_factory=list)
    tearing: Tearing | None = None
    radius: np.ndarray | None = None
    #: t -> points on the colliders' surfaces, for drawing (None: no colliders)
    collider_surface: Callable[[float], np.ndarray] | None = None


#: c in "a constant acceleration a over a step of dt moves a position by c dt^2 a", per method:
def follow_weight(integrator: Integrator) -> float:
    """The integrator's c in x1 = x0 + dt (v0 + c dv): x1 = x0 + dt v1 for symplectic and
    implicit Euler (c = 1), x1 = x0 + dt v0 for explicit Euler (c = 0), and the exact
    dt^2 a / 2 of every method of order 2 or more (Runge-Kutta, Verlet, the averaged Euler),
    declared by its method or derived from its tableau (animsim.methods.Method.position_weight).
    Contact stages move what they touch by c dt times the velocity change of their resting and
    sliding impulses, which stand for forces acting during the step."""
    return integrator.method.position_weight


def spring_max_strain(scene: m.Scene) -> np.ndarray:
    """Per spring, in the compiler's order (listed springs, then each structure's families),
    the tearing limit; +inf where the spring cannot tear."""
    parts = [np.array([np.inf if sp.max_strain is None else sp.max_strain for sp in scene.springs])]
    for s in scene.structures:
        if tears(s):
            for group in expand(s).springs:
                parts.append(np.full(len(group.index), group.max_strain))
        else:
            parts.append(np.full(structure_spring_count(s), np.inf))
    return np.concatenate(parts) if parts else np.zeros(0)


def particle_radius(scene: m.Scene, system: System) -> np.ndarray:
    """Per row radius (m): own, else structure's, else particle_collisions', else 0."""
    n = system.particle_count
    default = scene.particle_collisions.radius if scene.particle_collisions is not None else 0.0
    radius = np.full(n, default, dtype=np.float64)
    for i, p in enumerate(scene.particles):
        if p.radius is not None:
            radius[i] = p.radius
    for s, (first, shape, _f0, _f1) in zip(scene.structures, system.structure_grids, strict=True):
        if s.radius is not None:
            radius[first : first + int(np.prod(shape))] = s.radius
    return radius


def _point_rows(system: System) -> np.ndarray:
    """Rows colliders and contacts act on: particles, not rigid-body centres (when bodies exist)."""
    rows = getattr(system, "point_rows", None)
    return np.ones(system.particle_count, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)


def collider_shape(c: m.SphereCollider | m.BoxCollider | m.CapsuleCollider) -> Shape:
    """The :class:`animsim.colliders.Shape` of one scene collider, at its written position."""

    if isinstance(c, m.SphereCollider):
        shape = Shape(SPHERE, np.array(c.center), radius=c.radius)
    elif isinstance(c, m.BoxCollider):
        o = c.orientation
        q = axis_angle_quaternion(np.array(o.axis), o.angle) if isinstance(o, m.AxisAngle) else np.array(o)
        shape = Shape(BOX, np.array(c.center), half=0.5 * np.array(c.size), rotation=quaternion_matrix(q))
    else:
        a, b = np.array(c.a), np.array(c.b)
        mid = 0.5 * (a + b)
        shape = Shape(CAPSULE, mid, radius=c.radius, segment=b - mid)
    return Shape(
        shape.kind,
        shape.center,
        shape.radius,
        shape.half,
        shape.rotation,
        shape.segment,
        c.restitution,
        c.friction,
    )


def build(
    scene: m.Scene, system: System, backend: str, springs: Springs | None, positions: np.ndarray
) -> Built:
    """Every stage this module owns that ``scene`` uses (see the module docstring).

    ``springs``: the scene's spring element (tearing switches broken ones off in it);
    ``positions``: the initial positions (a structure's pins move relative to them).
    """
    out = Built()
    radius = particle_radius(scene, system)
    out.radius = radius
    numba = "numba" if backend == "numba" else "numpy"
    _add_keyframes(out, scene, system, positions, numba)
    _add_colliders(out, scene, system, radius, numba)
    _add_contacts(out, scene, system, radius, numba)
    _add_tearing(out, scene, system, springs, numba)
    return out


def _add_keyframes(out: Built, scene: m.Scene, system: System, positions: np.ndarray, numba: str) -> None:
    """The keyframe drive of the listed pinned particles and the structures' pins."""
    keys: list[list[Any]] = []  # each path's keys as validated: [t, [x, y, z]] (m.Keyframe)
    smooth: list[bool] = []
    rows: list[int] = []
    which: list[int] = []
    base: list[np.ndarray] = []
    for i, p in enumerate(scene.particles):
        if p.keyframes is not None:
            which.append(len(keys))
            keys.append(list(p.keyframes))
            smooth.append(p.interpolation == "smooth")
            rows.append(i)
            base.append(np.zeros(3))
    if scene.structures:
        for s, (first, _shape, _f0, _f1) in zip(scene.structures, system.structure_grids, strict=True):
            motion = getattr(s, "pin_motion", None)  # not every structure kind has pins that move
            if motion is None:
                continue
            path = len(keys)
            keys.append(list(motion.keyframes))
            smooth.append(motion.interpolation == "smooth")
            for li in pinned_rows(s).tolist():
                which.append(path)
                rows.append(first + li)
                base.append(positions[first + li])
    if rows:  # the keyframes module loads only for a scene that has some
        drive = KeyframeDrive(
            np.array(rows), np.array(which), np.array(base), make_paths(keys, smooth), numba
        )
        out.front.append(drive)
        out.drivers.append(drive)
    else:
        out.left_out.append("keyframes: no keyframed particles or pins")


def _add_colliders(out: Built, scene: m.Scene, system: System, radius: np.ndarray, numba: str) -> None:
    """The solid colliders (spheres, boxes, capsules), still or keyframed."""
    if not scene.colliders:
        out.left_out.append("colliders: no spheres, boxes or capsules")
        return
    shapes: list[Shape] = []
    motion_keys: list[list[Any]] = []
    motion_smooth: list[bool] = []
    moving: list[int] = []
    for c in scene.colliders:
        shapes.append(collider_shape(c))
        if c.motion is not None:
            moving.append(len(motion_keys))
            motion_keys.append(list(c.motion.keyframes))
            motion_smooth.append(c.motion.interpolation == "smooth")
        else:
            moving.append(-1)
    evaluator = None
    if motion_keys:
        evaluator = PathEvaluator(make_paths(motion_keys, motion_smooth), numba)
    colliders = Colliders(
        shapes,
        system.particle_inv_mass,
        radius=radius,
        active=_point_rows(system),
        motion=evaluator,
        moving=np.array(moving, dtype=np.int64),
        backend=numba,
    )
    out.front.append(colliders)
    out.colliders = colliders
    out.collider_surface = colliders.surface_points


def _add_contacts(out: Built, scene: m.Scene, system: System, radius: np.ndarray, numba: str) -> None:
    """Contacts between particles of a radius (after the colliders, which they know)."""
    if scene.particle_collisions is None:
        out.left_out.append("particle contacts: no particle_collisions")
        return
    pc = scene.particle_collisions
    active = _point_rows(system) & (radius > 0)
    exclude = spring_exclusions(system.spring_index, system.spring_rest_length, radius, system.particle_count)
    contacts = ParticleContacts(
        radius, pc.restitution, pc.friction, system.particle_inv_mass, active, exclude, numba
    )
    # ParticleContacts leaves its attribute unannotated (None until set here)
    contacts.colliders = out.colliders  # type: ignore[assignment]
    out.back.append(contacts)
    out.contacts = contacts


def _add_tearing(out: Built, scene: m.Scene, system: System, springs: Springs | None, numba: str) -> None:
    """Tearing, when some spring has a max_strain (it switches broken ones off in ``springs``)."""
    limits = spring_max_strain(scene)
    if not (system.spring_count and np.isfinite(limits).any()):
        out.left_out.append(
            "tearing: needs a max_strain on a spring, a spring family or a structure; none has one"
        )
        return
    tear = Tearing(
        system.spring_index, system.spring_rest_length, limits, numba, families=system.spring_families
    )
    tear.springs = springs
    out.back.append(tear)
    out.tearing = tear


def particles_inside_colliders(scene: Any) -> list[tuple[tuple[str | int, ...], str, bool]]:
    """A listed particle that starts inside a solid collider would be thrown out to its
    surface by the first step: say so instead (pinned ones stay where they are)."""
    colliders = [c for c in getattr(scene, "colliders", None) or [] if c is not None]
    particles = [
        (i, p)
        for i, p in enumerate(scene.particles)
        if isinstance(p, m.Particle) and not p.pinned and p.position is not None
    ]
    if not colliders or not particles:
        return []
    pc = getattr(scene, "particle_collisions", None)
    default = pc.radius if pc is not None else 0.0
    x = np.array([p.position for _, p in particles], dtype=np.float64)
    r = np.array([default if p.radius is None else p.radius for _, p in particles])
    out: list[tuple[tuple[str | int, ...], str, bool]] = []
    for j, c in enumerate(colliders):
        shape = collider_shape(c)
        offset = None
        if c.motion is not None:
            at0, _ = make_paths([c.motion.keyframes], [c.motion.interpolation == "smooth"]).evaluate(0.0)
            offset = at0[0] - shape.center
        d, _ = shape.signed_distance(x, offset)
        for k in np.flatnonzero(d < r):
            i, p = particles[k]
            depth = float(r[k] - d[k])
            grown = f" (grown by the particle's radius {r[k]:g} m)" if r[k] > 0 else ""
            out.append(
                (
                    ("particles", i, "position"),
                    f"starts {depth:.3g} m inside colliders.{j} ({c.type}){grown} at t = 0: the first "
                    "step would throw it out to the surface; move it outside",
                    False,
                )
            )
    return out
