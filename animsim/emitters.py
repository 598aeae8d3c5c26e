"""Particle systems: emitter pools with births, attributes, ageing and deaths.

The course notes' "Basic Model of Particle Systems" (after Reeves 1983): at
each frame new particles are born and given attributes, particles that have
exceeded their life span are terminated, the rest are animated and their
shading (size, colour) changes. This module does the bookkeeping; forces,
integrators and plane collisions move emitted particles exactly like any
other particle, because emitted particles live in the same global arrays.

Storage
    Each emitter owns a preallocated pool of ``max_particles`` slots appended
    after the fixed particles (structure of arrays). A dead slot has mass 0
    and inverse mass 0, so no force moves it and collisions skip it; its
    velocity is zeroed so no integrator drifts it. ``state.particle_alive``
    marks the alive slots. Memory is bounded by the cap, not by run length:
    births are generated chunk by chunk as time advances.

Births in time, independent of dt
    Births are a random process in *time*, drawn from the emitter's own
    random streams, never from the step: the birth times and every birth's
    attributes are the same whatever dt or integrator is used. The rate
    r(t) is ``rate`` or piecewise-linear keyframes (before the first and
    after the last keyframe it holds that keyframe's value; two keyframes at
    one time make a jump). ``rate_spread`` s is the standard deviation of the
    rate itself, redrawn every RATE_NOISE_WINDOW of simulated time (Reeves's
    "NParts = MeanParts + Rand() * VarParts", held for a fixed span of
    simulated time instead of a frame so it does not depend on dt). Within
    that, births form a Poisson process of intensity
    lambda(t) = max(0, r(t) + s xi_w), drawn by thinning (Lewis and Shedler
    1979): candidates at rate lambda_max, each kept with probability
    lambda(t)/lambda_max. So births in T seconds of constant rate number
    r T on average, with variance r T (+ s^2 w T from the rate noise,
    w the noise window).

Attributes (constrained randomization, course notes)
    Position from the shape: a point; uniform inside a sphere by rejection
    ("re-randomize if outside the radius", as the notes do it); uniform in a
    box; uniform on a disc (rejection in the square, then laid in the plane
    perpendicular to the normal). Velocity: mean + spread * N(0, 1) per
    component. Lifetime: mean + spread * N(0, 1), redrawn while <= 0 (a
    truncated Gaussian; since the mean is > 0 at least half of all draws are
    kept, so the redraw loop ends quickly). Mass is the emitter's. Size and
    RGBA colour are linear in age / lifetime between start and end.

The rest of the birth step
    A particle born at tau inside the step [t0, t1) is advanced for the rest
    of it, r = t1 - tau, ballistically with the acceleration at birth,
    x = x0 + r v0 + r^2/2 a0, v = v0 + r a0 (a0 = F(x0, v0)/m evaluated once
    per step with births, at the step's midpoint time), then collided with
    the impulse planes over that same partial step. Once per particle this
    errs by O(r^3) in position and O(r^2) in velocity (the acceleration is
    held constant, and taken at one time for the whole step), and the
    velocity error carries into the position for the rest of the flight, so
    emitted trajectories converge at order min(p, 2) for an integrator of
    order p (measured: 1 for symplectic Euler, 2 for midpoint and for rk4).
    A higher order would need one more force evaluation over every slot per
    step, at the per-particle birth time, which the force contract (one
    scalar t) does not offer.

Deaths
    At the exact age limit: a particle is alive for birth <= t < birth +
    lifetime, so the same particles are alive at a recorded time whatever dt
    is. Outside the optional ``kill_box``, checked at the end of every step
    (this one depends on the trajectory, so on dt, like any position). A full
    pool drops births: birth i is kept if, at its exact time, fewer than
    ``max_particles`` are alive (counting deaths by age before it), which is
    also independent of dt. Dropped births are counted in the run's metadata
    (``summary``). Deaths by age of particles born in the same step do not
    free slots for later births of that step (that matters only when
    lifetimes are shorter than dt and the pool is full).

Ids and order
    Ids are ``<name>#<n>``, n counting the emitter's (kept) births from 0,
    never reused. Each birth event's attributes are drawn whether or not the
    pool has room, so raising ``max_particles`` does not change the
    attributes drawn for later events. Frames hold the alive particles in
    creation order: fixed particles first, then emitted ones by birth time
    (ties by emitter order).

Bookkeeping on the numba backend
    A step's births and deaths by age are one compiled call per pool instead
    of about forty NumPy calls and two scans of every slot: the death times
    wait in a queue of runs, one per step with births, each sorted by time,
    so a step reads only the runs' heads and the entries due (a lazy
    priority queue: an entry of a slot that died otherwise is skipped when
    it comes up); the free slots are kept as a sorted list (dead slots merged
    in, births taking its head) instead of being searched for. They choose
    the same slots as the NumPy scans, in the same order, so both backends
    give the same particles bit for bit. When the newborns' forces read only
    their own rows and every collider has a newborn kernel, the same call
    also flies the newborns on, collides them and kills those already at
    their age limit or outside the kill box (:func:`_pool_step`): a step of
    an emitter is then one compiled call and a little bookkeeping in Python.

Random streams
    Every emitter has its own streams, seeded by ``np.random.SeedSequence``
    from (scene seed, a hash of the emitter's name): one for birth times and
    rate noise, one for attributes. Adding, removing or reordering another
    emitter does not change this one's particles.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.colors import parse_color
from animsim.elements import StepStage, compile_helpers, numba_helper
from animsim.record import Frame
from animsim.scene import models as m
from animsim.system import State, kept_copies
from animsim.vec import put_rows

#: The rate noise (``rate_spread``) is held for this span of simulated time, s.
RATE_NOISE_WINDOW = 0.1
#: Births are generated in chunks of about this many candidates, so memory is
#: bounded by the chunk, not the run (a noise window is split if needed).
CHUNK_BIRTHS = 4096
#: Rate-noise draws above this many standard deviations are rare enough to
#: ignore when sizing chunks (sizing only; it never truncates the noise).
RATE_NOISE_SIGMAS = 4.0
#: Volume of the unit ball over that of the cube [-1, 1]^3 (pi/6): the
#: acceptance rate of sphere rejection sampling; the disc's is pi/4.
BALL_ACCEPTANCE = np.pi / 6.0
DISC_ACCEPTANCE = np.pi / 4.0
#: Oversampling of rejection batches so one batch nearly always suffices.
REJECTION_MARGIN = 1.2
REJECTION_EXTRA = 16
#: Tag that separates emitter streams from other uses of the scene seed.
EMITTER_STREAM_TAG = 0x656D_6974  # "emit"
#: Words of the name hash mixed into the seed (4 x 32 bits).
NAME_HASH_WORDS = 4
#: The numba backend's death queue (Pool.use_numba): at most this many runs (one per
#: step with births; more are merged into one), and rows for twice the pool (entries
#: of slots already dead are dropped when the rows run out).
QUEUE_RUNS = 1024
QUEUE_SLACK = 64


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
    k = ev_time.shape[0]
    if alive_count + k <= capacity:
        for i in range(k):
            keep[i] = True
    else:
        # kept_i = i + min(0, min_{j<=i} f_j - j), f_j = cap - A0 + D(b_j) (Pool._accepted)
        deaths = np.sort(slot_death[dying[:nd]])
        low = 0
        prev = 0
        for i in range(k):
            f = capacity - alive_count + np.searchsorted(deaths, ev_time[i], side="right")
            if i == 0 or f - (i + 1) < low:
                low = f - (i + 1)
            kept = (i + 1) + min(0, low)
            keep[i] = kept - prev > 0
            prev = kept
    if nd:
        _pool_kill(dying[:nd], alive, m, inv_m, v, slot_death, free, sizes, scratch)
    n = 0
    head = sizes[2]
    for i in range(k):
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
    if n:
        # the newborns' deaths as a new run, sorted by time (room made by compacting first)
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
    return nd, n


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
        # fused._acc's sum, written here rather than called: numba's disk cache does not
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
#: the kill box of a pool without one (the birth step's argument, never read)
_NO_BOX = np.zeros(3)


def _numba_kernels() -> dict[str, Any]:
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


def _name_words(name: str) -> list[int]:
    digest = hashlib.sha256(name.encode("utf-8")).digest()
    return [int.from_bytes(digest[4 * i : 4 * i + 4], "little") for i in range(NAME_HASH_WORDS)]


@dataclass(frozen=True)
class RateSchedule:
    """Piecewise-linear births per second; holds the end values outside the keyframes.

    ``times`` non-decreasing (s); equal times make a jump (right-continuous).
    """

    times: np.ndarray
    values: np.ndarray

    @classmethod
    def from_spec(cls, rate: float | list[list[float]]) -> RateSchedule:
        if isinstance(rate, list):
            kf = np.array(rate, dtype=np.float64).reshape(-1, 2)
            return cls(kf[:, 0].copy(), kf[:, 1].copy())
        return cls(np.array([0.0]), np.array([float(rate)]))

    @functools.cached_property
    def constant(self) -> bool:
        return bool(np.all(self.values == self.values[0]))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        if self.constant:
            # what the interpolation gives, v + w * 0.0 = v, without its eight passes (a
            # fountain's 2,500 events a chunk: 40 us)
            return np.full(t.shape, self.values[0])
        return self._interpolate(t)

    def _interpolate(self, t: np.ndarray) -> np.ndarray:
        k = np.searchsorted(self.times, t, side="right")
        lo = np.clip(k - 1, 0, len(self.times) - 1)
        hi = np.clip(k, 0, len(self.times) - 1)
        t0, t1 = self.times[lo], self.times[hi]
        span = t1 - t0
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(span > 0, (t - t0) / np.where(span > 0, span, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)
        return self.values[lo] + w * (self.values[hi] - self.values[lo])

    def max_over(self, a: float, b: float) -> float:
        """An upper bound (the maximum) of the rate over [a, b]."""
        if self.constant:
            return float(self.values[0])
        return self._max_interpolated(a, b)

    def _max_interpolated(self, a: float, b: float) -> float:
        inside = (self.times >= a) & (self.times <= b)
        ends = self(np.array([a, b]))
        return float(max(ends.max(), self.values[inside].max() if inside.any() else 0.0))

    def describe(self) -> str:
        if len(self.times) == 1:
            return f"{self.values[0]:g}/s"
        return "keyframes " + ", ".join(
            f"{v:g}/s at {t:g} s" for t, v in zip(self.times, self.values, strict=True)
        )


class ShapeSampler:
    """Uniform birth positions in an emitter shape (constrained randomization).

    Built from the scene's shape once (compile time); sampling reads plain numbers.
    """

    def __init__(self, shape: m.PointShape | m.SphereShape | m.BoxShape | m.DiscShape):
        self.kind = shape.type
        if self.kind == "point":
            self.center = np.array(shape.position, dtype=np.float64)
            self.text = f"point {list(shape.position)}"
        elif self.kind == "box":
            self.lo = np.array(shape.min, dtype=np.float64)
            self.hi = np.array(shape.max, dtype=np.float64)
            self.text = f"box {list(shape.min)}..{list(shape.max)}"
        elif self.kind == "sphere":
            self.center, self.radius = np.array(shape.center, dtype=np.float64), float(shape.radius)
            self.text = f"sphere at {list(shape.center)} r = {shape.radius:g} m (uniform inside, rejection)"
        else:  # disc
            self.center, self.radius = np.array(shape.center, dtype=np.float64), float(shape.radius)
            n = np.array(shape.normal) / np.linalg.norm(shape.normal)
            # Any vector not parallel to n gives the in-plane basis (e1, e2).
            helper = np.eye(3)[int(np.argmin(np.abs(n)))]
            e1 = np.cross(n, helper)
            e1 /= np.linalg.norm(e1)
            self.basis = np.stack([e1, np.cross(n, e1)])  # (2, 3)
            self.text = (
                f"disc at {list(shape.center)} normal {list(shape.normal)} r = {shape.radius:g} m (rejection)"
            )

    def describe(self) -> str:
        return self.text

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.kind == "point":
            return np.tile(self.center, (n, 1))
        if self.kind == "box":
            return self.lo + (self.hi - self.lo) * rng.random((n, 3))
        if self.kind == "sphere":
            unit = _inside_unit_ball(rng, n, 3, BALL_ACCEPTANCE)
            return self.center + self.radius * unit
        unit = _inside_unit_ball(rng, n, 2, DISC_ACCEPTANCE)
        return self.center + self.radius * (unit @ self.basis)


def _inside_unit_ball(rng: np.random.Generator, n: int, dim: int, acceptance: float) -> np.ndarray:
    """n points uniform in the unit ball of ``dim`` dimensions.

    The notes' constrained randomization: draw in the cube [-1, 1]^dim and
    re-randomize what falls outside the radius, in vectorised batches.
    """
    out = np.empty((n, dim))
    have = 0
    while have < n:
        want = n - have
        batch = rng.uniform(-1.0, 1.0, (int(want * REJECTION_MARGIN / acceptance) + REJECTION_EXTRA, dim))
        # np.compress: the rows a boolean index would pick, at a sixth of its time on rows
        keep = np.compress(np.einsum("ij,ij->i", batch, batch) <= 1.0, batch, axis=0)[:want]
        out[have : have + len(keep)] = keep
        have += len(keep)
    return out


def _positive_gaussian(rng: np.random.Generator, n: int, mean: float, spread: float) -> np.ndarray:
    """n draws of mean + spread*N(0, 1), each redrawn while <= 0 (a truncated Gaussian)."""
    if spread == 0.0:
        return np.full(n, mean)
    out = np.empty(n)
    have = 0
    while have < n:
        want = n - have
        batch = mean + spread * rng.standard_normal(want + REJECTION_EXTRA)
        keep = batch[batch > 0.0][:want]
        out[have : have + len(keep)] = keep
        have += len(keep)
    return out


@dataclass
class Births:
    """Birth events in time order: times (k,) s, position (k, 3), velocity (k, 3), lifetime (k,)."""

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    lifetime: np.ndarray

    @classmethod
    def empty(cls) -> Births:
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))

    def __len__(self) -> int:
        return len(self.time)

    def split(self, before: float) -> tuple[Births, Births]:
        k = int(np.searchsorted(self.time, before, side="left"))
        head = Births(self.time[:k], self.position[:k], self.velocity[:k], self.lifetime[:k])
        tail = Births(self.time[k:], self.position[k:], self.velocity[k:], self.lifetime[k:])
        return head, tail

    def kept(self, keep: np.ndarray, n: int) -> Births:
        """The events where ``keep`` (bool, ``n`` of them True) holds; itself when all do."""
        if n == len(self):
            return self
        return Births(
            self.time[keep],
            np.compress(keep, self.position, axis=0),
            np.compress(keep, self.velocity, axis=0),
            self.lifetime[keep],
        )

    @staticmethod
    def concat(parts: Sequence[Births]) -> Births:
        if len(parts) == 1:
            return parts[0]
        return Births(
            np.concatenate([p.time for p in parts]),
            np.concatenate([p.position for p in parts]),
            np.concatenate([p.velocity for p in parts]),
            np.concatenate([p.lifetime for p in parts]),
        )


class BirthStream:
    """The births of one emitter, generated chunk by chunk in absolute time.

    Chunk c covers [c h, (c+1) h); the chunk length h divides the rate-noise
    window. Both are fixed by the scene, never by dt, and each chunk draws
    from the streams in a fixed order, so the events (and their attributes)
    are a function of the seed and the scene only.
    """

    def __init__(self, spec: m.Emitter, seed: int):
        # Plain numbers only: the stream draws while stepping and never reads the scene.
        self.name = spec.name
        self.v_spread = float(spec.velocity.spread)
        self.life_mean = float(spec.lifetime.mean)
        self.life_spread = float(spec.lifetime.spread)
        self.seed = seed
        self.rate = RateSchedule.from_spec(spec.rate)
        self.spread = float(spec.rate_spread)
        self.shape = ShapeSampler(spec.shape)
        bound = float(self.rate.values.max()) + RATE_NOISE_SIGMAS * self.spread
        self.chunks_per_window = max(1, int(np.ceil(bound * RATE_NOISE_WINDOW / CHUNK_BIRTHS)))
        self.chunk_length = RATE_NOISE_WINDOW / self.chunks_per_window
        self.v_mean = np.array(spec.velocity.mean)
        self.reset()

    def reset(self) -> None:
        root = np.random.SeedSequence([self.seed, EMITTER_STREAM_TAG, *_name_words(self.name)])
        birth_ss, attr_ss = root.spawn(2)
        self.rng_birth = np.random.default_rng(birth_ss)
        self.rng_attr = np.random.default_rng(attr_ss)
        self.next_chunk = 0
        self.noise = 0.0
        self.pending = Births.empty()

    def _chunk(self) -> Births:
        c = self.next_chunk
        self.next_chunk += 1
        a = c * self.chunk_length
        b = (c + 1) * self.chunk_length
        rb = self.rng_birth
        if self.spread > 0 and c % self.chunks_per_window == 0:
            self.noise = self.spread * float(rb.standard_normal())
        lam_max = max(0.0, self.rate.max_over(a, b) + self.noise)
        count = int(rb.poisson(lam_max * (b - a)))
        t = np.sort(a + (b - a) * rb.random(count))
        u = rb.random(count)  # thinning: keep with probability lambda(t) / lambda_max
        if count:
            lam = np.maximum(self.rate(t) + self.noise, 0.0)
            t = t[u * lam_max < lam]
        k = len(t)
        ra = self.rng_attr
        position = self.shape.sample(ra, k)
        velocity = self.v_mean + self.v_spread * ra.standard_normal((k, 3))
        lifetime = _positive_gaussian(ra, k, self.life_mean, self.life_spread)
        return Births(t, position, velocity, lifetime)

    def snapshot(self) -> tuple[Any, ...]:
        """Everything a later draw depends on (the generators' states, the chunk counter, the rate
        noise and the events drawn but not taken), so :meth:`restore` repeats the same births."""
        return (
            self.rng_birth.bit_generator.state,
            self.rng_attr.bit_generator.state,
            self.next_chunk,
            self.noise,
            self.pending,
        )

    def restore(self, snap: tuple[Any, ...]) -> None:
        birth, attr, self.next_chunk, self.noise, self.pending = snap
        self.rng_birth.bit_generator.state = birth
        self.rng_attr.bit_generator.state = attr

    def take(self, t1: float) -> Births:
        """Every birth event with time < t1 not taken yet, in time order."""
        parts = [self.pending]
        while self.next_chunk * self.chunk_length < t1:
            parts.append(self._chunk())
        events, self.pending = Births.concat(parts).split(t1)
        return events


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
        # The numba backend's kernels (module docstring), set by use_numba; None: scans.
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
        self._kernels = _numba_kernels()
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
        deaths are one compiled call per pool (:func:`_pool_step`), compiled or loaded now,
        before the run is timed."""
        for p in self.pools:
            if p._kernels is None:
                p.use_numba()
        self._step = None
        forces = getattr(self.dynamics, "forces", None)
        tables = None if (forces is None or state is None) else forces.newborn_tables(self.colliders)
        if tables is None:
            return
        from animsim.backends.fused import FastCall

        both = (forces.masses(), tables)
        # one call that changes nothing (no events, nothing due by -inf, no row outside a
        # box: the pools are empty) compiles it, or loads it from the disk cache
        args = self.pools[0].step_args(state, Births.empty(), -np.inf, 0.0, both, np.empty(0, dtype=bool))
        call = FastCall(_numba_kernels()["step"], args)
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

    def restore(self, snap: list[tuple[Any, ...]]) -> None:
        for p, s in zip(self.pools, snap, strict=True):
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
