"""The solid colliders' step stage: every collider of a scene, static or keyframed.

The response copies the planes' (:mod:`animsim.collisions`, Lander, Game
Developer 1999, Eq. 3) in the collider's frame: a collider that moves
translates from c(t0) to c(t1) during a step, so the particle's path relative
to it is the segment ``x_old + c(t1) - c(t0) -> x``, and the collider's
velocity over the step ``u = (c(t1) - c(t0)) / dt`` is taken off the particle's.
Along that segment the first contact is found by sphere tracing (march by the
distance, which can never overshoot a surface), so a 1,000 m/s particle meets
a 1 cm box instead of jumping over it. At the contact the relative velocity
is reflected (``v_t - e v_n``, Coulomb friction taking at most ``friction``
times the change of ``v_n`` off ``v_t``), ``u`` is added back, and the
particle flies on for the rest of the step with the step's mean acceleration.
A particle that still ends inside (resting under gravity, a collider that
scoops it up) is projected out along the normal and loses its inward
relative velocity, so resting and sliding contact stay still as on planes and
a moving collider pushes what it meets. A particle never ends a step inside.

Particles are points here unless they have a radius (``radius``, or
``particle_collisions``): then the shape is grown by that radius.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from animsim.colliders.kernels import numba_kernel, stage_kernel
from animsim.colliders.numpy_rule import resolve_numpy
from animsim.colliders.shapes import KIND_NAMES, PARAMS, Shape, shape_bounds
from animsim.collisions.response import energy_shift
from animsim.elements import PlaneProjector, StepStage
from animsim.system import State


@dataclass
class StepMotion:
    """Where every collider is over one step: displacement from the reference at t0 and t1."""

    at0: np.ndarray  # (C, 3)
    at1: np.ndarray  # (C, 3)


class Colliders(StepStage):
    """All solid colliders of a scene: a step stage after each integrator step.

    shapes: the colliders; ``motion``: a :class:`animsim.keyframes.PathEvaluator`
    for the moving ones (``moving`` lists which path drives which collider),
    or None. ``radius``: (N,) particle radii (0: points). ``active``: (N,) bool
    rows colliders act on (particles, not rigid bodies); pinned and dead rows
    (inverse mass 0) are never moved.
    """

    #: not pointwise: its fused stage's parameters hold every row's radius and active flag,
    #: indexed by the row's place in the whole scene (a block of rows would read the wrong ones)
    pointwise = False
    #: the method's c, set at compile time: a bounce keeps e^2 of the energy the method
    #: conserves (animsim.collisions.kept_bounce_speed)
    follow_weight: float | None = 1.0
    #: the scene's impulse planes (compile sets it): a moving collider meets the particles
    #: where the planes keep them, not where the step left them behind a plane
    planes_first: PlaneProjector | None = None

    def __init__(
        self,
        shapes: list[Shape],
        inv_mass: np.ndarray,
        radius: np.ndarray | None = None,
        active: np.ndarray | None = None,
        motion=None,
        moving: np.ndarray | None = None,
        backend: str = "numpy",
    ):
        self.shapes = shapes
        self.inv_mass = inv_mass
        n = inv_mass.shape[0]
        self.radius = np.zeros(n) if radius is None else np.asarray(radius, dtype=np.float64)
        self.active = np.ones(n, dtype=bool) if active is None else np.asarray(active, dtype=bool)
        self.motion = motion
        self.moving = np.full(len(shapes), -1, dtype=np.int64) if moving is None else np.asarray(moving)
        self.backend = backend
        self.params = np.array([s.packed() for s in shapes]).reshape(-1, PARAMS)
        self.params[:, 20] = [s.restitution for s in shapes]
        self.friction = np.array([s.friction for s in shapes], dtype=np.float64)
        self.bounds = shape_bounds(self.params)
        self._kernel = numba_kernel() if backend == "numba" else None
        self.no_closed_form = "solid colliders"
        self.injects = bool((self.moving >= 0).any())
        self.dissipative = any(s.restitution < 1 or s.friction > 0 for s in shapes)
        counts: dict[str, int] = {}
        for s in shapes:
            counts[KIND_NAMES[s.kind]] = counts.get(KIND_NAMES[s.kind], 0) + 1
        what = ", ".join(
            f"{v} {k}{('es' if k == 'box' else 's') if v > 1 else ''}" for k, v in counts.items()
        )
        n_moving = int((self.moving >= 0).sum())
        if n_moving == 0:
            # static shapes need no clock: the numba backend can run them inside its fused chunks
            self.numba_stage_source = stage_kernel
        self.label = (
            f"colliders: {what}"
            + (f" ({n_moving} keyframed)" if n_moving else " (static)")
            + ", time of impact inside the step, restitution and Coulomb friction"
        )

    def stability_note(self, dt: float) -> str:
        return (
            "particles against colliders: impulses at the time of impact inside each step, found at "
            "any speed and angle, no stiffness and no limit on dt"
            + ("; moving ones put energy in (the watchdog's energy test is off)" if self.injects else "")
        )

    def offsets(self, t: float) -> np.ndarray:
        """Displacement (C, 3) of every collider from its reference position at ``t``."""
        off = np.zeros((len(self.shapes), 3))
        if self.motion is not None:
            pos, _ = self.motion(t)
            m = self.moving >= 0
            off[m] = pos[self.moving[m]] - self.params[m, 1:4]
        return off

    def reset(self, state: State) -> None:
        """Nothing to reset: colliders keep no state between steps."""

    def surface_points(self, t: float, per_shape: int = 600) -> np.ndarray:
        """About ``per_shape`` points on each collider's surface at time ``t`` (for drawing)."""
        if not hasattr(self, "_surface"):
            # a Fibonacci sphere of directions, pushed onto each surface along its own
            # distance function: points spread evenly enough to show the shape
            k = np.arange(per_shape) + 0.5
            phi = np.arccos(1 - 2 * k / per_shape)
            theta = np.pi * (1 + 5**0.5) * k
            dirs = np.stack([np.cos(theta) * np.sin(phi), np.cos(phi), np.sin(theta) * np.sin(phi)], axis=1)
            pts = []
            for s in self.shapes:
                reach = s.radius + float(np.linalg.norm(s.half)) + float(np.linalg.norm(s.segment))
                p = s.center + dirs * reach * 1.5
                for _ in range(60):  # march inward onto the surface (sphere tracing)
                    d, n = s.signed_distance(p)
                    p = p - d[:, None] * n
                pts.append(p - s.center)
            self._surface = pts
        off = self.offsets(t)
        return np.concatenate(
            [s.center + off[c] + p for c, (s, p) in enumerate(zip(self.shapes, self._surface, strict=True))]
        )

    def apply(
        self,
        state: State,
        x_old: np.ndarray,
        v_old: np.ndarray,
        t0: float,
        t1: float,
        dt: float | None = None,
        project_only: bool = False,
    ) -> bool:
        dt = t1 - t0 if dt is None else dt
        if dt <= 0:
            return False
        planes_moved = False
        if self.injects and self.planes_first is not None and not project_only:
            # A particle resting on the floor dips below it in every step (gravity) until the
            # plane stage puts it back: a keyframed box sliding flush with the floor met it
            # there, under its bottom face, and swept over it. The planes first (the plane
            # stage runs again after the colliders, and changes nothing a plane already did).
            planes_moved = self.planes_first.apply(state, x_old, v_old, t0, t1, dt)
        off0, off1 = self.offsets(t0), self.offsets(t1)
        x, v = state.particle_position, state.particle_velocity
        # the state's live masses: emitter pools switch theirs on at birth
        inv_mass = getattr(state, "particle_inv_mass", self.inv_mass)
        movable = self.active & (inv_mass > 0)
        if state.particle_alive is not None:
            movable = movable & state.particle_alive
        if self._kernel is not None:
            hit = bool(
                self._kernel(
                    self.params,
                    self.friction,
                    self.bounds,
                    off0,
                    off1,
                    x_old,
                    v_old,
                    x,
                    v,
                    dt,
                    self.radius,
                    movable,
                    inv_mass,
                    project_only,
                    energy_shift(self.follow_weight),
                )
            )
            return hit or planes_moved
        hit = resolve_numpy(
            self.params,
            self.friction,
            off0,
            off1,
            x_old,
            v_old,
            x,
            v,
            dt,
            self.radius,
            movable,
            project_only,
            self.bounds,
            energy_shift(self.follow_weight),
        )
        return hit or planes_moved

    def numba_stage_params(self) -> tuple[np.ndarray, np.ndarray]:
        """The fused stage's numbers (static colliders only): see :func:`stage_kernel`."""
        fp = np.concatenate(
            [
                [len(self.shapes)],
                self.params.ravel(),
                self.friction,
                self.bounds.ravel(),
                [energy_shift(self.follow_weight)],
                self.radius,
            ]
        )
        return np.ascontiguousarray(fp, dtype=np.float64), self.active.astype(np.int64)

    def project(self, state, t0: float, t1: float) -> bool:
        """Push out of every collider whatever another stage (particle contacts) pushed in."""
        x, v = state.particle_position, state.particle_velocity
        return self.apply(state, x, v, t0, t1, t1 - t0, project_only=True)
