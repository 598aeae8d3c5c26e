"""Particles against rigid bodies, both ways: rain on a crate, a ball through a cloth curtain.

After each step (after the bodies met the planes and colliders), every particle (listed,
structure, emitted; a point or a sphere of its radius) found inside a body's shape is a
contact, with the shape's own signed distance in its frame
(:func:`animsim.bodies.contact_detection.local_sdf`) and its outward normal n. The contacts are
resolved as one system:

* **Velocities**: normal impulses along n at the body's surface point, with the body's
  restitution (an approach slower than what the step's relative acceleration adds in two
  steps rests instead of bouncing, as on planes) and Coulomb friction with the body's
  friction, accumulated and clamped over a few Jacobi sweeps (Catto, "Iterative Dynamics with
  Temporal Coherence", GDC 2005). A body touched by k particles at once is split into k
  parts of 1/k of its mass and inertia for each contact's effective mass, and takes the sum
  of the impulses (mass splitting: Tonge, Benevolenski and Voroshilov, "Mass splitting for
  jitter-free parallel rigid body simulation", SIGGRAPH 2012): the sweeps converge however
  heavy the particles are against the body, and every impulse is equal and opposite, so
  momentum and angular momentum are kept exactly.
* **Positions**: each particle leaves the body along n by its whole penetration (a pinned
  one pushes the body out instead), then is put back on the front of any plane it was pushed
  behind.

A particle joined to a body by a spring (a rope's end, a hook) does not touch that body: the
spring holds it there. Contacts are found where things are at the end of each step: a particle
faster than (r + t/2) / dt against a body t thick can pass through it (``check`` says so).
"""

from __future__ import annotations

import math

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.bodies.contact_detection import local_sdf, shape_arrays
from animsim.bodies.shapes import BodyShape
from animsim.bodies.sleep import Sleep
from animsim.elements import PlaneProjector, StepStage
from animsim.system import State

#: an approach slower than this many steps of the relative acceleration rests (no bounce)
RESTING_STEPS = 2.0
#: Jacobi sweeps at most, and the change of velocity (m/s) below which they stop
MAX_SWEEPS = 32
SWEEP_TOLERANCE = 1e-10


class ParticleBodyContacts(StepStage):
    """Contacts between the scene's particles and its rigid bodies (module docstring)."""

    def __init__(
        self,
        first: int,
        shapes: tuple[BodyShape, ...],
        inv_mass: np.ndarray,
        inv_inertia: np.ndarray,
        restitution: np.ndarray,
        friction: np.ndarray,
        particle_rows: np.ndarray,
        radius: np.ndarray,
        joined: set[tuple[int, int]],
    ) -> None:
        self.first = first
        self.count = len(shapes)
        self.kind, self.dims, self.bound = shape_arrays(shapes)
        self.inv_mass = np.asarray(inv_mass, dtype=np.float64)
        self.inv_inertia = np.asarray(inv_inertia, dtype=np.float64)
        self.restitution = np.asarray(restitution, dtype=np.float64)
        self.friction = np.asarray(friction, dtype=np.float64)
        #: (N,) the rows that are particles (not body centres)
        self.rows = np.flatnonzero(particle_rows)
        self.radius = np.asarray(radius, dtype=np.float64)
        #: (particle row, body) pairs a spring joins: no contact between them
        self.joined = joined
        self.thinnest = min((s.thickness for s in shapes), default=math.inf)
        #: a bounce below restitution 1, or friction, takes energy out (the watchdog's verdict)
        self.dissipative = bool((self.restitution < 1.0).any() or (self.friction > 0.0).any())
        #: the impulse planes (compile sets it): a particle pushed out of a body stays in front of them
        self.planes: PlaneProjector | None = None
        #: the bodies' sleep (animsim.bodies.sleep): a particle that touches a sleeping body wakes it
        self.sleep: Sleep | None = None
        self.label = (
            f"particle-body contacts: every particle against {self.count} rigid bod"
            f"{'y' if self.count == 1 else 'ies'}; impulses with the body's restitution and Coulomb "
            f"friction, Jacobi sweeps with the bodies' mass split among their contacts (at most "
            f"{MAX_SWEEPS}), particles pushed out of the shapes"
        )

    def stability_note(self, dt: float) -> str | None:
        r = float(self.radius[self.rows].min()) if self.rows.size else 0.0
        return (
            f"particle-body contacts: found at step ends, so a particle faster than (r + t/2) / dt = "
            f"{(r + 0.5 * self.thinnest) / dt:.3g} m/s can pass through a body (r = {r:.3g} m, the "
            f"smallest particle radius; t = {self.thinnest:.3g} m, the thinnest body)"
        )

    def _contacts(
        self, state: State
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """(particle rows, bodies, normals (K,3), arms from the body centre (K,3), depths) of the
        particles inside a body's shape, in (body, row) order; None when there are none."""
        x = state.particle_position
        xb = x[self.first : self.first + self.count]
        q = state.body_orientation
        live = self.rows
        if state.particle_alive is not None:
            live = live[state.particle_alive[live]]
        parts: list[tuple[np.ndarray, ...]] = []
        for b in range(self.count):
            reach = self.bound[b] + self.radius[live]
            gap = x[live] - xb[b]
            near = live[np.einsum("ij,ij->i", gap, gap) <= reach * reach * (1.0 + 1e-9)]
            if near.size == 0:
                continue
            if self.joined:
                near = near[[(int(i), b) not in self.joined for i in near]]
                if near.size == 0:
                    continue
            qb = np.repeat(q[b : b + 1], near.size, axis=0)
            local = quat.rotate_inverse(qb, x[near] - xb[b])
            d, n_local = local_sdf(
                np.full(near.size, self.kind[b]), np.repeat(self.dims[b : b + 1], near.size, axis=0), local
            )
            depth = self.radius[near] - d
            inside = depth > 0.0
            if not inside.any():
                continue
            rows, n_local, d, depth = near[inside], n_local[inside], d[inside], depth[inside]
            n = quat.rotate(qb[: rows.size], n_local)
            arm = x[rows] - xb[b] - d[:, None] * n  # the body's surface point under the particle
            parts.append((rows, np.full(rows.size, b), n, arm, depth))
        if not parts:
            return None
        return tuple(np.concatenate(p) for p in zip(*parts, strict=True))  # type: ignore[return-value]

    def apply(
        self, state: State, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float
    ) -> bool:
        found = self._contacts(state)
        if found is None:
            return False
        rows, body, n, arm, depth = found
        if self.sleep is not None:  # woken now, it answers the particle in this step
            self.sleep.wake(np.unique(body))
        x, v = state.particle_position, state.particle_velocity
        brow = self.first + body
        w_body = state.body_angular_velocity
        wp = state.particle_inv_mass[rows]
        wb = self.inv_mass[body]
        # the body's mass and inertia split among its contacts (mass splitting)
        split = np.bincount(body, minlength=self.count)[body].astype(np.float64)
        rot = quat.to_matrix(state.body_orientation)
        inv_i = np.einsum("bij,bj,bkj->bik", rot, self.inv_inertia, rot)[body]  # R I^-1 R^T
        rn = np.cross(arm, n)
        ang_n = np.einsum("kij,kj->ki", inv_i, rn)  # I_w^-1 (r x n)
        k_n = wp + split * (wb + np.einsum("ki,ki->k", rn, ang_n))
        movable = k_n > 0.0
        inv_k = np.where(movable, 1.0 / np.where(movable, k_n, 1.0), 0.0)

        def relative(rows_v: np.ndarray, vb: np.ndarray, wb_: np.ndarray) -> np.ndarray:
            return rows_v - (vb + np.cross(wb_, arm))

        vb, wbv = v[brow], w_body[body]
        rel = relative(v[rows], vb, wbv)
        vn0 = np.einsum("ki,ki->k", rel, n)
        # the step's relative acceleration along n: what resting contact presses with
        dv_rel = (v[rows] - v_old[rows]) - (v[brow] - v_old[brow])
        pressing = np.maximum(-np.einsum("ki,ki->k", dv_rel, n), 0.0)
        e = self.restitution[body]
        mu = self.friction[body]
        bounce = vn0 < -RESTING_STEPS * pressing
        target = np.where(bounce, -e * vn0, 0.0)
        jn = np.zeros(rows.size)
        jt = np.zeros((rows.size, 3))
        for _ in range(MAX_SWEEPS):
            vb, wbv = v[brow], w_body[body]
            rel = relative(v[rows], vb, wbv)
            vn = np.einsum("ki,ki->k", rel, n)
            new = np.maximum(jn + (target - vn) * inv_k, 0.0)
            dj = new - jn
            jn = new
            # Coulomb friction: stop the sliding, within mu times the normal impulse so far
            vt = rel - vn[:, None] * n
            want = jt - vt * inv_k[:, None]
            cap = mu * jn
            mag = np.sqrt(np.einsum("ki,ki->k", want, want))
            want = np.where((mag > cap)[:, None], want * (cap / np.where(mag > 0, mag, 1.0))[:, None], want)
            dt_imp = want - jt
            jt = want
            impulse = dj[:, None] * n + dt_imp  # on the particle; its opposite on the body
            np.add.at(v, rows, wp[:, None] * impulse)  # a particle may touch two bodies
            np.add.at(v, brow, -wb[:, None] * impulse)
            np.add.at(w_body, body, -np.einsum("kij,kj->ki", inv_i, np.cross(arm, impulse)))
            change = float(np.max(np.abs(impulse) * np.maximum(wp, wb)[:, None], initial=0.0))
            if change <= SWEEP_TOLERANCE:
                break
        # positions: a particle leaves the body by the whole penetration; a pinned one (which
        # cannot move) pushes the body out instead, by the mean of its pinned contacts' pushes
        free = wp > 0.0
        np.add.at(x, rows[free], depth[free, None] * n[free])
        held = ~free & (wb > 0.0)
        if held.any():
            per_body = np.bincount(body[held], minlength=self.count)[body[held]].astype(np.float64)
            np.add.at(x, brow[held], -(depth[held] / per_body)[:, None] * n[held])
        if self.planes is not None:  # pushed out of a body, never behind a plane
            moved = np.unique(rows)
            self.planes.project_rows(x, v, moved)
        return True
