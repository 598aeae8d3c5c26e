"""One emitter's pool of slots in the global particle arrays: births, deaths and the books.

:class:`Pool` holds an emitter's preallocated slots, takes the births of its
:class:`~animsim.emitters.births.BirthStream` into free slots, kills at the age
limit and outside the kill box, counts births, drops and deaths, and keeps the
snapshots a replay restores. On the numba backend it keeps a sorted free list
and a death queue and calls the kernels of :mod:`animsim.emitters.kernels`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.colors import parse_color
from animsim.emitters.births import Births, BirthStream
from animsim.emitters.kernels import numba_kernels
from animsim.scene import models as m
from animsim.system import State, kept_copies

#: The numba backend's death queue (Pool.use_numba): at most this many runs (one per
#: step with births; more are merged into one), and rows for twice the pool (entries
#: of slots already dead are dropped when the rows run out).
QUEUE_RUNS = 1024
QUEUE_SLACK = 64
#: the kill box of a pool without one (the birth step's argument, never read)
_NO_BOX = np.zeros(3)


class Pool:
    """One emitter's slots [first, first + capacity) in the global arrays."""

    def __init__(self, spec: m.Emitter, order: int, first: int, seed: int):
        self.name = spec.name
        self.order = order
        self.first = first
        self.capacity = int(spec.max_particles)
        self.stream = BirthStream(spec, seed)
        self.mass = float(spec.mass)
        self.size0, self.size1 = float(spec.size.start), float(spec.size.end)
        self.color0 = parse_color(spec.color.start)
        self.color1 = parse_color(spec.color.end)
        kb = spec.kill_box
        self.kill_lo = None if kb is None else np.array(kb.min, dtype=np.float64)
        self.kill_hi = None if kb is None else np.array(kb.max, dtype=np.float64)
        cap = self.capacity
        # Per-slot bookkeeping (structure of arrays), shape (capacity,).
        self.slot_birth = np.zeros(cap)  # s
        self.slot_death = np.full(cap, np.inf)  # s; inf for a dead slot
        self.slot_lifetime = np.ones(cap)  # s
        self.slot_serial = np.zeros(cap, dtype=np.int64)  # n of the id <name>#<n>
        self.slot_table = np.full(cap, -1, dtype=np.int64)  # row in the id table, -1 = not yet recorded
        self._kept: list[np.ndarray] | None = None  # the last snapshot's arrays (snapshot)
        # The numba backend's kernels (animsim.emitters' docstring), set by use_numba; None: scans.
        self._kernels: dict[str, Any] | None = None
        self._stale = True  # the free list is to be built from the slots before the next step
        # Slots born and slots dead since the energy books last asked (take_changed);
        # None: not known (a fresh or restored pool), the books compare every slot.
        self._born_rows: list[np.ndarray] | None = None
        self._dead_rows: list[np.ndarray] = []
        self._changed_count = 0
        self.reset_counters()

    def use_numba(self) -> None:
        """Births and deaths by numba kernels with a sorted free list (numba backend)."""
        self._kernels = numba_kernels()
        cap = self.capacity
        self._free = np.empty(cap, dtype=np.int64)  # free slots, ascending, from sizes[2]
        # (unused, free count, free list start, runs, queue entries)
        self._sizes = np.zeros(5, dtype=np.int64)
        # The death queue: entries (time; slot, serial) in runs [start, head, end) of rows.
        self._q = np.empty((2 * cap + QUEUE_SLACK, 1))
        self._qs = np.empty((2 * cap + QUEUE_SLACK, 2), dtype=np.int64)
        self._bounds = np.empty((QUEUE_RUNS, 3), dtype=np.int64)
        self._dying = np.empty(cap, dtype=np.int64)
        self._scratch = np.empty(cap, dtype=np.int64)
        self._taken = np.empty(cap, dtype=np.int64)
        self._gone = np.empty(cap, dtype=np.int64)  # slots the birth step killed (step_numba)
        self._counts = np.zeros(4, dtype=np.int64)
        self._stale = True

    def _rebuild(self) -> None:
        """The free list and the death queue from the slots (after bind, or after a replay
        restored them)."""
        free = np.flatnonzero(~self.alive)
        self._free[: len(free)] = free
        live = np.flatnonzero(self.alive)
        live = live[np.argsort(self.slot_death[live], kind="stable")]
        n = len(live)
        self._q[:n, 0] = self.slot_death[live]
        self._qs[:n, 0] = live
        self._qs[:n, 1] = self.slot_serial[live]
        self._bounds[0] = (0, 0, n)  # one run: every alive slot, by death time
        self._sizes[:] = (0, len(free), 0, 1, n)
        self._stale = False

    def reset_counters(self) -> None:
        self.born = 0
        self.dropped = 0
        self.died_age = 0
        self.died_kill_box = 0
        self.alive_count = 0
        self.peak_alive = 0
        self.kinetic_energy_born = 0.0

    def bind(self, state: State) -> None:
        """Point at this run's arrays and empty the pool."""
        sl = slice(self.first, self.first + self.capacity)
        self.x = state.particle_position[sl]
        self.v = state.particle_velocity[sl]
        assert state.particle_alive is not None
        self.alive = state.particle_alive[sl]
        # the state's own live masses: births and deaths switch slots on and off
        self.m = state.particle_mass[sl]
        self.inv_m = state.particle_inv_mass[sl]
        self.alive[:] = False
        self.m[:] = 0.0
        self.inv_m[:] = 0.0
        self.x[:] = 0.0
        self.v[:] = 0.0
        self.slot_death[:] = np.inf
        self.slot_table[:] = -1
        self.stream.reset()
        self.reset_counters()
        self._stale = True
        self._born_rows = None

    #: the per-slot and counting fields a replay restores (the slots' alive flags and masses
    #: are the state's, restored with it; the id-table rows belong to recording and stay)
    _SLOT_FIELDS = ("slot_birth", "slot_death", "slot_lifetime", "slot_serial")
    _COUNTERS = (
        "born",
        "dropped",
        "died_age",
        "died_kill_box",
        "alive_count",
        "peak_alive",
        "kinetic_energy_born",
    )

    def snapshot(self) -> tuple[Any, ...]:
        """The pool's books for a replay; only the latest snapshot is valid (the next one
        reuses its arrays: the loop restores only from the last passing check)."""
        self._kept = kept_copies(self._kept, [getattr(self, f) for f in self._SLOT_FIELDS])
        return (
            self._kept,
            [getattr(self, f) for f in self._COUNTERS],
            self.stream.snapshot(),
        )

    def restore(self, snap: tuple[Any, ...]) -> None:
        slots, counters, stream = snap
        for f, a in zip(self._SLOT_FIELDS, slots, strict=True):
            np.copyto(getattr(self, f), a)
        for f, value in zip(self._COUNTERS, counters, strict=True):
            setattr(self, f, value)
        self.stream.restore(stream)
        # The free list follows the state's alive flags, restored with the state:
        # rebuilt at the next step. The energy books compare every slot once.
        self._stale = True
        self._born_rows = None

    def _dead_booked(self, slots: np.ndarray) -> None:
        """The alive count and the energy books' rows after ``slots`` died."""
        self._note(slots, born=False)
        self.alive_count -= len(slots)

    def _kill(self, slots: np.ndarray) -> None:
        self._dead_booked(slots)
        if self._kernels is not None:
            self._kernels["kill"](
                np.sort(slots), self.alive, self.m, self.inv_m, self.v, self.slot_death,
                self._free, self._sizes, self._scratch,
            )  # fmt: skip
            return
        self.alive[slots] = False
        self.m[slots] = 0.0
        self.inv_m[slots] = 0.0
        self.v[slots] = 0.0  # a dead slot must not drift
        self.slot_death[slots] = np.inf

    def _note(self, slots: np.ndarray, born: bool) -> None:
        """Remember slots whose alive flag changed, for the energy books (take_changed)."""
        if self._born_rows is None:
            return
        (self._born_rows if born else self._dead_rows).append(slots)
        self._changed_count += len(slots)
        if self._changed_count > self.capacity:  # nobody is asking: comparing all is cheaper
            self._born_rows = None

    def take_changed(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(slots born, sorted and unique; slots dead, any order) since the last call, as
        global rows; None when not known (then any slot may have changed)."""
        born, dead = self._born_rows, self._dead_rows
        self._born_rows, self._dead_rows, self._changed_count = [], [], 0
        if born is None:
            return None
        if len(born) == 1:  # one step's births: the lowest free slots, ascending
            b = born[0]
        else:
            b = np.unique(np.concatenate(born)) if born else np.zeros(0, dtype=np.int64)
        d = (dead[0] if len(dead) == 1 else np.concatenate(dead)) if dead else np.zeros(0, dtype=np.int64)
        if self.first == 0:  # a pool at the first row: its slots are the rows (no new arrays)
            return b, d
        return self.first + b, self.first + d

    def _accepted(self, events: Births, dying: np.ndarray) -> np.ndarray:
        """Boolean mask of the events that find room in the pool, at their exact times.

        With A0 alive at the step's start and D(b) of them dead by time b,
        birth i (1-based) sees f_i = cap - A0 + D(b_i) free slots not taken by
        earlier births; the kept count c_i = min(c_{i-1} + 1, f_i), whose
        closed form (f non-decreasing) is c_i = i + min(0, min_{j<=i} f_j - j).
        """
        k = len(events)
        if self.alive_count + k <= self.capacity:
            return np.ones(k, dtype=bool)
        deaths = np.sort(self.slot_death[dying])
        free = self.capacity - self.alive_count + np.searchsorted(deaths, events.time, side="right")
        i = np.arange(1, k + 1)
        kept = i + np.minimum(0, np.minimum.accumulate(free - i))
        return np.diff(kept, prepend=0) > 0

    def births(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Take this step's births into free slots; return (global indices, birth times)."""
        events = self.stream.take(t1)
        if self._kernels is not None:
            return self._births_numba(events, t1)
        dying = np.flatnonzero(self.slot_death <= t1)
        keep = self._accepted(events, dying) if len(events) else np.zeros(0, dtype=bool)
        if len(dying):
            self.died_age += len(dying)
            self._kill(dying)
        n = int(np.count_nonzero(keep))
        self.dropped += len(events) - n
        if n == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        events = events.kept(keep, n)
        slots = np.flatnonzero(~self.alive)[:n]
        self.alive[slots] = True
        self.m[slots] = self.mass
        self.inv_m[slots] = 1.0 / self.mass
        self.x[slots] = events.position
        self.v[slots] = events.velocity
        self.slot_birth[slots] = events.time
        self.slot_lifetime[slots] = events.lifetime
        self.slot_death[slots] = events.time + events.lifetime
        self.slot_serial[slots] = self.born + np.arange(n)
        self.slot_table[slots] = -1
        self._booked(slots, events)
        return self.first + slots, events.time

    def _booked(self, slots: np.ndarray, events: Births) -> None:
        """The counters and the energy brought in by ``events``, born into ``slots`` (whose
        fields are set)."""
        n = len(slots)
        self._note(slots, born=True)
        self.born += n
        self.alive_count += n
        self.kinetic_energy_born += (
            0.5 * self.mass * float(np.einsum("ij,ij->", events.velocity, events.velocity))
        )

    def _births_numba(self, events: Births, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`births` in one kernel call for the deaths by age, the room
        test and the slots' fields; the counters here, as the scans do them."""
        keep = np.empty(len(events), dtype=bool)
        dead, n = self._kernels["births"](*self.births_args(events, t1, keep))
        got = self._births_booked(events, keep, dead, n)
        if got is None:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        return self.first + got[0], got[1].time

    def births_args(self, events: Births, t1: float, keep: np.ndarray) -> tuple[Any, ...]:
        """_pool_births' arguments for this pool's births to t1 (``keep`` receives the
        events' mask), the free list and the death queue rebuilt first if stale."""
        if self._stale:
            self._rebuild()
        return (
            t1, np.ascontiguousarray(events.time), np.ascontiguousarray(events.lifetime),
            np.ascontiguousarray(events.position), np.ascontiguousarray(events.velocity),
            self.mass, 1.0 / self.mass, self.alive_count, self.born, self.capacity,
            self.x, self.v, self.alive, self.m, self.inv_m,
            self.slot_birth, self.slot_death, self.slot_lifetime, self.slot_serial, self.slot_table,
            self._free, self._sizes, self._q, self._qs, self._bounds, self._dying, self._scratch,
            keep, self._taken,
        )  # fmt: skip

    def _births_booked(
        self, events: Births, keep: np.ndarray, dead: int, n: int
    ) -> tuple[np.ndarray, Births] | None:
        """The counters after _pool_births: ``dead`` deaths by age (in _dying), ``n`` of
        ``events`` kept (``keep``, into _taken); (the pool's slots born, their events), or
        None when none was kept."""
        if dead:
            self.died_age += dead
            self._dead_booked(self._dying[:dead].copy())
        self.dropped += len(events) - n
        if n == 0:
            return None
        slots, kept = self._taken[:n].copy(), events.kept(keep, n)
        self._booked(slots, kept)
        return slots, kept

    def step_numba(
        self, state: State, events: Births, t1: float, t_mid: float, call: Any, tables: Any
    ) -> tuple[int, bool]:
        """This pool's births, newborns and deaths of a step in one compiled call
        (_pool_step through ``call``, with ``tables``: the newborns' forces and colliders);
        the counters here, as :meth:`births` and :meth:`deaths` keep them. Returns
        (births kept, whether a birth or death changed the state as :meth:`deaths` says)."""
        keep = np.empty(len(events), dtype=bool)
        call(*self.step_args(state, events, t1, t_mid, tables, keep))
        dead, n, old, out = self._counts.tolist()
        self._births_booked(events, keep, dead, n)
        if old:  # as deaths: newborns at their age limit, then the kill box
            self.died_age += old
            self._dead_booked(self._gone[:old].copy())
        if out:
            self.died_kill_box += out
            self._dead_booked(self._gone[old : old + out].copy())
        self.peak_alive = max(self.peak_alive, self.alive_count)
        return n, bool(n or old or out)

    def step_args(
        self, state: State, events: Births, t1: float, t_mid: float, tables: Any, keep: np.ndarray
    ) -> tuple[Any, ...]:
        """_pool_step's arguments for this pool's step to t1 with ``events`` (``keep``
        receives their mask; ``tables``: the masses, then the newborns' kernels)."""
        box = self.kill_lo is not None
        return (
            state.particle_position, state.particle_velocity, *tables[0], t_mid, self.first,
            *self.births_args(events, t1, keep), *tables[1], box,
            self.kill_lo if box else _NO_BOX, self.kill_hi if box else _NO_BOX, self._gone, self._counts,
        )  # fmt: skip

    def deaths(self, t1: float, newborn: np.ndarray) -> bool:
        """Newborns that already reached their age limit, and anything outside the kill box."""
        changed = False
        if self._kernels is not None and self._stale:
            self._rebuild()
        if len(newborn):
            local = newborn - self.first
            old = local[self.slot_death[local] <= t1]
            if len(old):
                self.died_age += len(old)
                self._kill(old)
                changed = True
        if self.kill_lo is not None and self.alive_count:
            if self._kernels is not None:
                count = self._kernels["outside"](self.x, self.alive, self.kill_lo, self.kill_hi, self._dying)
                out = self._dying[:count].copy()
            else:
                out = np.flatnonzero(self._outside_box())
            if len(out):
                self.died_kill_box += len(out)
                self._kill(out)
                changed = True
        self.peak_alive = max(self.peak_alive, self.alive_count)
        return changed

    def _outside_box(self) -> np.ndarray:
        """Alive slots with a coordinate outside the kill box, as a mask: column by column
        into one boolean buffer (a quarter of ``((x < lo) | (x > hi)).any(axis=1)``'s time,
        whose reduction over an inner axis of 3 dominated; the same booleans)."""
        x, lo, hi = self.x, self.kill_lo, self.kill_hi
        assert lo is not None and hi is not None
        out = np.less(x[:, 0], lo[0])
        scratch = np.empty_like(out)
        out |= np.greater(x[:, 0], hi[0], out=scratch)
        for c in (1, 2):
            out |= np.less(x[:, c], lo[c], out=scratch)
            out |= np.greater(x[:, c], hi[c], out=scratch)
        out &= self.alive
        return out

    def summary(self) -> dict[str, Any]:
        return {
            "born": self.born,
            "dropped": self.dropped,
            "died_age": self.died_age,
            "died_kill_box": self.died_kill_box,
            "alive": self.alive_count,
            "peak_alive": self.peak_alive,
            "max_particles": self.capacity,
            "kinetic_energy_born": self.kinetic_energy_born,
        }
