"""Solid colliders: spheres, oriented boxes and capsules, static or keyframed.

Each shape is a signed distance function (negative inside) with its outward
normal, the gradient of the distance (Hart, "Sphere tracing", The Visual
Computer 1996; Quilez's closed forms for the box and the capsule):

* sphere (c, r):           d = |x - c| - r
* box (c, half sizes h, rotation R): q = R^T (x - c), e = |q| - h;
  outside d = |max(e, 0)|, inside d = max_k e_k (the nearest face)
* capsule (segment a-b, r): d = |x - closest point of [a, b]| - r

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

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.collisions import (
    RESTING_STEPS,
    apply_friction,
    energy_shift,
    hold_by_static_friction,
    kept_bounce_speed,
    static_friction_holds,
)
from animsim.elements import StepStage, jit_kernel, numba_helper
from animsim.vec import dot3

SPHERE, BOX, CAPSULE = 0, 1, 2
KIND_NAMES = {SPHERE: "sphere", BOX: "box", CAPSULE: "capsule"}
#: parameters of one collider in the packed array handed to kernels
#: [kind, c(3), radius, half(3), R (9, row major), s (3): capsule half segment, restitution, friction]
PARAMS = 21
#: sphere-tracing iterations; a grazing path that needs more is searched (_first_touch)
MARCH_STEPS = 48
#: after the march: golden-section steps towards a grazing path's closest approach, then
#: bisection steps to its first touch (brackets shrink by 0.618^80 and 0.5^60 of the step)
GOLDEN_STEPS = 80
BISECT_STEPS = 60
INV_PHI = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class Shape:
    """One collider's geometry at its reference position (``center``)."""

    kind: int
    center: np.ndarray  # (3,) sphere/box centre; capsule: midpoint of a-b
    radius: float = 0.0  # sphere, capsule
    half: np.ndarray = field(default_factory=lambda: np.zeros(3))  # box half sizes
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))  # box: body frame -> world
    segment: np.ndarray = field(
        default_factory=lambda: np.zeros(3)
    )  # capsule: b - center (a = center - segment)
    restitution: float = 0.5
    friction: float = 0.0

    @property
    def thickness(self) -> float:
        """Its thinnest extent: what a body must cross to pass through it."""
        return float(2.0 * self.radius if self.kind != BOX else 2.0 * (np.min(self.half) + self.radius))

    def packed(self) -> np.ndarray:
        p = np.zeros(PARAMS)
        p[0] = self.kind
        p[1:4] = self.center
        p[4] = self.radius
        p[5:8] = self.half
        p[8:17] = np.asarray(self.rotation).reshape(9)
        p[17:20] = self.segment
        p[20] = self.restitution
        return p

    def signed_distance(
        self, x: np.ndarray, offset: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (M,) and unit outward normal (M, 3) at points ``x`` (M, 3).

        ``offset``: where the shape is, as a displacement from its reference
        position (a moving collider). Rigid-body contacts use this too.
        """
        c = self.center if offset is None else self.center + offset
        return sdf(self.kind, x - c, self.radius, self.half, self.rotation, self.segment)


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion [w, x, y, z] (Hamilton)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def axis_angle_quaternion(axis: np.ndarray, degrees: float) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    h = np.radians(degrees) / 2
    return np.concatenate([[np.cos(h)], np.sin(h) * a])


def sdf(
    kind: int, p: np.ndarray, radius: float, half: np.ndarray, rotation: np.ndarray, segment: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance and outward unit normal of points ``p`` (M, 3), relative to the shape's centre."""
    if kind == SPHERE:
        length = np.sqrt(dot3(p, p))
        n = np.empty_like(p)
        ok = length > 0
        n[ok] = p[ok] / length[ok, None]
        n[~ok] = (0.0, 1.0, 0.0)  # at the very centre any direction is out; pick up
        return length - radius, n
    if kind == CAPSULE:
        # every sum x, then y, then z, as the numba kernel: the backends agree to the bit
        ss = float((segment[0] * segment[0] + segment[1] * segment[1]) + segment[2] * segment[2])
        t = np.clip(dot3(p, segment) / ss, -1.0, 1.0) if ss > 0 else np.zeros(len(p))
        w = p - t[:, None] * segment
        length = np.sqrt(dot3(w, w))
        n = np.empty_like(p)
        ok = length > 0
        n[ok] = w[ok] / length[ok, None]
        if not ok.all():  # on the axis: any direction perpendicular to it
            sx, sy, sz = float(segment[0]), float(segment[1]), float(segment[2])
            # cross(s, x-axis) or cross(s, y-axis), written out as the numba kernel does
            cx, cy, cz = (0.0, sz, -sy) if abs(sx) < 0.9 * np.sqrt(ss) else (-sz, 0.0, sx)
            cn = float(np.sqrt(cx * cx + cy * cy + cz * cz))
            n[~ok] = (cx / cn, cy / cn, cz / cn) if cn > 0 else (0.0, 1.0, 0.0)
        return length - radius, n
    # box: in the box frame. Column by column: (N, 3) @ (3, 3) through matmul costs
    # ten times more than these three multiply-adds at this shape.
    r = rotation
    q0 = p[:, 0] * r[0, 0] + p[:, 1] * r[1, 0] + p[:, 2] * r[2, 0]  # q = R^T p
    q1 = p[:, 0] * r[0, 1] + p[:, 1] * r[1, 1] + p[:, 2] * r[2, 1]
    q2 = p[:, 0] * r[0, 2] + p[:, 1] * r[1, 2] + p[:, 2] * r[2, 2]
    e0, e1, e2 = np.abs(q0) - half[0], np.abs(q1) - half[1], np.abs(q2) - half[2]
    o0, o1, o2 = np.maximum(e0, 0.0), np.maximum(e1, 0.0), np.maximum(e2, 0.0)
    out_len = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    inside = out_len == 0
    s0, s1, s2 = np.where(q0 < 0, -1.0, 1.0), np.where(q1 < 0, -1.0, 1.0), np.where(q2 < 0, -1.0, 1.0)
    safe = np.where(inside, 1.0, out_len)
    # outside: towards the nearest point; inside: the nearest face (first of equals: x, y, z)
    f0 = (e0 >= e1) & (e0 >= e2)
    f1 = ~f0 & (e1 >= e2)
    f2 = ~f0 & ~f1
    n0 = np.where(inside, np.where(f0, s0, 0.0), s0 * o0 / safe)
    n1 = np.where(inside, np.where(f1, s1, 0.0), s1 * o1 / safe)
    n2 = np.where(inside, np.where(f2, s2, 0.0), s2 * o2 / safe)
    d = np.where(inside, np.maximum(np.maximum(e0, e1), e2), out_len)
    n = np.empty_like(p)
    n[:, 0] = r[0, 0] * n0 + r[0, 1] * n1 + r[0, 2] * n2  # n = R n_local
    n[:, 1] = r[1, 0] * n0 + r[1, 1] * n1 + r[1, 2] * n2
    n[:, 2] = r[2, 0] * n0 + r[2, 1] * n1 + r[2, 2] * n2
    return d, n


def _edge_face(shape: Shape, p: np.ndarray, w: np.ndarray, tol: np.ndarray, n: np.ndarray) -> None:
    """At a box's edge or corner, the face the particle runs into: in place on the normals n.

    A contact point on an edge is on two faces' planes at once (within ``tol``), and which one
    the distance function names was left to rounding: a grain on the floor lies on the plane
    of the bottom face of a box sliding flush with the floor, and half the time the box's
    front face, which pushes it, lost to the bottom one, which does not, and the box slid over
    the grain. Where two or more faces are within tol (and the point is not further outside),
    the face is the one whose outward normal the particle's velocity relative to the box at
    the step's end, ``w`` (k, 3), runs into most; the first of equals (x, y, z) otherwise."""
    r, half = shape.rotation, shape.half
    q0 = p[:, 0] * r[0, 0] + p[:, 1] * r[1, 0] + p[:, 2] * r[2, 0]  # q = R^T p, as sdf
    q1 = p[:, 0] * r[0, 1] + p[:, 1] * r[1, 1] + p[:, 2] * r[2, 1]
    q2 = p[:, 0] * r[0, 2] + p[:, 1] * r[1, 2] + p[:, 2] * r[2, 2]
    e = np.stack([np.abs(q0) - half[0], np.abs(q1) - half[1], np.abs(q2) - half[2]], axis=1)
    sign = np.where(np.stack([q0, q1, q2], axis=1) < 0, -1.0, 1.0)
    near = e >= -tol[:, None]
    edge = np.flatnonzero((near.sum(axis=1) >= 2) & (e.max(axis=1) <= tol))
    if edge.size == 0:
        return
    score = np.full((edge.size, 3), np.inf)
    for j in range(3):  # the world normal of face j: sign_j R[:, j]
        into = sign[edge, j] * ((r[0, j] * w[edge, 0] + r[1, j] * w[edge, 1]) + r[2, j] * w[edge, 2])
        score[:, j] = np.where(near[edge, j], into, np.inf)
    face = np.argmin(score, axis=1)
    n[edge] = sign[edge, face][:, None] * r[:, face].T


def _path_distance(
    shape: Shape, center: np.ndarray, p0: np.ndarray, sg: np.ndarray, r: np.ndarray, rows: np.ndarray
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """f(s, sel) of :func:`_first_touch`: the distance from ``shape`` (at ``center``) of the
    paths p0 + s sg of ``rows[sel]``, minus their radii."""

    def dist(sv: np.ndarray, sel: np.ndarray) -> np.ndarray:
        at = rows[sel]
        d, _ = sdf(
            shape.kind,
            p0[at] + sv[:, None] * sg[at] - center,
            shape.radius,
            shape.half,
            shape.rotation,
            shape.segment,
        )
        return d - r[at]

    return dist


def _first_touch(
    dist: Callable[[np.ndarray, np.ndarray], np.ndarray], s0: np.ndarray, tol: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where paths the march gave up on first touch the shape: (hit (k,), s (k,)).

    Sphere tracing steps by the distance to the shape; along a path that skims a surface at a
    small angle theta each step closes only sin(theta) of the gap, so a particle at 1,000 m/s
    passing a 1 cm box at 2 degrees ran out of steps and went through. The distance to a convex
    shape along a line, f(s) = dist(s) (``dist(s, sel)``: the rows ``sel`` at fractions ``s``,
    minus their radius), is a convex function, so from s0 (where f > tol) a golden-section
    search (Kiefer 1953) closes in on its minimum over [s0, 1]; the first point found with
    f <= tol brackets the first touch, which bisection then finds. A path whose minimum stays
    above tol misses the shape. The numba twin (:func:`_first_touch1`) does the same steps."""
    k = s0.size
    every = np.arange(k)
    touch = np.where(dist(np.ones(k), every) <= tol, 1.0, np.nan)  # ends on or inside
    a, b = s0.copy(), np.ones(k)
    for _ in range(GOLDEN_STEPS):
        sel = np.flatnonzero(np.isnan(touch))
        if sel.size == 0:
            break
        c = b[sel] - INV_PHI * (b[sel] - a[sel])
        d = a[sel] + INV_PHI * (b[sel] - a[sel])
        fc, fd = dist(c, sel), dist(d, sel)
        touch[sel] = np.where(fc <= tol[sel], c, np.where(fd <= tol[sel], d, np.nan))
        left = fc <= fd  # convex: the minimum is in [a, d], else in [c, b]
        b[sel] = np.where(left, d, b[sel])
        a[sel] = np.where(left, a[sel], c)
    hit = ~np.isnan(touch)
    sel = np.flatnonzero(hit)
    lo, hi = s0[sel], touch[sel]
    for _ in range(BISECT_STEPS if sel.size else 0):
        mid = 0.5 * (lo + hi)
        inside = dist(mid, sel) <= tol[sel]
        hi = np.where(inside, mid, hi)
        lo = np.where(inside, lo, mid)
    s = s0.copy()
    s[sel] = hi
    return hit, s


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
    planes_first: Any = None

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
            self.numba_stage_source = _stage_kernel
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

    def reset(self, state) -> None:
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
        state,
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
        """The fused stage's numbers (static colliders only): see :func:`_stage_kernel`."""
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


def shape_of(params: np.ndarray, friction: float) -> Shape:
    return Shape(
        kind=int(params[0]),
        center=params[1:4],
        radius=float(params[4]),
        half=params[5:8],
        rotation=params[8:17].reshape(3, 3),
        segment=params[17:20],
        restitution=float(params[20]),
        friction=friction,
    )


def shape_bounds(params: np.ndarray) -> np.ndarray:
    """(C, 6): each collider's axis-aligned box [lo (3), hi (3)] at its reference position.

    The broad phase of both kernels: a particle whose ball (its step's segment
    and its radius) misses a collider's box, grown by how far the collider moved
    in the step, cannot touch the collider, so neither kernel looks further.
    """
    out = np.zeros((params.shape[0], 6))
    for c, pr in enumerate(params):  # colliders, not particles
        kind, center = int(pr[0]), pr[1:4]
        if kind == SPHERE:
            ext = np.full(3, pr[4])
        elif kind == CAPSULE:
            ext = np.abs(pr[17:20]) + pr[4]
        else:
            ext = np.abs(pr[8:17].reshape(3, 3)) @ pr[5:8]
        out[c, :3] = center - ext
        out[c, 3:] = center + ext
    return out


#: slack of the broad phase: relative, on a particle's radius and a collider's box
#: (far more than rounding in the exact tests that follow it)
BROAD_RELATIVE = 1e-6


def _grown_box(
    bounds: np.ndarray, off0: np.ndarray, off1: np.ndarray, longest: float
) -> tuple[np.ndarray, np.ndarray]:
    """A collider's box where it ends the step, grown by how far it moved and a margin
    (``longest``: the longest extent of a particle's step, for the tracing's tolerance)."""
    shift = off1 - off0
    grow = (
        float(np.sqrt(dot3(shift, shift)))
        + BROAD_RELATIVE * (1.0 + float(np.abs(bounds).max()))
        + 1e-8 * (1.0 + longest)
    )
    return bounds[:3] + off1 - grow, bounds[3:] + off1 + grow


def _boxes(
    x_old: np.ndarray, x: np.ndarray, radius: np.ndarray, rows: np.ndarray, project_only: bool
) -> tuple[np.ndarray, np.ndarray, float]:
    """Boxes (3, k) lo and hi around each row's step (its end alone when ``project_only``), grown by
    its radius, and the longest extent of a step.

    A particle that touches a shape during its step has its segment within its
    radius of the shape, so within its radius of the shape's box: one that
    misses the box is left alone by the exact tests too (they only change
    particles whose segment reaches the shape).
    """
    xs, r = x[rows], radius[rows] * (1.0 + BROAD_RELATIVE) + 1e-12
    if project_only:
        lo, hi, longest = xs - r[:, None], xs + r[:, None], 0.0
    else:
        xo = x_old[rows]
        lo, hi = np.minimum(xo, xs), np.maximum(xo, xs)
        longest = float((hi - lo).max(initial=0.0))
        lo -= r[:, None]
        hi += r[:, None]
    return np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T), longest


def _overlap(lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
    """Indices of the boxes (3, k) that overlap the box [box_lo, box_hi]."""
    m = hi[0] >= box_lo[0]
    for a in range(3):
        if a:
            m &= hi[a] >= box_lo[a]
        m &= lo[a] <= box_hi[a]
    return np.flatnonzero(m)


def resolve_numpy(
    params: np.ndarray,
    friction: np.ndarray,
    off0: np.ndarray,
    off1: np.ndarray,
    x_old: np.ndarray,
    v_old: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    dt: float,
    radius: np.ndarray,
    movable: np.ndarray,
    project_only: bool = False,
    bounds: np.ndarray | None = None,
    kappa: float = 0.5,
) -> bool:
    """Resolve the step x_old -> x against every collider, in place (NumPy kernel).

    ``project_only``: no time of impact, only push out whatever is inside
    (after particle contacts moved particles). ``bounds``: :func:`shape_bounds`
    of ``params`` (computed when not given). ``kappa``: the method's energy shift
    (:func:`animsim.collisions.kept_bounce_speed`).
    """
    if bounds is None:
        bounds = shape_bounds(params)
    mov = np.flatnonzero(movable)
    if mov.size == 0:
        return False
    lo_p, hi_p, longest = _boxes(x_old, x, radius, mov, project_only)
    changed = False
    for c in range(params.shape[0]):  # colliders, not particles
        shape = shape_of(params[c], float(friction[c]))
        center = shape.center + off1[c]
        u = (off1[c] - off0[c]) / dt  # the collider's velocity over the step
        near = _overlap(lo_p, hi_p, *_grown_box(bounds[c], off0[c], off1[c], longest))
        if near.size == 0:
            continue
        rows = mov[near]
        if project_only:
            if _project(shape, center, u, x, v, rows, radius):
                changed = True
                lo_p[:, near], hi_p[:, near], _ = _boxes(x_old, x, radius, rows, True)
            continue
        shift = off1[c] - off0[c]
        # Exact filter: the relative segment lies in the ball around its midpoint
        # of radius half its length; if that ball misses the shape, so does the segment.
        p0_all = x_old[rows] + shift
        seg = x[rows] - p0_all
        mid = p0_all + 0.5 * seg  # the numba kernel's midpoint, to the bit
        half_len = 0.5 * np.sqrt(dot3(seg, seg))
        d_mid, _ = shape.signed_distance(mid, off1[c])
        keep = d_mid - radius[rows] <= half_len * (1 + 1e-12) + 1e-12
        cand = rows[keep]
        if cand.size == 0:
            continue
        r = radius[cand]
        p0 = p0_all[keep]
        p1 = x[cand]
        sg = p1 - p0
        length = np.sqrt(dot3(sg, sg))
        tol = 1e-9 * (1.0 + length)
        s = np.zeros(len(cand))
        hit = np.zeros(len(cand), dtype=bool)
        alive = np.ones(len(cand), dtype=bool)
        d_start = np.zeros(len(cand))  # each row's distance at the step's start (the first march)
        for it in range(MARCH_STEPS):  # sphere tracing, vectorised over candidates
            idx = np.flatnonzero(alive)
            if idx.size == 0:
                break
            d, _ = sdf(
                shape.kind,
                p0[idx] + s[idx, None] * sg[idx] - center,
                shape.radius,
                shape.half,
                shape.rotation,
                shape.segment,
            )
            d = d - r[idx]
            if it == 0:
                d_start[idx] = d
            touched = d <= tol[idx]
            hit[idx[touched]] = True
            step = np.divide(d, length[idx], out=np.full(idx.size, 2.0), where=length[idx] > 0)
            s[idx] = np.where(touched, s[idx], s[idx] + step)
            alive[idx[touched | (s[idx] > 1.0)]] = False
        grazing = np.flatnonzero(alive)  # the march gave up: neither touching nor past the end
        if grazing.size:
            along = _path_distance(shape, center, p0, sg, r, grazing)
            touched, s_touch = _first_touch(along, s[grazing], tol[grazing])
            hit[grazing] = touched
            s[grazing] = s_touch
        h = np.flatnonzero(hit)
        if h.size:
            changed = True
            rows_hit = cand[h]
            sh = np.minimum(s[h], 1.0)[:, None]
            xc = p0[h] + sh * sg[h]
            vo, vh = v_old[rows_hit], v[rows_hit]
            mean_acc = (vh - vo) / dt
            vc = vo + sh * (vh - vo) - u  # relative velocity at the contact
            _, n = sdf(shape.kind, xc - center, shape.radius, shape.half, shape.rotation, shape.segment)
            if shape.kind == BOX:
                _edge_face(shape, xc - center, vh - u, tol[h], n)
            vn = dot3(vc, n)
            approaching = vn < 0
            an = dot3(mean_acc, n)
            pressing = np.maximum(-an, 0.0)
            resting = approaching & (-vn <= RESTING_STEPS * pressing * dt)
            e = np.where(resting, 0.0, shape.restitution)
            vn_new = np.where(approaching, -e * vn, vn)
            rest = (1.0 - sh) * dt
            if kappa != 0.0 and shape.restitution > 0.0:
                bounce = approaching & ~resting
                u0 = dot3(vo - u, n)
                w = kept_bounce_speed(u0, np.maximum(d_start[h], 0.0), an, rest[:, 0], e, kappa * dt)
                vn_new = np.where(bounce & (w > 0.0), w, vn_new)
            # A contact that the step's acceleration presses back onto the surface before the
            # step ends rests on it: the surface's reaction takes the normal speed left and
            # cancels the press for the rest of the step (and friction takes its share of that
            # reaction, -an rest). Flown on with the press, the particle went into the shape
            # and relied on the projection, which cannot see a point on the plane of a box's
            # face (a box sliding flush with the floor then lost the grains it pushed).
            settled = (an < 0.0) & (vn_new + an * rest[:, 0] <= 0.0)
            reaction = np.where(settled, -an * rest[:, 0], 0.0)
            vn_new = np.where(settled, 0.0, vn_new)
            vt = vc - vn[:, None] * n
            vt = apply_friction(vt, np.abs(vn_new - vn) + reaction, shape.friction)
            vr = vt + vn_new[:, None] * n
            if shape.friction != 0.0:  # held still on the surface: no flight after the impact
                hold_by_static_friction(vr, vn_new, mean_acc, n, shape.friction)
            pressed = dot3(mean_acc, n)
            mean_acc = mean_acc - np.where(settled & (pressed < 0.0), pressed, 0.0)[:, None] * n
            x[rows_hit] = xc + rest * vr + 0.5 * rest * rest * mean_acc
            v[rows_hit] = vr + u + rest * mean_acc
        if _project(shape, center, u, x, v, cand, radius):
            changed = True
        # the rows looked at may have moved: their boxes follow them
        lo_p[:, near], hi_p[:, near], moved = _boxes(x_old, x, radius, rows, False)
        longest = max(longest, moved)
    return changed


def _project(
    shape: Shape,
    center: np.ndarray,
    u: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    idx: np.ndarray,
    radius: np.ndarray,
) -> bool:
    """Put any of ``idx`` still inside the shape on its surface; stop its inward relative motion."""
    d, n = sdf(shape.kind, x[idx] - center, shape.radius, shape.half, shape.rotation, shape.segment)
    d = d - radius[idx]
    sel = d < 0
    if not sel.any():
        return False
    rows = idx[sel]
    n = n[sel]
    xb = x[rows] - d[sel, None] * n
    # Rounding can leave the projected point a hair inside; push until it is not.
    for _ in range(4):
        db, _ = sdf(shape.kind, xb - center, shape.radius, shape.half, shape.rotation, shape.segment)
        db = db - radius[rows]
        still = db < 0
        if not still.any():
            break
        xb[still] += (np.spacing(np.abs(xb[still]).max(axis=1) + 1.0) * 4 - db[still])[:, None] * n[still]
    x[rows] = xb
    vr = v[rows] - u
    vn = dot3(vr, n)
    inward = np.minimum(vn, 0.0)
    vt = vr - vn[:, None] * n
    vt = apply_friction(vt, -inward, shape.friction)
    v[rows] = vt + (vn - inward)[:, None] * n + u
    return True


# --- numba twin ------------------------------------------------------------------------------
# Module-level helpers (compiled with the kernels that call them, animsim.elements.numba_helper):
# the step-by-step kernel and the fused stage kernel run the same code.


@numba_helper
def _edge_face1(pr, px, py, pz, wx, wy, wz, tol, n):  # pragma: no cover - compiled
    """:func:`_edge_face` for one point, into ``n``: the same operations."""
    q0 = pr[8] * px + pr[11] * py + pr[14] * pz
    q1 = pr[9] * px + pr[12] * py + pr[15] * pz
    q2 = pr[10] * px + pr[13] * py + pr[16] * pz
    count = 0
    top = -np.inf
    best = np.inf
    face = -1
    sign = 1.0
    for j in range(3):
        qj = q0 if j == 0 else (q1 if j == 1 else q2)
        ej = abs(qj) - pr[5 + j]
        top = max(top, ej)
        if ej >= -tol:
            count += 1
            sj = -1.0 if qj < 0 else 1.0
            into = sj * ((pr[8 + j] * wx + pr[11 + j] * wy) + pr[14 + j] * wz)
            if into < best:
                best = into
                face = j
                sign = sj
    if count >= 2 and top <= tol and face >= 0:
        n[0] = sign * pr[8 + face]
        n[1] = sign * pr[11 + face]
        n[2] = sign * pr[14 + face]


@numba_helper
def _first_touch1(pr, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz, r, tol, s0, n):  # pragma: no cover
    """:func:`_first_touch` for one path: (hit, s), the same steps."""
    touch = np.nan
    if _sdf1(pr, p0x + sgx - cx, p0y + sgy - cy, p0z + sgz - cz, n) - r <= tol:
        touch = 1.0
    a, b = s0, 1.0
    for _ in range(GOLDEN_STEPS):
        if not np.isnan(touch):
            break
        c = b - INV_PHI * (b - a)
        d = a + INV_PHI * (b - a)
        fc = _sdf1(pr, p0x + c * sgx - cx, p0y + c * sgy - cy, p0z + c * sgz - cz, n) - r
        fd = _sdf1(pr, p0x + d * sgx - cx, p0y + d * sgy - cy, p0z + d * sgz - cz, n) - r
        if fc <= tol:
            touch = c
        elif fd <= tol:
            touch = d
        if fc <= fd:
            b = d
        else:
            a = c
    if np.isnan(touch):
        return False, s0
    lo, hi = s0, touch
    for _ in range(BISECT_STEPS):
        mid = 0.5 * (lo + hi)
        if _sdf1(pr, p0x + mid * sgx - cx, p0y + mid * sgy - cy, p0z + mid * sgz - cz, n) - r <= tol:
            hi = mid
        else:
            lo = mid
    return True, hi


@numba_helper
def _sdf1(pr, px, py, pz, out_n):  # pragma: no cover - compiled
    """Signed distance of one point p (relative to the centre) and its normal (into ``out_n``)."""
    kind = int(pr[0])
    if kind == 0:
        ln = np.sqrt(px * px + py * py + pz * pz)
        if ln > 0:
            out_n[0] = px / ln
            out_n[1] = py / ln
            out_n[2] = pz / ln
        else:
            out_n[0] = 0.0
            out_n[1] = 1.0
            out_n[2] = 0.0
        return ln - pr[4]
    if kind == 2:
        sx, sy, sz = pr[17], pr[18], pr[19]
        ss = sx * sx + sy * sy + sz * sz
        t = 0.0
        if ss > 0:
            t = (px * sx + py * sy + pz * sz) / ss
            if t < -1.0:
                t = -1.0
            elif t > 1.0:
                t = 1.0
        wx, wy, wz = px - t * sx, py - t * sy, pz - t * sz
        ln = np.sqrt(wx * wx + wy * wy + wz * wz)
        if ln > 0:
            out_n[0] = wx / ln
            out_n[1] = wy / ln
            out_n[2] = wz / ln
        else:
            sn = np.sqrt(ss)
            if abs(sx) < 0.9 * sn:  # cross(s, x-axis)
                cx, cy, cz = 0.0, sz, -sy
            else:  # cross(s, y-axis)
                cx, cy, cz = -sz, 0.0, sx
            cn = np.sqrt(cx * cx + cy * cy + cz * cz)
            if cn > 0:
                out_n[0] = cx / cn
                out_n[1] = cy / cn
                out_n[2] = cz / cn
            else:
                out_n[0] = 0.0
                out_n[1] = 1.0
                out_n[2] = 0.0
        return ln - pr[4]
    # box: q = R^T p, R row major at pr[8:17]
    q0 = pr[8] * px + pr[11] * py + pr[14] * pz
    q1 = pr[9] * px + pr[12] * py + pr[15] * pz
    q2 = pr[10] * px + pr[13] * py + pr[16] * pz
    e0 = abs(q0) - pr[5]
    e1 = abs(q1) - pr[6]
    e2 = abs(q2) - pr[7]
    s0 = -1.0 if q0 < 0 else 1.0
    s1 = -1.0 if q1 < 0 else 1.0
    s2 = -1.0 if q2 < 0 else 1.0
    o0 = max(e0, 0.0)
    o1 = max(e1, 0.0)
    o2 = max(e2, 0.0)
    ol = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    if ol > 0:
        n0, n1, n2 = s0 * o0 / ol, s1 * o1 / ol, s2 * o2 / ol
        d = ol
    else:
        n0 = n1 = n2 = 0.0
        if e0 >= e1 and e0 >= e2:
            n0 = s0
            d = e0
        elif e1 >= e2:
            n1 = s1
            d = e1
        else:
            n2 = s2
            d = e2
    out_n[0] = pr[8] * n0 + pr[9] * n1 + pr[10] * n2
    out_n[1] = pr[11] * n0 + pr[12] * n1 + pr[13] * n2
    out_n[2] = pr[14] * n0 + pr[15] * n1 + pr[16] * n2
    return d


@numba_helper
def _friction1(vt, dvn, mu):  # pragma: no cover - compiled
    if mu == 0.0:
        return
    sp = np.sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2])
    keep = 0.0
    if sp > 0:
        keep = max(sp - mu * dvn, 0.0) / sp
    for a in range(3):
        vt[a] *= keep


@numba_helper
def _collide(
    params,
    friction,
    bounds,
    off0,
    off1,
    x_old,
    v_old,
    x,
    v,
    dt,
    radius,
    movable,
    inv_mass,
    project_only,
    kappa,
):  # pragma: no cover - compiled
    """The numba kernel: :func:`resolve_numpy`'s algorithm, one particle at a time.

    Particles are independent here, so each runs through every collider in turn
    (the NumPy kernel's order for that particle), with the same broad phase.
    """
    n_col = params.shape[0]
    lo = np.empty((n_col, 3))
    hi = np.empty((n_col, 3))
    cen = np.empty((n_col, 3))
    sh = np.empty((n_col, 3))
    uu = np.empty((n_col, 3))
    for c in range(n_col):
        # _grown_box and the centre and velocity of resolve_numpy, operation for operation
        big = 0.0
        for a in range(6):
            big = max(big, abs(bounds[c, a]))
        d0 = off1[c, 0] - off0[c, 0]
        d1 = off1[c, 1] - off0[c, 1]
        d2 = off1[c, 2] - off0[c, 2]
        grow = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) + 1e-6 * (1.0 + big) + 1e-8
        for a in range(3):
            lo[c, a] = bounds[c, a] + off1[c, a] - grow
            hi[c, a] = bounds[c, 3 + a] + off1[c, a] + grow
            cen[c, a] = params[c, 1 + a] + off1[c, a]
            sh[c, a] = off1[c, a] - off0[c, a]
            uu[c, a] = sh[c, a] / dt
    changed = False
    n = np.zeros(3)
    vt = np.zeros(3)
    acc = np.zeros(3)
    for i in range(x.shape[0]):
        if not movable[i] or not inv_mass[i] > 0:
            continue
        r = radius[i]
        stale = True
        lx = ly = lz = hx = hy = hz = 0.0
        for c in range(n_col):
            if stale:  # the box of _boxes
                rr = r * (1.0 + 1e-6) + 1e-12
                if project_only:
                    lx, ly, lz = x[i, 0], x[i, 1], x[i, 2]
                    hx, hy, hz = lx, ly, lz
                else:
                    lx, hx = min(x_old[i, 0], x[i, 0]), max(x_old[i, 0], x[i, 0])
                    ly, hy = min(x_old[i, 1], x[i, 1]), max(x_old[i, 1], x[i, 1])
                    lz, hz = min(x_old[i, 2], x[i, 2]), max(x_old[i, 2], x[i, 2])
                    # the tracing's tolerance grows with the step's length
                    rr += 1e-8 * max(hx - lx, max(hy - ly, hz - lz))
                lx -= rr
                ly -= rr
                lz -= rr
                hx += rr
                hy += rr
                hz += rr
                stale = False
            if not (
                hx >= lo[c, 0]
                and hy >= lo[c, 1]
                and hz >= lo[c, 2]
                and lx <= hi[c, 0]
                and ly <= hi[c, 1]
                and lz <= hi[c, 2]
            ):
                continue
            pr = params[c]
            mu = friction[c]
            e_rest = pr[20]
            cx, cy, cz = cen[c, 0], cen[c, 1], cen[c, 2]
            shx, shy, shz = sh[c, 0], sh[c, 1], sh[c, 2]
            ux, uy, uz = uu[c, 0], uu[c, 1], uu[c, 2]
            if project_only:
                sgx = sgy = sgz = 0.0
                p0x, p0y, p0z = x[i, 0], x[i, 1], x[i, 2]
                length = 0.0
                dm = -1.0
            else:
                p0x, p0y, p0z = x_old[i, 0] + shx, x_old[i, 1] + shy, x_old[i, 2] + shz
                sgx, sgy, sgz = x[i, 0] - p0x, x[i, 1] - p0y, x[i, 2] - p0z
                length = np.sqrt(sgx * sgx + sgy * sgy + sgz * sgz)
                dm = _sdf1(pr, p0x + 0.5 * sgx - cx, p0y + 0.5 * sgy - cy, p0z + 0.5 * sgz - cz, n) - r
            if not (dm <= 0.5 * length * (1 + 1e-12) + 1e-12):
                continue
            stale = True  # looked at: it may move
            tol = 1e-9 * (1.0 + length)
            s = 0.0
            hit = False
            d_start = 0.0
            for it in range(0 if project_only else MARCH_STEPS):
                d = _sdf1(pr, p0x + s * sgx - cx, p0y + s * sgy - cy, p0z + s * sgz - cz, n) - r
                if it == 0:
                    d_start = d
                if d <= tol:
                    hit = True
                    break
                s += d / length if length > 0 else 2.0
                if s > 1.0:
                    break
            if not hit and not project_only and s <= 1.0:  # the march gave up: a grazing path
                hit, s = _first_touch1(pr, p0x, p0y, p0z, sgx, sgy, sgz, cx, cy, cz, r, tol, s, n)
            if hit:
                changed = True
                if s > 1.0:
                    s = 1.0
                xcx, xcy, xcz = p0x + s * sgx, p0y + s * sgy, p0z + s * sgz
                _sdf1(pr, xcx - cx, xcy - cy, xcz - cz, n)
                if int(pr[0]) == BOX:  # at an edge: the face it runs into (_edge_face)
                    _edge_face1(
                        pr, xcx - cx, xcy - cy, xcz - cz, v[i, 0] - ux, v[i, 1] - uy, v[i, 2] - uz, tol, n
                    )
                for a in range(3):
                    acc[a] = (v[i, a] - v_old[i, a]) / dt
                vcx = v_old[i, 0] + s * (v[i, 0] - v_old[i, 0]) - ux
                vcy = v_old[i, 1] + s * (v[i, 1] - v_old[i, 1]) - uy
                vcz = v_old[i, 2] + s * (v[i, 2] - v_old[i, 2]) - uz
                vn = vcx * n[0] + vcy * n[1] + vcz * n[2]
                an = acc[0] * n[0] + acc[1] * n[1] + acc[2] * n[2]
                pressing = max(-an, 0.0)
                vn_new = vn
                if vn < 0:
                    e = e_rest
                    if -vn <= RESTING_STEPS * pressing * dt:
                        e = 0.0
                    vn_new = -e * vn
                    if kappa != 0.0 and e > 0.0:
                        u0 = (v_old[i, 0] - ux) * n[0] + (v_old[i, 1] - uy) * n[1] + (v_old[i, 2] - uz) * n[2]
                        w = kept_bounce_speed(u0, max(d_start, 0.0), an, (1.0 - s) * dt, e, kappa * dt)
                        if w > 0.0:
                            vn_new = w
                rest = (1.0 - s) * dt
                settled = an < 0.0 and vn_new + an * rest <= 0.0  # resting (resolve_numpy)
                reaction = 0.0
                if settled:
                    reaction = -an * rest
                    vn_new = 0.0
                vt[0] = vcx - vn * n[0]
                vt[1] = vcy - vn * n[1]
                vt[2] = vcz - vn * n[2]
                _friction1(vt, abs(vn_new - vn) + reaction, mu)
                vrx = vt[0] + vn_new * n[0]
                vry = vt[1] + vn_new * n[1]
                vrz = vt[2] + vn_new * n[2]
                if static_friction_holds(
                    vrx, vry, vrz, vn_new, acc[0], acc[1], acc[2], n[0], n[1], n[2], mu, mu != 0.0
                ):
                    acc[0] = 0.0
                    acc[1] = 0.0
                    acc[2] = 0.0
                ap = acc[0] * n[0] + acc[1] * n[1] + acc[2] * n[2]
                if settled and ap < 0.0:
                    acc[0] -= ap * n[0]
                    acc[1] -= ap * n[1]
                    acc[2] -= ap * n[2]
                x[i, 0] = xcx + rest * vrx + 0.5 * rest * rest * acc[0]
                x[i, 1] = xcy + rest * vry + 0.5 * rest * rest * acc[1]
                x[i, 2] = xcz + rest * vrz + 0.5 * rest * rest * acc[2]
                v[i, 0] = vrx + ux + rest * acc[0]
                v[i, 1] = vry + uy + rest * acc[1]
                v[i, 2] = vrz + uz + rest * acc[2]
            # projection (every candidate, as the NumPy kernel)
            d = _sdf1(pr, x[i, 0] - cx, x[i, 1] - cy, x[i, 2] - cz, n) - r
            if d < 0:
                changed = True
                bx, by, bz = x[i, 0] - d * n[0], x[i, 1] - d * n[1], x[i, 2] - d * n[2]
                nx, ny, nz = n[0], n[1], n[2]
                for _ in range(4):
                    db = _sdf1(pr, bx - cx, by - cy, bz - cz, n) - r
                    if db >= 0:
                        break
                    big = max(abs(bx), max(abs(by), abs(bz))) + 1.0
                    push = np.spacing(big) * 4 - db
                    bx += push * nx
                    by += push * ny
                    bz += push * nz
                x[i, 0], x[i, 1], x[i, 2] = bx, by, bz
                rvx, rvy, rvz = v[i, 0] - ux, v[i, 1] - uy, v[i, 2] - uz
                vn = rvx * nx + rvy * ny + rvz * nz
                inward = min(vn, 0.0)
                vt[0] = rvx - vn * nx
                vt[1] = rvy - vn * ny
                vt[2] = rvz - vn * nz
                _friction1(vt, -inward, mu)
                v[i, 0] = vt[0] + (vn - inward) * nx + ux
                v[i, 1] = vt[1] + (vn - inward) * ny + uy
                v[i, 2] = vt[2] + (vn - inward) * nz + uz
    return changed


def _stage_kernel(x_old, v_old, x, v, dt, inv_mass, fp, ip):  # pragma: no cover - compiled
    """Static colliders as a fused stage (stage_signature): fp = [C, params, friction, bounds, kappa, radius],
    ip = the rows colliders act on (1) or not (0)."""
    n_col = int(fp[0])
    o = 1
    params = np.ascontiguousarray(fp[o : o + PARAMS * n_col]).reshape((n_col, PARAMS))
    o += PARAMS * n_col
    friction = fp[o : o + n_col]
    o += n_col
    bounds = np.ascontiguousarray(fp[o : o + 6 * n_col]).reshape((n_col, 6))
    o += 6 * n_col
    kappa = fp[o]
    radius = fp[o + 1 : o + 1 + x.shape[0]]
    still = np.zeros((n_col, 3))
    return _collide(
        params, friction, bounds, still, still, x_old, v_old, x, v, dt, radius, ip, inv_mass, False, kappa
    )


def numba_kernel():
    """The step-by-step numba kernel (:func:`_collide`), compiled or loaded on first use."""
    jit_kernel(_stage_kernel, stage=True)  # compiles this module's helpers (_collide among them)
    return globals()["_collide"]
