"""Blow-up detection: has the mechanical energy grown far beyond what was put in?

An isfinite test alone is not enough: explicit Euler on k = 1e7 N/m, m = 1 kg,
dt = 0.01 s multiplies the energy by 1 + (omega dt)^2 ~ 1e3 every step and
reaches 1e149 without a NaN. Energy is the judge instead (the Lander column's
"Bring Me Stability or Bring My Program Death" failure is exactly energy that
no force supplied).

The energy watched is shift-invariant and never negative,

    H = kinetic + spring + penalty energy,

so a particle sitting still at x = 1e17 contributes nothing. What may feed H is
the budget

    B = H(0) + energy released by gravity and attractors since the start
        + an upper bound of the work of the wind (k |w|^2 / 4 per particle and second)
        + kinetic energy of particles born since the start
        + one step's worth of the initial external force (ENERGY_FLOOR_STEPS dt^2 sum |f|^2 / m)
        + ENERGY_FLOOR_J.

Gravity and attractors are released as U(x0) - U(x), per particle from its own
start, so positions far from the origin lose nothing to rounding. With exact
integration H <= B (drag and damping only remove energy). The floor covers the
one-step lag of explicit methods from rest (explicit Euler's first step gives
m g^2 dt^2 / 2 of kinetic energy before any position has moved).

A run is unstable when H > BLOWUP_FACTOR * S * B: at least 99 % of the energy
was made by the integrator. S is the energy swing the method shows on the
scene's stiffest modes at this dt when it is stable
(:func:`animsim.measures.stability.energy_excursion`, 1 when the dt is beyond
the limit): near its limit a stable method's energy oscillates far above its
start (symplectic Euler by about 400x at omega dt = 1.99) and comes back, so a
fixed factor would call bounded runs unstable that ``check`` calls stable. Terms whose energy input is unknown (turbulence, moving
anchors) switch the energy test off; the finiteness test stays.
"""

from __future__ import annotations

# ``compiled`` below is animsim.compile.Compiled: Any, since measures may not import compile (layers)
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.elements import DISSIPATIVE, ELASTIC, INJECTING, RELEASING
from animsim.measures.stability import run_energy_excursion
from animsim.system import kept_copies
from animsim.vec import put_rows, take_rows

if TYPE_CHECKING:  # types only
    from animsim.system import State

#: the energy may reach this multiple of its budget before the run is called unstable
BLOWUP_FACTOR = 100.0
#: steps' worth of the initial external force's kinetic energy allowed as slack
ENERGY_FLOOR_STEPS = 4.0
#: absolute energy floor, J: below it changes are rounding, not growth
ENERGY_FLOOR_J = 1e-9
#: particles from which the numba backend's checks use compiled sums (released energy)
COMPILED_SUMS_FROM = 4096


def _newborn_rows(  # numba
    x: np.ndarray,
    v: np.ndarray,
    rows: np.ndarray,
    dead: np.ndarray,
    alive: np.ndarray,
    alive_prev: np.ndarray,
    mass: np.ndarray,
    x_ref: np.ndarray,
    idx: np.ndarray,
    xb: np.ndarray,
    vb: np.ndarray,
    mb: np.ndarray,
) -> int:
    """EnergyWatch.book_births on the rows the emitters name, in one compiled pass: the rows
    of ``rows`` alive now and not at the last booking into ``idx`` (ascending, as ``rows``),
    their positions, velocities and masses gathered into ``xb``, ``vb``, ``mb`` and their
    positions written into ``x_ref``; the flags of ``dead``, then of ``rows``, brought up to
    date (in NumPy's order: newborns found first). Returns how many newborns. The gathered
    values are the same numbers fancy indexing gives, so the books' sums stay NumPy's."""
    n = 0
    for j in range(rows.shape[0]):
        i = rows[j]
        if alive[i] and not alive_prev[i]:
            idx[n] = i
            n += 1
    for j in range(dead.shape[0]):
        alive_prev[dead[j]] = alive[dead[j]]
    for j in range(rows.shape[0]):
        alive_prev[rows[j]] = alive[rows[j]]
    for j in range(n):
        i = idx[j]
        mb[j] = mass[i]
        for k in range(3):
            xb[j, k] = x[i, k]
            vb[j, k] = v[i, k]
            x_ref[i, k] = x[i, k]
    return n


#: the books a replay restores: energy booked at births, the reference positions, the
#: released terms' references, which slots were alive (EnergyWatch.snapshot)
WatchBooks = tuple[float, np.ndarray, list[np.ndarray], np.ndarray]


class EnergyWatch:
    """Per-run energy bookkeeping for the watchdog (see the module docstring).

    Each force element says how its energy is booked (``watch_role``, see
    :mod:`animsim.elements`): elastic potentials are watched, releasing ones
    (gravity, attractors) feed the budget as they release energy, injecting
    ones (wind) add their power bound, dissipative ones need nothing; any
    other element, or a post-step stage that puts energy in (a moving collider),
    switches the energy test off.
    """

    def __init__(self, compiled: Any, dt: float):
        system = compiled.system
        self.system = system
        self.dynamics = compiled.dynamics
        terms = self.dynamics.terms
        self.mass = system.particle_mass  # rebound to the run's live masses by bind()
        emitters = compiled.emitters
        self._take_changed = None if emitters is None else emitters.take_changed
        self._movable = float(np.count_nonzero(self.mass))
        self.inv_mass = system.particle_inv_mass
        self.elastic = [t for t in terms if t.watch_role == ELASTIC]
        self.releasing = [t for t in terms if t.watch_role == RELEASING]
        # On the numba backend a releasing term may offer the same sum from compiled code,
        # worth its call where the NumPy passes over many particles cost more.
        compiled_sums = compiled.backend == "numba" and system.particle_count >= COMPILED_SUMS_FROM
        fast = [t.released_numba if compiled_sums else None for t in self.releasing]
        #: the newborns' books in one compiled call (numba backend, runs with births): a
        #: step's few hundred rows took about a dozen NumPy calls, 33 us a step of the
        #: 100,000-slot fountain
        self._book_rows: Any = None
        self._book_buffers: tuple[np.ndarray, ...] | None = None
        if self._take_changed is not None and compiled.backend == "numba":
            self._book_rows = _compiled_book_rows(system.particle_count)
        self._released = [f or t.released for f, t in zip(fast, self.releasing, strict=True)]
        self.springs = next((t for t in terms if t.offers_per_spring_energy), None)
        self.wind_power = sum(t.max_power_per_particle for t in terms if t.watch_role == INJECTING)
        known = (ELASTIC, RELEASING, DISSIPATIVE, INJECTING)
        unknown = [t.label for t in terms if t.watch_role not in known]
        unknown += [st.label for st in compiled.post_step if st.injects and not st.random]
        x0 = compiled.initial.particle_position
        v0 = compiled.initial.particle_velocity
        if np.any(system.particle_pinned & np.any(v0 != 0, axis=1)):
            unknown.append("moving anchors")
        #: why the energy test is off, or None when it is on
        self.disabled = ", ".join(unknown) if unknown else None
        self.dt = dt
        #: the energy swing a stable run may show at this dt, and the growth H/B that stops a run
        self.excursion = run_energy_excursion(compiled, dt)
        self.allowance = BLOWUP_FACTOR * self.excursion
        self.reset(compiled.initial)
        x_init = np.zeros_like(x0)
        for f, u in zip(fast, self.u_ref, strict=True):
            if f is not None:  # compile (or load) the compiled sum now, before the run
                f(x_init, x_init, u)
        self.floor = ENERGY_FLOOR_J + self._external_floor(x0, v0)

    def bind(self, state: State) -> None:
        """Book the run's live masses (pool births change them)."""
        self.mass = state.particle_mass
        self.inv_mass = state.particle_inv_mass
        self._movable = float(np.count_nonzero(self.mass))  # fixed populations: counted once

    def _external_floor(self, x: np.ndarray, v: np.ndarray) -> float:
        if not self.releasing:
            return 0.0
        f = np.zeros_like(x)
        with np.errstate(all="ignore"):  # a singular start is the first check's to report
            for t in self.releasing:
                t.accumulate(x, v, 0.0, f)
        inv = self.inv_mass
        return ENERGY_FLOOR_STEPS * self.dt**2 * float(np.dot(inv, np.einsum("ij,ij->i", f, f)))

    def reset(self, state: State) -> None:
        """Start the books at ``state`` (the run's initial state)."""
        x = state.particle_position
        self.x_ref = x.copy()  # where each particle's released energy is measured from
        self.u_ref = [t.per_particle_potential(x) for t in self.releasing]
        #: the reference potentials a newborn changes (gravity's stay zero: not booked)
        self._u_booked = [
            (t, u) for t, u in zip(self.releasing, self.u_ref, strict=True) if t.books_reference_potential
        ]
        self.alive_prev = None if state.particle_alive is None else state.particle_alive.copy()
        self.born_energy = 0.0
        self._kept: list[np.ndarray] | None = None  # the last snapshot's arrays (snapshot)
        self.h0 = self.watched(state)

    def kinetic(self, v: np.ndarray) -> float:
        return float(0.5 * np.dot(self.mass, np.einsum("ij,ij->i", v, v)))

    def watched(self, state: State) -> float:
        """H = kinetic + spring + penalty energy (J)."""
        x = state.particle_position
        h = self.kinetic(state.particle_velocity)
        for t in self.elastic:
            h += self._spring_energy(t, x) if t is self.springs else t.potential(x)
        bodies = self.dynamics.bodies
        if bodies is not None and state.body_orientation is not None:
            # rigid bodies: spin energy and the energy of springs to points of bodies
            h += bodies.rotational_energy(state.body_orientation, state.body_angular_velocity)
            h += bodies.potential(x, state.body_orientation)
        return h

    @staticmethod
    def _spring_energy(springs: Any, x: np.ndarray) -> float:
        """sum 1/2 ks (|L| - R)^2, as Springs.potential but without its zero-length guard
        (|L| alone needs none), since this runs on every check."""
        d = x[springs.a] - x[springs.b]
        stretch = np.sqrt(np.einsum("ij,ij->i", d, d)) - springs.rest
        return 0.5 * float(np.dot(springs.ks, stretch * stretch))

    def book_births(self, state: State) -> None:
        """Book the particles alive now and not at the last booking: their kinetic energy joins
        the budget and their released energy is measured from here. The loop calls this after
        every step of a run with births (and each check does), so the books are those of a
        check at every step while the full checks keep their stride."""
        if self.alive_prev is None or state.particle_alive is None:
            return
        alive = state.particle_alive
        # The emitters name the rows born and dead since they were last asked (a step's
        # few); only when they cannot is every row's flag compared with its last value.
        changed = None if self._take_changed is None else self._take_changed(state)
        if changed is None:
            born = alive & ~self.alive_prev
            idx = np.flatnonzero(born) if born.any() else None
            np.copyto(self.alive_prev, alive)
        elif self._book_rows is not None:
            self._book_compiled(state, *changed)
            return
        else:
            rows, dead = changed
            now = alive[rows]
            idx = rows[now & ~self.alive_prev[rows]]  # ascending, as flatnonzero finds them
            self.alive_prev[dead] = alive[dead]
            self.alive_prev[rows] = now
        if idx is not None and len(idx):
            # rows gathered and put back whole (take_rows, put_rows: the same bytes as fancy
            # indexing, about three times faster on a step's few hundred newborns)
            xb = take_rows(state.particle_position, idx)
            put_rows(self.x_ref, idx, xb)
            self._book_newborns(idx, xb, take_rows(state.particle_velocity, idx), self.mass[idx])

    def _book_newborns(self, idx: np.ndarray, xb: np.ndarray, vb: np.ndarray, mb: np.ndarray) -> None:
        """The newborns ``idx`` (ascending) at positions ``xb``, velocities ``vb``, masses
        ``mb``: their kinetic energy into the budget, their reference potentials booked
        (their reference positions are the caller's to write)."""
        self.born_energy += float(0.5 * np.dot(mb, np.einsum("ij,ij->i", vb, vb)))
        for t, u in self._u_booked:
            u[idx] = t.per_particle_potential(xb, idx)

    def _book_compiled(self, state: State, rows: np.ndarray, dead: np.ndarray) -> None:
        """book_births' booking of ``rows`` (born, ascending) and ``dead`` through
        :func:`_newborn_rows`: the same numbers, its sums NumPy's on the gathered rows."""
        k = len(rows)
        if self._book_buffers is None or len(self._book_buffers[0]) < k:  # grown, then reused
            room = max(k, 1024)
            self._book_buffers = (
                np.empty(room, dtype=np.int64),
                np.empty((room, 3)),
                np.empty((room, 3)),
                np.empty(room),
            )
        idx, xb, vb, mb = self._book_buffers
        n = self._book_rows(
            state.particle_position, state.particle_velocity,
            np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(dead, dtype=np.int64),
            state.particle_alive, self.alive_prev, self.mass, self.x_ref, idx, xb, vb, mb,
        )  # fmt: skip
        if n:
            self._book_newborns(idx[:n], xb[:n], vb[:n], mb[:n])

    def snapshot(self) -> WatchBooks | None:
        """The books a replay from a checked state restores (None: they never change)."""
        if self.alive_prev is None:
            return None
        # only the latest snapshot is valid: the next one reuses its arrays (kept_copies)
        self._kept = kept_copies(self._kept, [self.x_ref, self.alive_prev, *self.u_ref])
        x_ref, alive_prev, *u_ref = self._kept
        return self.born_energy, x_ref, u_ref, alive_prev

    def restore(self, snap: WatchBooks | None) -> None:
        if snap is None:
            return
        self.born_energy = snap[0]
        np.copyto(self.x_ref, snap[1])
        for u, saved in zip(self.u_ref, snap[2], strict=True):
            np.copyto(u, saved)
        assert self.alive_prev is not None  # a snapshot exists only with births (snapshot)
        np.copyto(self.alive_prev, snap[3])

    def budget(self, state: State) -> float:
        """B: the most energy H may hold at ``state`` without the integrator making any."""
        x = state.particle_position
        self.book_births(state)
        released = 0.0
        for release, u in zip(self._released, self.u_ref, strict=True):
            released += release(x, self.x_ref, u)
        movable = self._movable if self.alive_prev is None else float(np.count_nonzero(self.mass))
        total: float = (
            self.h0
            + max(released, 0.0)
            + self.wind_power * movable * state.time
            + self.born_energy
            + self.floor
        )
        return total

    def budget_constants(self) -> tuple[float, float, float, float, float]:
        """(h0, floor, wind power per particle, movable particles, born energy): the terms of
        :meth:`budget` besides the released energy and the time, for compiled checks of a run
        without births (whose books never change)."""
        return self.h0, self.floor, float(self.wind_power), self._movable, self.born_energy

    def growth(self, state: State) -> tuple[float, float, float]:
        """(H, B, H/B) at ``state``."""
        h = self.watched(state)
        b = self.budget(state)
        return h, b, h / b

    def blame(self, state: State) -> tuple[int, int | None]:
        """The particle holding the most watched energy and the spring holding the most."""
        x, v = state.particle_position, state.particle_velocity
        e = 0.5 * self.mass * np.einsum("ij,ij->i", v, v)
        bodies = self.dynamics.bodies
        if bodies is not None and state.body_orientation is not None:
            e = e.copy()
            e[bodies.rows] += bodies.rotational_energy_per_body(
                state.body_orientation, state.body_angular_velocity
            )
        spring = None
        if self.springs is not None and len(self.springs.a):
            per = self.springs.per_spring_energy(x)
            n = len(e)
            e = e + 0.5 * (np.bincount(self.springs.a, per, n) + np.bincount(self.springs.b, per, n))
            spring = int(np.nanargmax(per)) if np.isfinite(per).any() else 0
        return int(np.nanargmax(e)) if np.isfinite(e).any() else 0, spring


def _compiled_book_rows(n: int) -> Any:
    """:func:`_newborn_rows` compiled (or loaded from numba's disk cache) now, before a run,
    with the types a run passes (``n`` slots), and called without the dispatcher's typing."""
    import numba

    from animsim.backends.kernel_calls import FastCall

    kernel = numba.njit(cache=True)(_newborn_rows)
    i, f = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    alive = np.zeros(1, dtype=bool)
    args = (
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        i,
        i,
        alive,
        alive.copy(),
        np.zeros(1),
        np.zeros((1, 3)),
        i,
        f,
        f,
        np.zeros(0),
    )
    kernel(*args)
    return FastCall(kernel, args)
