"""The numba kernels of the emitter pools' bookkeeping (the numba backend).

The free list merge, the death queue's compaction, a pool's births and deaths
by age (:func:`_pool_births`), the kill box test and the birth step that also
flies and collides the newborns (:func:`_pool_step`), plain Python until
:func:`numba_kernels` compiles them (or loads them from numba's disk cache) on
first use. The helpers are marked :func:`~animsim.elements.numba_helper` and
compiled by name from this module's namespace, so every helper a kernel calls
lives here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.elements import compile_helpers, numba_helper, numba_inline_helper


@numba_helper
def _free_merge(free: np.ndarray, sizes: np.ndarray, slots: np.ndarray, scratch: np.ndarray) -> None:
    """Sorted ``slots`` into the sorted free list free[sizes[2] : sizes[2] + sizes[1]]
    (a merge of two sorted runs), which then starts at free[0]."""
    head, count = sizes[2], sizes[1]
    i, j, n = 0, 0, 0
    while i < count or j < slots.shape[0]:
        if j == slots.shape[0] or (i < count and free[head + i] < slots[j]):
            scratch[n] = free[head + i]
            i += 1
        else:
            scratch[n] = slots[j]
            j += 1
        n += 1
    free[:n] = scratch[:n]
    sizes[1], sizes[2] = n, 0


@numba_helper
def _pool_kill(
    slots: np.ndarray,
    alive: np.ndarray,
    m: np.ndarray,
    inv_m: np.ndarray,
    v: np.ndarray,
    slot_death: np.ndarray,
    free: np.ndarray,
    sizes: np.ndarray,
    scratch: np.ndarray,
) -> None:
    """Pool._kill with the free list: the slots (ascending) die and join it."""
    for s in slots:
        alive[s] = False
        m[s] = 0.0
        inv_m[s] = 0.0
        v[s, 0] = 0.0
        v[s, 1] = 0.0
        v[s, 2] = 0.0
        slot_death[s] = np.inf
    _free_merge(free, sizes, slots, scratch)


@numba_helper
def _queue_compact(
    q: np.ndarray,
    qs: np.ndarray,
    bounds: np.ndarray,
    sizes: np.ndarray,
    alive: np.ndarray,
    slot_serial: np.ndarray,
    merge: bool,
) -> None:
    """Keep only the death queue's entries of alive slots (at most one per slot, so at most
    the pool's size), in their runs; with ``merge``, as one run sorted by time."""
    n = 0
    runs = 0
    for r in range(sizes[3]):
        lo, hi = bounds[r, 1], bounds[r, 2]
        bounds[runs, 0] = n
        for e in range(lo, hi):
            s = qs[e, 0]
            if alive[s] and slot_serial[s] == qs[e, 1]:
                q[n, 0] = q[e, 0]
                qs[n, 0] = s
                qs[n, 1] = qs[e, 1]
                n += 1
        if n == bounds[runs, 0]:
            continue
        bounds[runs, 1] = bounds[runs, 0]
        bounds[runs, 2] = n
        runs += 1
    if merge and runs > 1:
        order = np.argsort(q[:n, 0], kind="mergesort")
        t = q[:n, 0][order]
        a = qs[:n, 0][order]
        b = qs[:n, 1][order]
        q[:n, 0] = t
        qs[:n, 0] = a
        qs[:n, 1] = b
        bounds[0, 0], bounds[0, 1], bounds[0, 2] = 0, 0, n
        runs = 1
    sizes[3] = runs
    sizes[4] = n


@numba_helper
def _pool_births(
    t1: float,
    ev_time: np.ndarray,
    ev_life: np.ndarray,
    ev_pos: np.ndarray,
    ev_vel: np.ndarray,
    mass: float,
    inv_mass: float,
    alive_count: int,
    born: int,
    capacity: int,
    x: np.ndarray,
    v: np.ndarray,
    alive: np.ndarray,
    m: np.ndarray,
    inv_m: np.ndarray,
    slot_birth: np.ndarray,
    slot_death: np.ndarray,
    slot_lifetime: np.ndarray,
    slot_serial: np.ndarray,
    slot_table: np.ndarray,
    free: np.ndarray,
    sizes: np.ndarray,
    q: np.ndarray,
    qs: np.ndarray,
    bounds: np.ndarray,
    dying: np.ndarray,
    scratch: np.ndarray,
    keep: np.ndarray,
    taken: np.ndarray,
) -> tuple[int, int]:
    """Pool.births in one call: (deaths by age, births kept).

    The same steps as the NumPy scans: the slots due by t1 die, the events
    find room by the same closed form (:meth:`Pool._accepted`), and the kept
    ones take the lowest free slots in order. The due slots come from the
    death queue: runs of (death time, slot, serial), one per step with
    births, each sorted by time, so a step reads each run's head and the
    entries that are due, never the whole pool. An entry whose slot died
    otherwise (kill box) or was taken again is recognised by its serial and
    skipped, as in a lazy priority queue. ``dying``, ``keep`` and ``taken``
    receive the dead slots (ascending), the kept-events mask and the slots taken.
    """
    nd = _due_deaths(t1, q, qs, bounds, sizes, alive, slot_serial, dying)
    _kept_events(ev_time, alive_count, capacity, slot_death, dying[:nd], keep)
    if nd:
        _pool_kill(dying[:nd], alive, m, inv_m, v, slot_death, free, sizes, scratch)
    n = _take_slots(
        ev_time, ev_life, ev_pos, ev_vel, mass, inv_mass, born, keep,
        x, v, alive, m, inv_m, slot_birth, slot_death, slot_lifetime, slot_serial, slot_table,
        free, sizes, taken,
    )  # fmt: skip
    if n:
        _queue_newborns(n, taken, alive, slot_death, slot_serial, q, qs, bounds, sizes)
    return nd, n


@numba_inline_helper
def _due_deaths(
    t1: float,
    q: np.ndarray,
    qs: np.ndarray,
    bounds: np.ndarray,
    sizes: np.ndarray,
    alive: np.ndarray,
    slot_serial: np.ndarray,
    dying: np.ndarray,
) -> int:
    """The slots the death queue says die by t1, ascending (as a scan finds them), into
    ``dying``; how many. Each run's head moves past the entries read; an entry whose slot
    died otherwise or was taken again (its serial differs) is skipped."""
    nd = 0
    for r in range(sizes[3]):
        h, end = bounds[r, 1], bounds[r, 2]
        while h < end and q[h, 0] <= t1:
            s = qs[h, 0]
            if alive[s] and slot_serial[s] == qs[h, 1]:
                dying[nd] = s
                nd += 1
            h += 1
        bounds[r, 1] = h
    if nd:
        dying[:nd] = np.sort(dying[:nd])  # ascending slots, as a scan finds them
    return nd


@numba_inline_helper
def _kept_events(
    ev_time: np.ndarray,
    alive_count: int,
    capacity: int,
    slot_death: np.ndarray,
    dying: np.ndarray,
    keep: np.ndarray,
) -> None:
    """keep[i]: whether event i finds room in the pool, by Pool._accepted's closed form
    (``dying``: the slots that die by the step's end, freeing room at their death times)."""
    k = ev_time.shape[0]
    if alive_count + k <= capacity:
        for i in range(k):
            keep[i] = True
        return
    # kept_i = i + min(0, min_{j<=i} f_j - j), f_j = cap - A0 + D(b_j) (Pool._accepted)
    deaths = np.sort(slot_death[dying])
    low = 0
    prev = 0
    for i in range(k):
        f = capacity - alive_count + np.searchsorted(deaths, ev_time[i], side="right")
        if i == 0 or f - (i + 1) < low:
            low = f - (i + 1)
        kept = (i + 1) + min(0, low)
        keep[i] = kept - prev > 0
        prev = kept


@numba_inline_helper
def _take_slots(
    ev_time, ev_life, ev_pos, ev_vel, mass, inv_mass, born, keep,
    x, v, alive, m, inv_m, slot_birth, slot_death, slot_lifetime, slot_serial, slot_table,
    free, sizes, taken,
):  # fmt: skip
    """The kept events born into the lowest free slots, in order (``taken``: the slots);
    how many."""
    n = 0
    head = sizes[2]
    for i in range(ev_time.shape[0]):
        if not keep[i]:
            continue
        s = free[head + n]
        taken[n] = s
        alive[s] = True
        m[s] = mass
        inv_m[s] = inv_mass
        for c in range(3):
            x[s, c] = ev_pos[i, c]
            v[s, c] = ev_vel[i, c]
        slot_birth[s] = ev_time[i]
        slot_lifetime[s] = ev_life[i]
        slot_death[s] = ev_time[i] + ev_life[i]
        slot_serial[s] = born + n
        slot_table[s] = -1
        n += 1
    sizes[1] -= n
    sizes[2] = head + n
    return n


@numba_inline_helper
def _queue_newborns(
    n: int,
    taken: np.ndarray,
    alive: np.ndarray,
    slot_death: np.ndarray,
    slot_serial: np.ndarray,
    q: np.ndarray,
    qs: np.ndarray,
    bounds: np.ndarray,
    sizes: np.ndarray,
) -> None:
    """The ``n`` newborns' deaths as a new run of the death queue, sorted by time (room made
    by compacting the queue first when it is full)."""
    runs_full = sizes[3] == bounds.shape[0]
    if sizes[4] + n > q.shape[0] or runs_full:
        _queue_compact(q, qs, bounds, sizes, alive, slot_serial, runs_full)
    order = np.argsort(slot_death[taken[:n]], kind="mergesort")
    e = sizes[4]
    for j in range(n):
        s = taken[order[j]]
        q[e + j, 0] = slot_death[s]
        qs[e + j, 0] = s
        qs[e + j, 1] = slot_serial[s]
    r = sizes[3]
    bounds[r, 0], bounds[r, 1], bounds[r, 2] = e, e, e + n
    sizes[3] = r + 1
    sizes[4] = e + n


@numba_helper
def _outside_box(x: np.ndarray, alive: np.ndarray, lo: np.ndarray, hi: np.ndarray, out: np.ndarray) -> int:
    """The alive slots with a coordinate below lo or above hi (the kill box test), ascending,
    into ``out``; how many. One pass instead of NumPy's six over (capacity, 3) arrays."""
    n = 0
    for i in range(x.shape[0]):
        if alive[i] and (
            x[i, 0] < lo[0]
            or x[i, 0] > hi[0]
            or x[i, 1] < lo[1]
            or x[i, 1] > hi[1]
            or x[i, 2] < lo[2]
            or x[i, 2] > hi[2]
        ):
            out[n] = i
            n += 1
    return n


def _pool_step(
    xs, vs, mass_all, inv_mass_all, t_mid, first,
    t1, ev_time, ev_life, ev_pos, ev_vel, mass, inv_mass, alive_count, born, capacity,
    x, v, alive, m, inv_m, slot_birth, slot_death, slot_lifetime, slot_serial, slot_table,
    free, sizes, q, qs, bounds, dying, scratch, keep, taken,
    kernels, fps, ips, stage_fns, stage_fps, stage_ips,
    has_box, box_lo, box_hi, gone, counts,
):  # fmt: skip
    """One pool's part of :meth:`Emitters.advance` in one call (the numba backend's birth
    step, :meth:`Pool.step_numba`): its births and deaths by age (_pool_births), its
    newborns flown on for the rest of their birth step and collided, then its newborns
    already at their age limit and the rows outside its kill box killed.

    ``xs``, ``vs``, ``mass_all``, ``inv_mass_all``: the whole system's rows (the pool's
    slots are ``first`` onward; ``x``, ``v``, ``alive``, ``m``, ``inv_m`` are its slices).
    ``t1`` to ``taken`` are _pool_births' arguments (:meth:`Pool.births_args`).
    The newborns' acceleration is the pointwise force kernels ``kernels`` (as the fused
    stepper calls them) on their rows alone at ``t_mid``, summed in the kernels' order,
    then times the inverse mass, as a full evaluation gives each row; they move by
    x += r v0 + (r^2 / 2) a, v += r a over their rest r = t1 - birth time, and meet the
    newborn kernels ``stage_fns`` (each stage's ``collide_subset``) in order. Every
    number is the one the Python path of :meth:`Emitters.advance` computes.

    ``counts`` receives (deaths by age among the alive, births kept, newborns dead at
    once, deaths outside the box); ``gone`` the slots of the last two, in that order.
    """
    dead, n = _pool_births(
        t1, ev_time, ev_life, ev_pos, ev_vel, mass, inv_mass, alive_count, born, capacity,
        x, v, alive, m, inv_m, slot_birth, slot_death, slot_lifetime, slot_serial, slot_table,
        free, sizes, q, qs, bounds, dying, scratch, keep, taken,
    )  # fmt: skip
    old = 0
    if n:
        rest = np.empty(n)
        j = 0
        for i in range(ev_time.shape[0]):
            if keep[i]:
                rest[j] = t1 - ev_time[i]
                j += 1
        x0 = np.empty((n, 3))
        v0 = np.empty((n, 3))
        a = np.zeros((n, 3))
        x1 = np.empty((n, 3))
        v1 = np.empty((n, 3))
        mm = np.empty(n)
        for j in range(n):
            r = first + taken[j]
            mm[j] = mass_all[r]
            for c in range(3):
                x0[j, c] = xs[r, c]
                v0[j, c] = vs[r, c]
        # fused_kernels.accelerations' sum, written here rather than called: numba's disk cache does not
        # notice when a compiled callee in another file changes, and would keep stale code
        for k in range(len(kernels)):
            kernels[k](x0, v0, t_mid, a, mm, fps[k], ips[k])
        for j in range(n):
            w = inv_mass_all[first + taken[j]]
            r = rest[j]
            h = 0.5 * r * r
            for c in range(3):
                a[j, c] *= w
                x1[j, c] = x0[j, c] + r * v0[j, c] + h * a[j, c]
                v1[j, c] = v0[j, c] + r * a[j, c]
        for k in range(len(stage_fns)):
            stage_fns[k](x0, v0, x1, v1, rest, stage_fps[k], stage_ips[k])
        for j in range(n):
            r = first + taken[j]
            for c in range(3):
                xs[r, c] = x1[j, c]
                vs[r, c] = v1[j, c]
        for j in range(n):  # ascending, as the slots were taken
            if slot_death[taken[j]] <= t1:
                gone[old] = taken[j]
                old += 1
        if old:
            _pool_kill(gone[:old], alive, m, inv_m, v, slot_death, free, sizes, scratch)
    out = 0
    if has_box and alive_count - dead + n - old > 0:
        out = _outside_box(x, alive, box_lo, box_hi, gone[old:])
        if out:
            _pool_kill(gone[old : old + out], alive, m, inv_m, v, slot_death, free, sizes, scratch)
    counts[0] = dead
    counts[1] = n
    counts[2] = old
    counts[3] = out


#: the bookkeeping kernels compiled by numba (filled on first use of the numba backend)
_NUMBA: dict[str, Any] = {}


def numba_kernels() -> dict[str, Any]:
    """The pool kernels compiled by numba (cached on disk), with their helper."""
    if not _NUMBA:
        import numba

        compile_helpers(globals())
        births = globals()["_pool_births"]  # compiled above, as helpers of the birth step
        kill = globals()["_pool_kill"]
        # Compile (or load from the disk cache) now, before any run is timed: a call on a
        # one-slot pool with no events and no deaths, with the types a pool passes.
        f, i = np.zeros(1), np.zeros(1, dtype=np.int64)
        xv, alive, none = np.zeros((1, 3)), np.zeros(1, dtype=bool), np.zeros(0)
        sizes = np.zeros(5, dtype=np.int64)
        q, qs, bounds = np.zeros((2, 1)), np.zeros((2, 2), dtype=np.int64), np.zeros((1, 3), dtype=np.int64)
        births(
            0.0, none, none, np.zeros((0, 3)), np.zeros((0, 3)), 1.0, 1.0, 0, 0, 1, xv, xv, alive,
            f, f, f, f, f, i, i, i, sizes, q, qs, bounds, i, i, np.zeros(0, dtype=bool), i,
        )  # fmt: skip
        kill(np.zeros(0, dtype=np.int64), alive, f, f, xv, f, i, sizes, i)
        outside = globals()["_outside_box"]
        outside(xv, alive, np.zeros(3), np.zeros(3), i)
        _NUMBA["births"], _NUMBA["kill"], _NUMBA["outside"] = births, kill, outside
        # the birth step is compiled (or loaded) by its first call, with the scene's tables
        _NUMBA["step"] = numba.njit(cache=True)(_pool_step)
    return _NUMBA
