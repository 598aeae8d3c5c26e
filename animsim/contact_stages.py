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

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.scene import models as m


@dataclass
class Built:
    front: list[Any] = field(default_factory=list)  # before planes: keyframes, colliders
    back: list[Any] = field(default_factory=list)  # after planes: contacts, tearing
    contacts: Any = None
    drivers: list[Any] = field(default_factory=list)  # keyframe drives (forces see the path)
    left_out: list[str] = field(default_factory=list)
    tearing: Any = None
    radius: np.ndarray | None = None
    #: t -> points on the colliders' surfaces, for drawing (None: no colliders)
    collider_surface: Any = None


#: c in "a constant acceleration a over a step of dt moves a position by c dt^2 a", per method:
#: x1 = x0 + dt v1 for symplectic and implicit Euler (c = 1), x1 = x0 + dt v0 for explicit Euler
#: (c = 0), and the exact dt^2 a / 2 of every method of order 2 or more (Runge-Kutta, Verlet,
#: the averaged Euler). Contact stages move what they touch by c dt times the velocity change
#: of their resting and sliding impulses, which stand for forces acting during the step.
FOLLOW_WEIGHT = {"symplectic_euler": 1.0, "implicit_euler": 1.0, "euler": 0.0}


def follow_weight(integrator: Any) -> float:
    """The integrator's c (its own ``follow_weight`` if it declares one)."""
    declared = getattr(integrator, "follow_weight", None)
    if declared is not None:
        return float(declared)
    return FOLLOW_WEIGHT.get(integrator.name, 0.5)


def spring_max_strain(scene: m.Scene) -> np.ndarray:
    """Per spring, in the compiler's order (listed springs, then each structure's families),
    the tearing limit; +inf where the spring cannot tear."""
    from animsim.scene.structures import expand, structure_spring_count

    parts = [np.array([np.inf if sp.max_strain is None else sp.max_strain for sp in scene.springs])]
    for s in scene.structures:
        families = [getattr(s, name, None) for name in type(s).model_fields]
        if any(isinstance(f, m.SpringFamily) and f.max_strain is not None for f in families):
            for group in expand(s).springs:
                parts.append(np.full(len(group.index), group.max_strain))
        else:
            parts.append(np.full(structure_spring_count(s), np.inf))
    return np.concatenate(parts) if parts else np.zeros(0)


def particle_radius(scene: m.Scene, system: Any) -> np.ndarray:
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


def _point_rows(system: Any) -> np.ndarray:
    """Rows colliders and contacts act on: particles, not rigid-body centres (when bodies exist)."""
    rows = getattr(system, "point_rows", None)
    return np.ones(system.particle_count, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)


def build(scene: m.Scene, system: Any, backend: str, springs: Any | None, positions: np.ndarray) -> Built:
    """Every stage this module owns that ``scene`` uses (see the module docstring).

    ``springs``: the scene's spring element (tearing switches broken ones off in it);
    ``positions``: the initial positions (a structure's pins move relative to them).
    """
    out = Built()
    radius = particle_radius(scene, system)
    out.radius = radius
    numba = "numba" if backend == "numba" else "numpy"

    # --- keyframes: listed pinned particles, structures' pins ---------------------------
    keys: list[list[tuple[float, tuple[float, float, float]]]] = []
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
        from animsim.scene.structures import local_index

        for s, (first, _shape, _f0, _f1) in zip(scene.structures, system.structure_grids, strict=True):
            if getattr(s, "pin_motion", None) is None:
                continue
            path = len(keys)
            keys.append(list(s.pin_motion.keyframes))
            smooth.append(s.pin_motion.interpolation == "smooth")
            for pid in s.pin:
                li = local_index(s, pid)
                if li is None:
                    continue
                which.append(path)
                rows.append(first + li)
                base.append(positions[first + li])
    if rows:  # the keyframes module loads only for a scene that has some
        from animsim.keyframes import KeyframeDrive, make_paths

        drive = KeyframeDrive(
            np.array(rows), np.array(which), np.array(base), make_paths(keys, smooth), numba
        )
        out.front.append(drive)
        out.drivers.append(drive)
    else:
        out.left_out.append("keyframes: no keyframed particles or pins")

    # --- solid colliders ------------------------------------------------------------------
    colliders = None
    if scene.colliders:
        from animsim.colliders import (
            BOX,
            CAPSULE,
            SPHERE,
            Colliders,
            Shape,
            axis_angle_quaternion,
            quaternion_matrix,
        )

        shapes: list[Shape] = []
        motion_keys: list[list[Any]] = []
        motion_smooth: list[bool] = []
        moving: list[int] = []
        for c in scene.colliders:
            if isinstance(c, m.SphereCollider):
                shape = Shape(SPHERE, np.array(c.center), radius=c.radius)
            elif isinstance(c, m.BoxCollider):
                o = c.orientation
                q = (
                    axis_angle_quaternion(np.array(o.axis), o.angle)
                    if isinstance(o, m.AxisAngle)
                    else np.array(o)
                )
                shape = Shape(
                    BOX, np.array(c.center), half=0.5 * np.array(c.size), rotation=quaternion_matrix(q)
                )
            else:
                a, b = np.array(c.a), np.array(c.b)
                mid = 0.5 * (a + b)
                shape = Shape(CAPSULE, mid, radius=c.radius, segment=b - mid)
            shapes.append(
                Shape(
                    shape.kind,
                    shape.center,
                    shape.radius,
                    shape.half,
                    shape.rotation,
                    shape.segment,
                    c.restitution,
                    c.friction,
                )
            )
            if c.motion is not None:
                moving.append(len(motion_keys))
                motion_keys.append(list(c.motion.keyframes))
                motion_smooth.append(c.motion.interpolation == "smooth")
            else:
                moving.append(-1)
        evaluator = None
        if motion_keys:
            from animsim.keyframes import PathEvaluator, make_paths

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
        out.collider_surface = colliders.surface_points
    else:
        out.left_out.append("colliders: no spheres, boxes or capsules")

    # --- particle contacts ------------------------------------------------------------------
    if scene.particle_collisions is not None:
        from animsim.particle_contacts import ParticleContacts, spring_exclusions

        pc = scene.particle_collisions
        active = _point_rows(system) & (radius > 0)
        exclude = spring_exclusions(
            system.spring_index, system.spring_rest_length, radius, system.particle_count
        )
        contacts = ParticleContacts(
            radius, pc.restitution, pc.friction, system.particle_inv_mass, active, exclude, numba
        )
        contacts.colliders = colliders
        out.back.append(contacts)
        out.contacts = contacts
    else:
        out.left_out.append("particle contacts: no particle_collisions")

    # --- tearing ----------------------------------------------------------------------------------
    limits = spring_max_strain(scene)
    if system.spring_count and np.isfinite(limits).any():
        from animsim.tearing import Tearing

        tear = Tearing(system.spring_index, system.spring_rest_length, limits, numba)
        tear.springs = springs
        out.back.append(tear)
        out.tearing = tear
    else:
        out.left_out.append("tearing: no spring has a max_strain")
    return out
