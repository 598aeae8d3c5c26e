"""The emitters' step stage: every pool of a scene and the hooks the simulation loop calls.

:class:`Emitters` resets the pools, advances them over a step (births flown on
for the rest of their step with the force at birth and collided, then deaths),
records the alive particles of a frame in creation order with their age, size
and colour, and reports the run's counts; :func:`build_emitters` makes one pool
per emitter of a scene.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from animsim.elements import StepStage
from animsim.emitters.births import RATE_NOISE_WINDOW, Births
from animsim.emitters.kernels import numba_kernels
from animsim.emitters.pool import Pool
from animsim.record import Frame
from animsim.scene import models as m
from animsim.system import State
from animsim.vec import put_rows


class Emitters(StepStage):
    """All pools of a scene and the hooks the simulation loop calls.

    ``reset`` before a run, ``advance`` after each step's integration and
    collisions, ``frame`` to record, ``summary`` for the metadata.
    """

    #: births bring kinetic energy in (the watchdog books it separately)
    injects = True
    random = True
    #: runs in Python after each step of the numba backend's fused kernel (no kernel of its own)
    fused_between_steps = True
    #: snapshot/restore keep the pools and their random streams for a replay
    replays = True
    no_closed_form = "it has emitters (particles are born and die at random)"

    def __init__(self, pools: list[Pool], first_index: int):
        self.pools = pools
        self.dynamics: Any = None
        self.colliders: list[Any] = []
        self.first_index = first_index
        self.capacity = sum(p.capacity for p in pools)
        self.names = [p.name for p in pools]
        self._accel: np.ndarray | None = None
        self._alive: np.ndarray | None = None  # the bound state's alive flags (take_changed)
        # The numba backend's compiled birth step (use_numba): its call, the tables it flies
        # and collides newborns with, and what counts its force evaluations; None: Python.
        self._step: tuple[Any, Any, Any] | None = None
        self._next_table = first_index
        kill = [p.name for p in pools if p.kill_lo is not None]
        self.labels = [
            *(
                f"emitter {p.name!r} births: {p.stream.rate.describe()}"
                + (
                    f" ± {p.stream.spread:g}/s (redrawn every {RATE_NOISE_WINDOW:g} s)"
                    if p.stream.spread
                    else ""
                )
                + f", Poisson in time from its own seeded stream; {p.stream.shape.describe()}; "
                f"pool of {p.capacity} slots (full: births dropped and counted)"
                for p in pools
            ),
            "emitter births inside a step: advanced for the rest of it with the force at birth "
            "(one extra force evaluation per step with births), then collided",
            "emitter ageing: size and RGBA colour linear over life",
            "emitter deaths: at the exact age limit"
            + (f"; kill box of {', '.join(repr(k) for k in kill)}" if kill else "; no kill box"),
        ]

    def reset(self, state: State) -> None:
        for p in self.pools:
            p.bind(state)
        self._accel = np.zeros_like(state.particle_position)
        self._next_table = self.first_index
        self._alive = state.particle_alive

    def use_numba(self, state: State | None = None) -> None:
        """The pools' births and deaths by numba kernels (numba backend; the same slots).

        With ``state`` (the run's, its pools bound) and newborns whose forces and
        colliders have kernels that run on their rows alone, a step's births, newborns and
        deaths are one compiled call per pool (:func:`animsim.emitters.kernels._pool_step`),
        compiled or loaded now, before the run is timed."""
        for p in self.pools:
            if p._kernels is None:
                p.use_numba()
        self._step = None
        forces = getattr(self.dynamics, "forces", None)
        tables = None if (forces is None or state is None) else forces.newborn_tables(self.colliders)
        if tables is None:
            return
        from animsim.backends.kernel_calls import FastCall

        both = (forces.masses(), tables)
        # one call that changes nothing (no events, nothing due by -inf, no row outside a
        # box: the pools are empty) compiles it, or loads it from the disk cache
        args = self.pools[0].step_args(state, Births.empty(), -np.inf, 0.0, both, np.empty(0, dtype=bool))
        call = FastCall(numba_kernels()["step"], args)
        call(*args)
        self._step = (call, both, forces)

    def take_changed(self, state: State) -> tuple[np.ndarray, np.ndarray] | None:
        """(rows born, sorted and unique; rows dead) since the last call, or None when not
        known for ``state`` (then any row may have changed).

        The energy books ask after every step, so they look at the few rows born or
        dead instead of comparing every slot's alive flag with its last value.
        """
        parts = [p.take_changed() for p in self.pools]
        if state.particle_alive is not self._alive or any(r is None for r in parts):
            return None
        if len(parts) == 1:
            return parts[0]
        # pools hold consecutive ranges in scene order: the born rows stay sorted when joined
        return np.concatenate([r[0] for r in parts]), np.concatenate([r[1] for r in parts])  # type: ignore[index]

    def explain_lines(self) -> list[str]:
        return self.labels

    def snapshot(self) -> list[tuple[Any, ...]]:
        """The pools' bookkeeping and random streams, for a replay from a checked state.

        With it the births are not a reason to check the watchdog at every step: a
        replay from the last good check restores this and the state, and draws the
        same births again (:func:`animsim.engine.run`).
        """
        return [p.snapshot() for p in self.pools]

    def restore(self, snap: object) -> None:
        # the token is what snapshot made (StepStage.restore takes any stage's, unopened)
        for p, s in zip(self.pools, cast("list[tuple[Any, ...]]", snap), strict=True):
            p.restore(s)

    def attach(self, dynamics: Any, colliders: list[Any]) -> None:
        """The force sum newborns fly on with, and the stages they collide with (compile time)."""
        self.dynamics = dynamics
        self.colliders = colliders

    def apply(
        self, state: State, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float
    ) -> bool:
        """The step stage: births in [t0, t1), deaths at t1 (bumps the state's revision itself)."""
        self.advance(state, t0, t1)
        return False  # advance bumps the revision itself when a birth or death changed the state

    def advance(self, state: State, t0: float, t1: float) -> None:
        """Births in [t0, t1), moved on to t1; then deaths at t1."""
        if self._step is not None:
            self._advance_compiled(state, t0, t1)
            return
        born: list[np.ndarray] = []
        times: list[np.ndarray] = []
        for p in self.pools:
            idx, tb = p.births(t0, t1)
            born.append(idx)
            times.append(tb)
        newborn = np.concatenate(born)
        changed = bool(len(newborn))
        if len(newborn):
            self._move_newborns(state, newborn, t1 - np.concatenate(times), 0.5 * (t0 + t1))
        for p, idx in zip(self.pools, born, strict=True):
            changed |= p.deaths(t1, idx)
        if changed:
            state.revision += 1  # integrators that cache a force must recompute it

    def _advance_compiled(self, state: State, t0: float, t1: float) -> None:
        """:meth:`advance` through the compiled birth step, a call per pool: the same numbers
        (each pool's newborns alone, which the forces' pointwise rows allow), and one force
        evaluation counted for a step's newborns, as the one evaluation of the Python path."""
        call, tables, forces = self._step  # type: ignore[misc]
        t_mid = 0.5 * (t0 + t1)
        born = 0
        changed = False
        for p in self.pools:
            n, c = p.step_numba(state, p.stream.take(t1), t1, t_mid, call, tables)
            born += n
            changed |= c
        if born:
            forces.dynamics.evaluations += 1
        if changed:
            state.revision += 1  # integrators that cache a force must recompute it

    def _move_newborns(self, state: State, idx: np.ndarray, rest: np.ndarray, t_mid: float) -> None:
        """x += r v0 + r^2/2 a0, v += r a0 for the rest r of the birth step; then planes."""
        x, v = state.particle_position, state.particle_velocity
        assert self._accel is not None
        # One evaluation over every slot: the NumPy force terms hold per-particle arrays
        # (mass) of the full system, so they cannot be evaluated on a subset, and on numba
        # a force that reads other rows (or a driven row) needs them all too (the numba
        # backend's compiled birth step serves the others, _advance_compiled).
        a = self.dynamics.acceleration(x, v, t_mid, self._accel)[idx]
        x0, v0 = x[idx], v[idx]
        r = rest[:, None]
        x1 = x0 + r * v0 + (0.5 * r * r) * a
        v1 = v0 + r * a
        for stage in self.colliders:
            stage.collide_subset(x0, v0, x1, v1, rest)
        put_rows(x, idx, x1)
        put_rows(v, idx, v1)

    def frame(self, compiled: Any, state: State) -> Frame:
        """The alive particles in creation order, with age, size and colour of the emitted ones."""
        fixed = self.first_index
        em_slots, em_order, em_birth, em_serial = [], [], [], []
        for p in self.pools:
            s = np.flatnonzero(p.alive)
            em_slots.append(s + p.first)
            em_order.append(np.full(len(s), p.order, dtype=np.int64))
            em_birth.append(p.slot_birth[s])
            em_serial.append(p.slot_serial[s])
        slots = np.concatenate(em_slots)
        order = np.concatenate(em_order)
        birth = np.concatenate(em_birth)
        serial = np.concatenate(em_serial)
        sort = np.lexsort((serial, order, birth))
        slots, order, birth, serial = slots[sort], order[sort], birth[sort], serial[sort]

        # Id-table rows: assigned when a particle is first recorded, in creation order.
        table = np.empty(len(slots), dtype=np.int64)
        new_ids: list[str] = []
        for p in self.pools:
            mine = order == p.order
            local = slots[mine] - p.first
            table[mine] = p.slot_table[local]
        fresh = np.flatnonzero(table < 0)
        if len(fresh):
            table[fresh] = self._next_table + np.arange(len(fresh))
            self._next_table += len(fresh)
            for p in self.pools:
                mine = fresh[order[fresh] == p.order]
                p.slot_table[slots[mine] - p.first] = table[mine]
            names = self.names
            new_ids = [
                f"{names[o]}#{n}" for o, n in zip(order[fresh].tolist(), serial[fresh].tolist(), strict=True)
            ]

        n_fixed = fixed
        n = n_fixed + len(slots)
        age = np.full(n, np.nan)
        size = np.full(n, np.nan)
        color = np.full((n, 4), np.nan)
        if len(slots):
            a = state.time - birth
            age[n_fixed:] = a
            lifetime = np.empty(len(slots))
            s0 = np.empty(len(slots))
            s1 = np.empty(len(slots))
            c0 = np.empty((len(slots), 4))
            c1 = np.empty((len(slots), 4))
            for p in self.pools:
                mine = order == p.order
                lifetime[mine] = p.slot_lifetime[slots[mine] - p.first]
                s0[mine], s1[mine] = p.size0, p.size1
                c0[mine], c1[mine] = p.color0, p.color1
            life = np.clip(a / lifetime, 0.0, 1.0)
            size[n_fixed:] = s0 + (s1 - s0) * life
            color[n_fixed:] = c0 + (c1 - c0) * life[:, None]
        rows = np.concatenate([np.arange(n_fixed, dtype=np.int64), slots])
        index = np.concatenate([np.arange(n_fixed, dtype=np.int64), table])
        return Frame(
            step=state.step,
            time=state.time,
            index=index,
            position=state.particle_position[rows],
            velocity=state.particle_velocity[rows],
            new_ids=new_ids,
            age=age,
            size=size,
            color=color,
        )

    def particle_id(self, index: int) -> str | None:
        """The id (``<name>#<n>``) of the particle alive in global slot ``index``, if any.

        For messages that name a particle (the stability guard): a pool slot's
        index means nothing to a user, its id does.
        """
        for p in self.pools:
            local = index - p.first
            if 0 <= local < p.capacity:
                return f"{p.name}#{int(p.slot_serial[local])}" if p.alive[local] else None
        return None

    def summary(self) -> dict[str, Any]:
        return {
            "births_dropped": sum(p.dropped for p in self.pools),
            "per_emitter": {p.name: p.summary() for p in self.pools},
        }


def build_emitters(scene: m.Scene, first_index: int) -> Emitters:
    """One pool per emitter, in scene order, slots starting at ``first_index``."""
    pools = []
    start = first_index
    for order, spec in enumerate(scene.emitters):
        pools.append(Pool(spec, order, start, scene.seed))
        start += spec.max_particles
    return Emitters(pools, first_index)
