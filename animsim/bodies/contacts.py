"""Contacts of rigid bodies: against planes, against signed-distance colliders, and between bodies.

Model (after each integrator step, as a step stage):

1. **Detection.** Every shape is a few contact spheres fixed in its body
   (:mod:`animsim.bodies.shapes`): a box's corners, a sphere's centre, a
   capsule's end centres. A contact is a sphere whose surface is behind a plane
   or inside another body's shape (signed distance < 0).
2. **Impulses** (Baraff 1997, "Rigid Body Simulation", section 8, colliding
   contact; solved as sequential impulses, Catto 2005): at the contact point, with
   lever arms r_a, r_b from the centres of mass and unit normal n (from b to a),
   the normal impulse j changes the approach speed v_n = n . (v_a + w_a x r_a -
   v_b - w_b x r_b) by j K, K = 1/m_a + 1/m_b + n . (I_a^-1 (r_a x n)) x r_a + (same for b).
   Its target is -e v_n for an approaching contact, and 0 (resting contact) when
   the approach speed is no more than twice what the forces added in this step:
   that is what gravity alone gives a body lying on a floor, so a resting body
   gets no bounce and does not jitter. Accumulated normal impulses stay >= 0
   (contacts push, never pull); the tangential (Coulomb) impulse stops sliding,
   capped at mu times the normal impulse; where a sphere or a capsule has a
   ``rolling_friction`` mu_r, an angular impulse stops its rolling, capped at mu_r
   times the normal impulse (rolling resistance as Bullet's and MuJoCo's;
   :func:`animsim.bodies.contact_kernels.rolling_total`). The contacts are solved one after the
   other, ``iterations`` times: on NumPy in batches in which no body appears
   twice (a batch is one vectorised update, and the result is the sequential
   one), on numba by a kernel that walks the list. Both write every sum in the
   same order, so the backends agree to the bit.
3. **Shock propagation** (Erleben 2007; :mod:`animsim.bodies.contact_shock`): after the
   sweeps, the contacts are swept again level by level from level 1 up, the bodies below
   each level held still, so a stack ends each step at rest on itself.
4. **Projection.** Each body is moved out of each plane by its deepest
   penetration there, and out of other bodies along the normal (split between
   two free bodies by their inverse masses); a
   bouncing contact is moved out by (1 + e) times the depth, the distance the
   reflected motion would have covered after the impact inside the step. The
   projection changes positions only, never velocities.

Limits (also in the user docs): edges of boxes are not contact points, so
box-box contacts are corner-against-face only (an edge crossing an edge is not
found) and a capsule against a capsule is end-sphere-against-shape only.

The parts live in their own modules: the constants in :mod:`animsim.bodies.contact_constants`,
detection and the contact list in :mod:`animsim.bodies.contact_detection`, the solver in
:mod:`animsim.bodies.contact_solve`, the numba twins in :mod:`animsim.bodies.contact_kernels`;
this module is the step stage that runs them (:class:`BodyContacts`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from animsim.bodies import projection
from animsim.bodies.contact_batches import islands
from animsim.bodies.contact_constants import (
    COLD_SWEEPS,
    ITERATIONS,
    MAX_SWEEPS,
    RESTING_FACTOR,
    SHAPE_CAPSULE,
    SKIN,
    SWEEP_TOLERANCE,
)
from animsim.bodies.contact_detection import (
    Contacts,
    PlaneTable,
    candidate_pairs,
    concat,
    contact_rolling,
    empty_contacts,
    pair_contacts,
    plane_contacts,
    sdf_contacts,
    shape_arrays,
)
from animsim.bodies.contact_follow import follow_impulses
from animsim.bodies.contact_kernels import numba_candidate_pairs, numba_kernels, numba_pair_contacts
from animsim.bodies.contact_shock import shock_pass
from animsim.bodies.contact_solve import solve
from animsim.bodies.shapes import BodyShape, contact_table
from animsim.bodies.sleep import Sleep
from animsim.bodies.warm import WarmStart
from animsim.collisions import energy_shift
from animsim.elements import StepStage


class BodyContacts(StepStage):
    """Step stage: bodies against planes, colliders (signed-distance callbacks) and each other."""

    injects = False
    dissipative = True
    no_closed_form = "its bodies touch planes or each other (contacts have no closed form here)"

    def __init__(
        self,
        first: int,
        inv_mass: np.ndarray,
        inv_inertia: np.ndarray,
        shapes: tuple[BodyShape, ...],
        planes: PlaneTable,
        restitution: np.ndarray,
        friction: np.ndarray,
        backend: str = "numpy",
        colliders: tuple[
            tuple[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], float, float], ...
        ] = (),
        iterations: int = ITERATIONS,
        collider_thickness: float = math.inf,
        collider_offsets: Callable[[float], np.ndarray] | None = None,
        rolling: np.ndarray | None = None,
    ) -> None:
        self.first = first
        #: (B,) each body's rolling resistance (m), None when no body has one (the solve then
        #: runs exactly as without the key)
        self.rolling = None if rolling is None or not (rolling > 0.0).any() else np.asarray(rolling, float)
        #: t -> (C, 3) every collider's displacement from where it was given (keyframed ones
        #: move; None: all static): the bodies meet them where they are, at their velocity
        self.collider_offsets = collider_offsets
        #: the thinnest collider's thinnest extent (stability_note)
        self.collider_thickness = collider_thickness
        self.thinnest_body = min((s.thickness for s in shapes), default=math.inf)
        self.count = len(shapes)
        self.inv_mass = np.ascontiguousarray(inv_mass, dtype=np.float64)
        self.inv_inertia = np.ascontiguousarray(inv_inertia, dtype=np.float64)
        self.points, self.radii, self.counts = contact_table(shapes)
        self.valid = np.arange(self.points.shape[1])[None, :] < self.counts[:, None]
        self.kind, self.dims, self.bound = shape_arrays(shapes)
        self.planes = planes
        self.restitution = np.asarray(restitution, dtype=np.float64)
        self.friction = np.asarray(friction, dtype=np.float64)
        self.colliders = colliders
        self.iterations = iterations
        #: c in "the impulses of a step move a body by c dt dv" (follow_impulses); the compiler sets
        #: it from the integrator (animsim.contact_stages.follow_weight)
        self.follow_weight = 1.0
        self.between_bodies = self.count > 1
        # Verlet list of candidate pairs: bounding spheres grown by SKIN * the largest bound,
        # rebuilt once some body has moved half of that since the last build
        self._skin = SKIN * float(self.bound.max()) if self.count else 0.0
        self._built_at: np.ndarray | None = None
        self._candidates: tuple[np.ndarray, np.ndarray] | None = None
        # the numba kernels find plane contacts and solve; colliders are found on the NumPy
        # path only, so a scene with colliders runs that path on both backends
        self.use_numba = backend == "numba" and not colliders
        self._buffers: tuple[np.ndarray, ...] | None = None
        self.numba_broadphase = backend == "numba"
        #: the last step's impulses, where each step's sweeps start (warm starting)
        self.warm = WarmStart(self.bound, planes.count)
        #: bodies at rest sleep (animsim.bodies.sleep); None: the scene has no ``sleep``
        self.sleep: Sleep | None = None
        #: how many times the candidate list was built, and the list less the sleepers' pairs
        self._builds = 0
        self._awake_key: tuple[int, int] | None = None
        self._awake_pairs = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
        #: the bodies (a, b) of the contacts the last step solved (the islands that may sleep)
        self._solved = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
        kinds = sorted({s.kind for s in shapes})
        parts = []
        if planes.count:
            parts.append(f"{planes.count} plane(s)")
        if colliders:
            parts.append(f"{len(colliders)} collider(s)")
        if self.between_bodies:
            parts.append(
                "each other (sphere-sphere, sphere-box, capsule ends; box-box faces, edges and corners)"
            )
        rolls = (
            ""
            if self.rolling is None
            else " and rolling resistance where a sphere or a capsule touches (a torque up to "
            "rolling_friction times the normal force against its rolling)"
        )
        self.label = (
            f"body contacts: {self.count} {'/'.join(kinds)} bodies against {', '.join(parts)}; "
            f"impulses with restitution and Coulomb friction{rolls}, {iterations} to {MAX_SWEEPS} sweeps ({COLD_SWEEPS} from rest; until a sweep "
            f"changes no velocity by {SWEEP_TOLERANCE:g} m/s), resting below "
            f"{RESTING_FACTOR:g}x the speed forces add per step, velocities settled and positions projected "
            "out from the ground up (shock propagation)"
        )

    def stability_note(self, dt: float) -> str | None:
        """Contacts are found where the bodies are at the end of each step. A contact sphere of
        radius r (0 for a box's corners) is caught inside a thing of thickness t, and pushed
        back out on its own side, only if no step carries it more than r + t / 2: faster, it can
        skip over a collider or another body between two step ends, or be pushed out through
        the far side. Planes are half-spaces: a body behind one is always found and pushed out."""
        if not (self.colliders or self.between_bodies) or not self.valid.any():
            return None
        r = float(self.radii[self.valid].min())
        parts = []
        if self.colliders:
            parts.append(("a collider", self.collider_thickness))
        if self.between_bodies:
            parts.append(("another body", self.thinnest_body))
        t = min(thick for _, thick in parts)
        what = " or ".join(name for name, _ in parts)
        return (
            f"body contacts: found at step ends, so a body faster than (r + t/2) / dt = "
            f"{(r + 0.5 * t) / dt:.3g} m/s can pass through {what} (r = {r:.3g} m, the smallest "
            f"contact sphere of a body, 0 at a box's corners; t = {t:.3g} m, the thinnest one); "
            "planes stop bodies at any speed"
        )

    @property
    def left_out(self) -> list[str]:
        """What body contacts do not simulate (for explain)."""
        out = []
        if self.between_bodies and int((self.kind == SHAPE_CAPSULE).sum()) > 1:
            out.append("capsule-capsule side-on-side contact (only end spheres are detected)")
        return out

    #: its memory between steps (warm starting, sleeping, the candidate list) is kept by
    #: snapshot/restore, so a replay (the watchdog tracing a failure to its first step) makes
    #: the same steps the run made
    replays = True

    def snapshot(self) -> object:
        sleep = None if self.sleep is None else self.sleep.snapshot()
        return (self.warm.snapshot(), sleep, self._built_at, self._candidates, self._builds)

    def restore(self, snap: object) -> None:
        warm, sleep, self._built_at, self._candidates, self._builds = cast(tuple[Any, ...], snap)
        self.warm.restore(warm)
        if self.sleep is not None:
            self.sleep.restore(sleep)
        self._awake_key = None

    def reset(self, state: Any) -> None:
        self._built_at = None
        self._candidates = None
        self._awake_key = None
        self.warm.forget()
        if self.sleep is not None:
            rows = slice(self.first, self.first + self.count)
            self.sleep.reset(state.particle_velocity[rows], state.body_angular_velocity)

    def apply(
        self, state: Any, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float = 0.0
    ) -> bool:
        dt = dt or (t1 - t0)
        rows = slice(self.first, self.first + self.count)
        # views: the solver and the projection change the state in place
        x = state.particle_position[rows]
        v = state.particle_velocity[rows]
        q = state.body_orientation
        w = state.body_angular_velocity
        sleep = self.sleep
        if sleep is not None:  # the sleeping bodies did not move (animsim.bodies.sleep)
            sleep.freeze(x, v, q, w)
        pairs = self.find_pairs(x, q)
        while sleep is not None and (woken := sleep.wake_touched(pairs.a, pairs.b, None)) is not None:
            sleep.unfreeze(woken, x, v, q, w)
            pairs = self.find_pairs(x, q)  # the woken bodies' own contacts too
        dv = v - v_old[rows]
        dx = x - x_old[rows]
        resting = RESTING_FACTOR * np.linalg.norm(dv, axis=1)
        self._old = (x_old[rows], v_old[rows])
        self._solved = (pairs.a[:0], pairs.b[:0])
        if not self.use_numba:
            changed = self._apply_numpy(x, v, q, w, dv, dx, resting, pairs, t0, t1, dt)
        else:
            changed = self._apply_numba(x, v, q, w, dv, dx, resting, pairs, dt)
        if sleep is None:
            return changed
        sleep.settle(x, v, q, w, *self._solved, dt)
        return changed or sleep.any_asleep

    def _apply_numpy(
        self,
        x: np.ndarray,
        v: np.ndarray,
        q: np.ndarray,
        w: np.ndarray,
        dv: np.ndarray,
        dx: np.ndarray,
        resting: np.ndarray,
        pairs: Contacts,
        t0: float,
        t1: float,
        dt: float,
    ) -> bool:
        """:meth:`apply` on NumPy: find the contacts, solve them (:func:`solve`), follow the
        impulses and project; in place on x, v, q, w."""
        offsets = velocities = None
        if self.collider_offsets is not None:  # keyframed colliders: where they are now, how fast
            before, offsets = self.collider_offsets(t0), self.collider_offsets(t1)
            velocities = (offsets - before) / dt
        contacts, surface = self.find(x, q, pairs, offsets, velocities)
        if self.sleep is not None:  # a moving collider wakes what it touches; sleepers sit out
            while (woken := self.sleep.wake_touched(contacts.a, contacts.b, surface)) is not None:
                self.sleep.unfreeze(woken, x, v, q, w)
                x_old, v_old = self._old
                dv[woken], dx[woken] = v[woken] - v_old[woken], x[woken] - x_old[woken]
                resting[woken] = RESTING_FACTOR * np.linalg.norm(dv[woken], axis=1)
                contacts, surface = self.find(x, q, None, offsets, velocities)
            contacts, surface = solved_part(contacts, surface, self.sleep.to_solve(contacts.a, contacts.b))
        if contacts.count == 0:
            return False
        c = contacts
        self._solved = (c.a, c.b)
        jn0, jt0, jr0, local = self.warm.guess(c.a, c.b, c.plane, c.n, c.ra, q)
        v_pre, w_pre = v.copy(), w.copy()
        sweeps, cold = self._sweep_limit(c, jn0)
        mu_r = None if self.rolling is None else contact_rolling(c, self.rolling, self.kind)
        e_used, impact, jn, jt, jr = solve(
            contacts,
            v,
            w,
            q,
            self.inv_mass,
            self.inv_inertia,
            resting,
            self.iterations,
            dv,
            dx,
            energy_shift(self.follow_weight) * dt,
            dt,
            surface,
            (jn0, jt0, jr0),
            sweeps,
            cold,
            islands(c.a, c.b, self.count),
            mu_r,
        )
        level = projection.levels(c.a, c.b, self.inv_mass)
        shock_pass(c, impact, level, q, self.inv_mass, self.inv_inertia, surface, dt, jn, jt, v, w, jr, mu_r)
        self.warm.keep(c.a, c.b, c.plane, c.n, local, jn, jt, jr, self._held())
        h = self.follow_weight * dt
        left = follow_impulses(c, impact, x, q, v - v_pre, w - w_pre, h) if h > 0.0 else c.depth
        push = projection.pushes(c.depth, left, e_used)
        projection.project(c.a, c.b, c.n, push, c.plane, x, self.inv_mass, level)
        return True

    def _apply_numba(
        self,
        x: np.ndarray,
        v: np.ndarray,
        q: np.ndarray,
        w: np.ndarray,
        dv: np.ndarray,
        dx: np.ndarray,
        resting: np.ndarray,
        pairs: Contacts,
        dt: float,
    ) -> bool:
        """:meth:`apply` on numba; in place on x, v, q, w."""
        # numba: plane contacts found body by body, then the whole list (pairs after the planes,
        # as on the NumPy path) solved in list order by one kernel call
        detect, solver = numba_kernels()
        buf = self._plane_buffers()
        found = detect(
            x,
            q,
            self.points,
            self.radii,
            self._awake_counts(),
            self.planes.point,
            self.planes.normal,
            self.planes.restitution,
            self.planes.friction,
            *buf,
        )
        if found == 0 and pairs.count == 0:
            return False
        planes_found = Contacts(
            buf[0][:found],
            self._no_body[:found],
            buf[1][:found],
            self._zero3[:found],
            buf[2][:found],
            buf[3][:found],
            buf[4][:found],
            buf[5][:found],
            buf[6][:found],
        )
        c = concat([planes_found, pairs])
        if self.sleep is not None:
            c, _ = solved_part(c, None, self.sleep.to_solve(c.a, c.b))
        if c.count == 0:
            return False
        self._solved = (c.a, c.b)
        arrays = [np.ascontiguousarray(getattr(c, f)) for f in Contacts.__dataclass_fields__]
        count = c.count
        e_used = np.empty(count)
        impact = np.empty(count, dtype=np.bool_)
        depth_left = np.empty(count)
        jn, jt, jr, local = self.warm.guess(c.a, c.b, c.plane, c.n, c.ra, q)
        sweeps, cold = self._sweep_limit(c, jn)
        mu_r = np.zeros(count) if self.rolling is None else contact_rolling(c, self.rolling, self.kind)
        level = projection.levels(c.a, c.b, self.inv_mass)
        solver(
            count,
            *arrays,
            x,
            v,
            w,
            q,
            self.inv_mass,
            self.inv_inertia,
            resting,
            dv,
            dx,
            self.iterations,
            e_used,
            impact,
            self.follow_weight * dt,
            depth_left,
            energy_shift(self.follow_weight) * dt,
            dt,
            jn,
            jt,
            sweeps,
            cold,
            level,
            islands(c.a, c.b, self.count),
            mu_r,
            jr,
        )
        self.warm.keep(c.a, c.b, c.plane, c.n, local, jn, jt, jr, self._held())
        push = projection.pushes(c.depth, depth_left, e_used)
        projection.project(c.a, c.b, c.n, push, c.plane, x, self.inv_mass, level, True)
        return True

    def _awake_candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """The candidate pairs, less those the sleeping bodies leave out (kept while neither the
        list nor who sleeps changes)."""
        assert self._candidates is not None
        if self.sleep is None or not self.sleep.any_asleep:
            return self._candidates
        key = (self._builds, self.sleep.version)
        if self._awake_key != key:
            i, j = self._candidates
            keep = self.sleep.pairs_to_find(i, j)
            self._awake_pairs, self._awake_key = (i[keep], j[keep]), key
        return self._awake_pairs

    def _held(self) -> np.ndarray | None:
        """The sleeping bodies, whose last impulses the warm start keeps (None: none sleep)."""
        return self.sleep.asleep if self.sleep is not None and self.sleep.any_asleep else None

    def _awake_counts(self) -> np.ndarray:
        """Contact spheres per body for the plane detection: none for a sleeping body."""
        if self.sleep is None or not self.sleep.any_asleep:
            return self.counts
        return np.where(self.sleep.asleep, 0, self.counts)

    @staticmethod
    def _sweep_limit(c: Contacts, start: np.ndarray) -> tuple[int, bool]:
        """(COLD_SWEEPS, True) when bodies touch each other and none of their contacts has an
        impulse to start from (a stack set down: the solve finds its normal impulses first, then
        the friction), else (MAX_SWEEPS, False). Not per contact: a corner that carries no load,
        or a speculative contact, starts from zero in every step of a standing stack."""
        between = c.b >= 0
        cold = bool(between.any()) and not bool((start[between] != 0.0).any())
        return (COLD_SWEEPS, True) if cold else (MAX_SWEEPS, False)

    def _plane_buffers(self) -> tuple[np.ndarray, ...]:
        """Output arrays of the numba plane detection (capacity: every sphere behind every plane)."""
        if self._buffers is None:
            cap = self.count * self.points.shape[1] * max(self.planes.count, 1)
            self._buffers = (
                np.zeros(cap, dtype=np.int64),
                np.zeros((cap, 3)),
                np.zeros((cap, 3)),
                np.zeros(cap),
                np.zeros(cap),
                np.zeros(cap),
                np.zeros(cap, dtype=np.int64),
            )
            self._no_body = np.full(cap, -1, dtype=np.int64)
            self._zero3 = np.zeros((cap, 3))
        return self._buffers

    def find(
        self,
        x: np.ndarray,
        q: np.ndarray,
        pairs: Contacts | None = None,
        offsets: np.ndarray | None = None,
        velocities: np.ndarray | None = None,
    ) -> tuple[Contacts, np.ndarray | None]:
        """Every contact of the bodies at x, q: planes, then colliders (displaced by ``offsets``
        (C, 3) where they move), then pairs; and with ``velocities`` (C, 3), the velocity (K, 3)
        of the surface each contact touches (None: every surface is still)."""
        parts = []
        if self.planes.count:
            valid = self.valid
            if self.sleep is not None and self.sleep.any_asleep:  # a sleeper's stay out of the solve
                valid = valid & ~self.sleep.asleep[:, None]
            parts.append(plane_contacts(x, q, self.points, self.radii, valid, self.planes))
        moving: list[tuple[int, int]] = []  # (collider, its contacts) in list order
        for c, (sdf, e, mu) in enumerate(self.colliders):
            where = None if offsets is None else offsets[c]
            found = sdf_contacts(
                x, q, self.points, self.radii, self.valid, lambda p, o=where, f=sdf: f(p, o), e, mu
            )
            parts.append(found)
            moving.append((c, found.count))
        parts.append(self.find_pairs(x, q) if pairs is None else pairs)
        contacts = concat(parts)
        if velocities is None:
            return contacts, None
        surface = np.zeros((contacts.count, 3))
        at = parts[0].count if self.planes.count else 0
        for c, k in moving:
            surface[at : at + k] = velocities[c]
            at += k
        return contacts, surface

    def find_pairs(self, x: np.ndarray, q: np.ndarray) -> Contacts:
        """Contacts between bodies (none when the scene has one body)."""
        if not self.between_bodies:
            return empty_contacts()
        moved = np.inf if self._built_at is None else float(np.abs(x - self._built_at).max(initial=0.0))
        if not moved <= 0.5 * self._skin / math.sqrt(3.0):  # a NaN position rebuilds too
            grown = self.bound + 0.5 * self._skin
            if self.numba_broadphase and self.count > 1 and np.isfinite(x).all():
                self._candidates = numba_candidate_pairs()(np.ascontiguousarray(x), grown)
            else:
                self._candidates = candidate_pairs(x, grown)
            self._built_at = x.copy()
            self._builds += 1
        i, j = self._awake_candidates()
        if i.size == 0:
            return empty_contacts()
        # the list holds pairs within a skin of touching; only pairs whose bounding spheres overlap
        # now can have a contact (every contact sphere lies inside its body's bounding sphere)
        gap = x[i] - x[j]
        reach = (self.bound[i] + self.bound[j]) * (1.0 + 1e-9)  # never lose a pair to rounding
        close = np.einsum("ij,ij->i", gap, gap) <= reach * reach
        if not close.any():
            return empty_contacts()
        if self.numba_broadphase:
            found = numba_pair_contacts()(
                x,
                q,
                self.points,
                self.radii,
                self.counts,
                self.kind,
                self.dims,
                self.restitution,
                self.friction,
                i[close],
                j[close],
            )
            return Contacts(*found, np.full(found[0].size, -1, dtype=np.int64))
        return pair_contacts(
            x,
            q,
            self.points,
            self.radii,
            self.counts,
            self.kind,
            self.dims,
            self.bound,
            self.restitution,
            self.friction,
            (i[close], j[close]),
        )


def solved_part(
    c: Contacts, surface: np.ndarray | None, keep: np.ndarray
) -> tuple[Contacts, np.ndarray | None]:
    """The contacts ``keep`` (C,) picks, and their surface velocities."""
    if keep.all():
        return c, surface
    part = Contacts(*(getattr(c, f)[keep] for f in Contacts.__dataclass_fields__))
    return part, None if surface is None else surface[keep]
