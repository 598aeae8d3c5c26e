"""Particle contacts as a step stage: the Verlet list kept, rebuilt when stale, and each step's
passes on NumPy (:mod:`animsim.particle_contacts.resolve`) or numba (:mod:`animsim.particle_contacts.kernels`)."""

from __future__ import annotations

import time

import numpy as np

from animsim.console import format_bytes
from animsim.elements import StepStage
from animsim.errors import SimulationError
from animsim.particle_contacts.constants import (
    BOUNCE_FLOOR,
    BOUNCE_SWEEPS,
    CONTACT_PAIR_BYTES,
    CONVERGED,
    ITERATIONS,
    OVERLAP_PASSES,
    RELAX,
    RESTING_STEPS,
    SKIN,
    SKIN_USE,
    SLOP,
)
from animsim.particle_contacts.kernels import numba_kernels
from animsim.particle_contacts.neighbours import EMPTY, candidates_numpy, count_pairs_numpy
from animsim.particle_contacts.resolve import Buffers, Kept, dot3_into, gather_diff, resolve_pairs_numpy
from animsim.particle_contacts.walls import NO_WALLS, WallContacts, Walls
from animsim.system import State
from animsim.thread_choice import BuildChooser
from animsim.vec import dot3

#: touching: closer than the contact distance and the slop (a resting pair whose overlap was
#: removed stays a contact, with its impulses); squared, as the distances are
TOUCH2 = (1.0 + SLOP) ** 2
#: the numba passes are shared among threads from this many overlapping pairs on (fewer: one
#: thread; a shared pass starts and joins the threads some 40 times a step, tens of
#: microseconds each)
SHARED_MIN_PAIRS = 16_384


class ParticleContacts(StepStage):
    """Particle-particle contacts as a step stage.

    radius: (N,) per-row radii.  active: (N,) rows that take part (not bodies).
    exclude: sorted keys of spring-joined pairs (:func:`spring_exclusions`).
    """

    injects = False
    no_closed_form = "particle contacts"

    def __init__(
        self,
        radius: np.ndarray,
        restitution: float,
        friction: float,
        inv_mass: np.ndarray,
        active: np.ndarray,
        exclude: np.ndarray,
        backend: str = "numpy",
        iterations: int = ITERATIONS,
    ):
        self.radius = np.ascontiguousarray(radius, dtype=np.float64)
        self.restitution = float(restitution)
        self.friction = float(friction)
        self.inv_mass = inv_mass
        self.active = np.asarray(active, dtype=bool)
        self.exclude = np.ascontiguousarray(exclude, dtype=np.int64)
        self.iterations = int(iterations)
        self.backend = backend
        self.dissipative = restitution < 1 or friction > 0
        self._kernels = numba_kernels() if backend == "numba" else None
        self.pairs_last = 0
        #: how many resting passes the last step ran (a statistic, for tests and benchmarks)
        self.passes_last = 0
        #: the most candidate pairs the list may hold (bound_memory: the memory budget's
        #: share after the rest of the run; -1 when nothing bounds it)
        self.max_pairs = -1
        #: how often the candidate list was built (a run's statistics, for tests and benchmarks)
        self.rebuilds = 0
        #: colliders (animsim.colliders.Colliders) and impulse planes (animsim.collisions) to push
        #: out of after the contacts moved particles
        self.colliders = None
        self.planes = None
        self._buffers = Buffers()
        #: whether the numba passes run shared among threads or on one: the faster, timed
        self._chooser = BuildChooser()
        self._forget()
        finder = (
            "a uniform grid (counting sort by cell)" if backend == "numba" else "a k-d tree (scipy cKDTree)"
        )
        shared = (
            f" (shared among numba's threads from {SHARED_MIN_PAIRS:,} touching pairs, while that is the faster)"
            if backend == "numba"
            else ""
        )
        self.label = (
            f"particle contacts: {int(self.active.sum())} particle(s) as spheres "
            f"(radius {self.radius[self.active].min():.3g}-{self.radius[self.active].max():.3g} m), "
            f"restitution {restitution:g}, friction {friction:g}, neighbours by {finder} "
            f"kept in a Verlet list, {iterations} Jacobi passes{shared}; "
            f"{self.exclude.size} spring-joined pair(s) left out"
            if self.active.any()
            else "particle contacts: no particle takes part"
        )

    def stability_note(self, dt: float) -> str:
        r = float(self.radius[self.active].min()) if self.active.any() else 0.0
        return (
            f"particle contacts: impulses at the end of each step, no stiffness; found only at step "
            f"ends, so two particles closing faster than 2 r / dt = {2 * r / dt:.3g} m/s can pass "
            f"through each other"
        )

    def _forget(self) -> None:
        self._ci = self._cj = EMPTY
        self._reach2: np.ndarray = np.zeros(0)
        self._x_built: np.ndarray | None = None
        self._active_built: np.ndarray | None = None
        self._skin = 0.0
        # the warm start's memory: each candidate's impulses and the step they were kept at,
        # each (row, wall)'s likewise (built on first use: the walls are set after __init__)
        self._lam_c, self._ft_c, self._stamp_c = np.zeros(0), np.zeros((0, 3)), EMPTY
        self._stamp = 0
        self._walls: Walls | None = None
        self._wall_mem: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def reset(self, state: State) -> None:
        """A run starts: the candidate list of another run is not reused (it would be valid, but
        a run should not depend on what ran before it, even in how long it takes)."""
        self._forget()

    def apply(
        self,
        state: State,
        x_old: np.ndarray,
        v_old: np.ndarray,
        t0: float,
        t1: float,
        dt: float | None = None,
    ) -> bool:
        changed = self._apply(state, v_old, t0, t1)
        if changed and self.colliders is not None:
            # the overlap removal may push a particle into a collider: never leave it there
            self.colliders.project(state, t0, t1)
        if changed and self.planes is not None:
            self.planes.project_rows(
                state.particle_position, state.particle_velocity, np.flatnonzero(self.active)
            )
        return changed

    def _list_is_stale(self, x: np.ndarray, active: np.ndarray) -> bool:
        """True when two particles may have closed by more than the skin since the list was built."""
        if self._x_built is None or self._x_built.shape != x.shape:
            return True
        if not np.array_equal(active, self._active_built):
            return True
        if self._kernels is not None:
            spread, far = self._kernels.spread(x, self._x_built, active)
        else:
            d = self._buffers.get("shift", x.shape)
            np.subtract(x, self._x_built, out=d)
            if not self._all_active:
                d = d[active]
            if d.shape[0] == 0:
                return False
            hi, lo = d.max(axis=0), d.min(axis=0)
            corner = np.maximum(-lo, hi)
            far = float(np.sqrt(corner @ corner))  # no row moved farther
            half = 0.5 * (hi - lo)
            if 2.0 * float(np.sqrt(half @ half)) <= SKIN_USE * self._skin and not self._walls_stale(far):
                return False  # even the corners of the displacements' box are near enough
            d -= 0.5 * (hi + lo)
            spread = float(np.sqrt(dot3(d, d).max()))
        # every displacement lies within ``spread`` of one common shift c (the centre of
        # their box), so any two particles have closed by at most |d_i - c| + |d_j - c| <= 2 spread
        return not (2.0 * spread <= SKIN_USE * self._skin) or self._walls_stale(far)

    def _walls_stale(self, far: float) -> bool:
        """A grain may have reached a wall it was not within the skin of (walls do not fall with it)."""
        return self._walls is not None and self._walls.count > 0 and not far <= SKIN_USE * self._skin

    def bound_memory(self, budget: int) -> None:
        """The candidate list may hold ``budget`` bytes (CONTACT_PAIR_BYTES a pair)."""
        self.max_pairs = max(int(budget) // CONTACT_PAIR_BYTES, 0)

    def _too_many(self, found: int, t: float) -> SimulationError:
        more = "at least " if self._kernels is not None else ""
        return SimulationError(
            f"particle contacts at t = {t:.6g} s: {more}{found} pairs of particles lie within "
            f"2 x radius + skin of each other (births or a pile squeezed together since the "
            f"start), more than the memory budget leaves room for ({self.max_pairs} pairs, "
            f"{format_bytes(self.max_pairs * CONTACT_PAIR_BYTES)}); lower the radius or the "
            "number of particles, or raise the budget with --max-memory"
        )

    def _rebuild(self, x: np.ndarray, active: np.ndarray, t: float = 0.0) -> None:
        rmax = float(self.radius[active].max()) if active.any() else 0.0
        self._skin = SKIN * 2.0 * rmax
        reach = 2.0 * rmax + self._skin
        if self._kernels is not None:
            ci, cj = self._kernels.candidates(x, active, self.exclude, reach, self.max_pairs)
            found = ci.size
        else:
            found = count_pairs_numpy(x, active, reach) if self.max_pairs >= 0 else 0
            if found <= self.max_pairs or self.max_pairs < 0:
                ci, cj = candidates_numpy(x, active, self.exclude, reach)
        if 0 <= self.max_pairs < found:
            raise self._too_many(found, t)
        self._carry_impulses(ci, cj, x.shape[0])
        self._ci, self._cj = ci, cj
        r = self.radius[ci] + self.radius[cj]
        self._reach2 = r * r
        if self._x_built is None or self._x_built.shape != x.shape:
            self._x_built = np.empty_like(x)
        np.copyto(self._x_built, x)
        self._active_built = active.copy()
        self._all_active = bool(active.all())
        if self._walls is not None:
            self._walls.rebuild(x, self.radius, np.flatnonzero(active), self._skin, t)
        self.rebuilds += 1

    def _carry_impulses(self, ci: np.ndarray, cj: np.ndarray, n: int) -> None:
        """The kept impulses moved to the new list's candidates, pair by pair (keys i n + j,
        ascending in both lists)."""
        if self._kernels is not None:
            lam, ft, stamp = np.empty(ci.size), np.empty((ci.size, 3)), np.empty(ci.size, dtype=np.int64)
            self._kernels.carry(
                self._ci, self._cj, self._lam_c, self._ft_c, self._stamp_c, ci, cj, lam, ft, stamp
            )
            self._lam_c, self._ft_c, self._stamp_c = lam, ft, stamp
            return
        old = self._ci * n + self._cj
        new = ci * n + cj
        lam, ft, stamp = np.zeros(new.size), np.zeros((new.size, 3)), np.full(new.size, -1, dtype=np.int64)
        if old.size and new.size:
            at = np.minimum(np.searchsorted(old, new), old.size - 1)
            hit = old[at] == new
            lam[hit], ft[hit], stamp[hit] = self._lam_c[at[hit]], self._ft_c[at[hit]], self._stamp_c[at[hit]]
        self._lam_c, self._ft_c, self._stamp_c = lam, ft, stamp

    def _wall_contacts(
        self, x: np.ndarray, inv_mass: np.ndarray, active: np.ndarray, t0: float, t1: float
    ) -> tuple[WallContacts, np.ndarray, np.ndarray]:
        """This step's wall contacts and their kept impulses (zero for one new this step)."""
        if self._walls is None or self._walls.count == 0:
            return NO_WALLS, np.zeros(0), np.zeros((0, 3))
        size = x.shape[0] * self._walls.count
        if self._wall_mem is None or self._wall_mem[0].size != size:
            self._wall_mem = (np.zeros(size), np.zeros((size, 3)), np.full(size, -1, dtype=np.int64))
        walls = self._walls.contacts(x, self.radius, active & (inv_mass > 0), t0, t1)
        lam, ft, stamp = self._wall_mem
        fresh = stamp[walls.key] == self._stamp - 1
        return walls, np.where(fresh, lam[walls.key], 0.0), np.where(fresh[:, None], ft[walls.key], 0.0)

    def _keep_walls(self, walls: WallContacts, wlam: np.ndarray, wft: np.ndarray) -> None:
        if self._wall_mem is not None and walls.key.size:
            lam, ft, stamp = self._wall_mem
            lam[walls.key], ft[walls.key], stamp[walls.key] = wlam, wft, self._stamp

    def _apply(self, state: State, v_old: np.ndarray, t0: float, t1: float) -> bool:
        dt = t1 - t0
        if dt <= 0:
            return False
        x, v = state.particle_position, state.particle_velocity
        # the state's live masses: emitter pools switch theirs on at birth
        inv_mass = getattr(state, "particle_inv_mass", self.inv_mass)
        if not inv_mass.flags.writeable:  # the model's own (fixed) masses: one writable copy
            if getattr(self, "_inv_copy", None) is None:
                self._inv_copy = np.array(inv_mass)
            inv_mass = self._inv_copy
        active = self.active if state.particle_alive is None else self.active & state.particle_alive
        if self._walls is None and (self.colliders is not None or self.planes is not None):
            self._walls = Walls(self.colliders, self.planes)
            self._x_built = None  # found with the next list
        if self._list_is_stale(x, active):
            self._rebuild(x, active, t0)
        self._stamp += 1
        ci = self._ci
        if ci.size == 0:
            self.pairs_last = self.passes_last = 0
            return False
        walls, wlam, wft = self._wall_contacts(x, inv_mass, active, t0, t1)
        if self._kernels is not None:
            found, changed, passes = self._numba_step(x, v, v_old, inv_mass, dt, walls, wlam, wft)
        else:
            found, changed, passes = self._numpy_step(x, v, v_old, inv_mass, dt, walls, wlam, wft)
        self.pairs_last = int(found)
        self.passes_last = passes
        if changed:
            self._keep_walls(walls, wlam, wft)
        return changed

    def _numba_step(self, x, v, v_old, inv_mass, dt, walls, wlam, wft) -> tuple[int, bool, int]:  # type: ignore[no-untyped-def]
        import numba  # the numba backend's path: numba is installed

        assert self._kernels is not None
        p = self._ci.size
        nw = walls.rows.size
        b = self._buffers
        n_rows = x.shape[0]
        # share the passes among threads only where a list is long enough to pay for it, and
        # only while that is the faster (the chooser times both ways; the bits are the same)
        can_share = numba.get_num_threads() > 1 and p >= SHARED_MIN_PAIRS
        shared = can_share and self._chooser.pick()
        # the slots are only ever written when shared: a run that cannot share holds none
        ps, ws = (p, nw) if can_share else (0, 0)
        sums = (
            b.get("si", (ps,), np.int64), b.get("sj", (ps,), np.int64), b.get("slots", (2 * ps, 3)),
            b.get("wc", (nw, 3)), b.get("start", (n_rows + 1,), np.int64),
            b.get("wstart", (n_rows + 1,), np.int64), b.get("wlist", (ws,), np.int64), b.get("dv", (n_rows, 3)),
        )  # fmt: skip
        start = time.perf_counter()
        found, changed, passes = self._kernels.step(
            self._ci, self._cj, self._reach2, TOUCH2, x, v, v_old, inv_mass, self.radius,
            self.restitution, self.friction, self.iterations, OVERLAP_PASSES, RELAX, dt,
            b.get("pi", (p,), np.int64), b.get("pj", (p,), np.int64), b.get("pk", (p,), np.int64),
            b.get("w", (p,)), b.get("rel", (p,)), b.get("nrm", (p, 3)), b.get("limit", (p,)),
            b.get("lam", (p,)), b.get("ft", (p, 3)), b.get("jb", (p,)), b.get("due", (p,), np.bool_),
            self._lam_c, self._ft_c, self._stamp_c, self._stamp,
            walls.rows, walls.normal, walls.velocity, walls.friction, b.get("wrel", (nw,)), wlam, wft,
            b.get("v0", (n_rows, 3)), b.get("added", (n_rows,)), b.get("near", (n_rows,)),
            RESTING_STEPS, BOUNCE_FLOOR, BOUNCE_SWEEPS, CONVERGED, shared, sums,
        )  # fmt: skip
        if can_share:
            self._chooser.record(shared, time.perf_counter() - start, 1)
        return int(found), bool(changed), int(passes)

    def _numpy_step(self, x, v, v_old, inv_mass, dt, walls, wlam, wft) -> tuple[int, bool, int]:  # type: ignore[no-untyped-def]
        # the candidates that overlap now (the numba kernel's test)
        ci, cj = self._ci, self._cj
        b = self._buffers
        p = ci.size
        d3 = gather_diff(x, ci, cj, b.get("d3", (p, 3)), b.get("t3", (p, 3)))
        d2 = dot3_into(d3, d3, b.get("s1", (p,)), b.get("s2", (p,)))
        found = int(np.count_nonzero(d2 < self._reach2))
        pk = np.flatnonzero(d2 < np.multiply(self._reach2, TOUCH2, out=b.get("s2", (p,))))
        if pk.size == 0:
            return found, False, 0
        kept = Kept(self._lam_c, self._ft_c, self._stamp_c, self._stamp, wlam, wft)
        changed, passes = resolve_pairs_numpy(
            ci[pk], cj[pk], pk, x, v, v_old, inv_mass, self.radius, self.restitution, self.friction,
            dt, kept, walls, self.iterations, b,
        )  # fmt: skip
        return found, changed, passes
