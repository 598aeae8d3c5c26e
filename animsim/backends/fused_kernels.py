"""The numba backend's compiled step loops, called by :mod:`animsim.backends.fused`.

* :func:`fused_chunk`: many steps of a fixed-step explicit method per call: the
  integrator's arithmetic (the same operations, in the same order, as
  :mod:`animsim.integrators`), every element's kernel and every fusable collision
  stage (first-class functions), stopping after the first step that is not finite;
* :func:`checked_chunk`: fused_chunk with the watchdog's checks inside;
  :func:`quick_check_state` is that check of one state, and :func:`quick_check_pieces`
  the same on numba's threads;
* :func:`blocked_chunk`, :func:`blocked_chunk_parallel`: fused_chunk for scenes whose
  particles do not act on each other, a cache-sized block of rows at a time, on the
  calling thread or on numba's threads, with the same bits;
* :func:`accelerations`: the force sum divided by the mass, pinned rows zero
  (:class:`animsim.backends.numba_forces.NumbaForces` calls it from the loop).

Why one module above the house's 600 lines: these kernels call one another and the
same compiled helpers (``_copy``, ``_all_finite``, ``_axpy``, the acceleration sums),
and numba's disk cache (``cache=True``) checks only the source file of the function it
caches. A kernel whose compiled callee lived in another file would keep the callee's
old code after that file changed (the reason :mod:`animsim.emitters.kernels` writes
its force sum out rather than call :func:`accelerations`). In one file, any edit here
recompiles every kernel that could include it.

The plain and the blocked step loops share the integrators' updates and the stage loop
(``_symplectic_euler`` ... ``_stages_changed``), which numba inlines into each loop
(``inline="always"``). numba compiles a called function on its own and calls it with
every array passed field by field: as plain calls these helpers made a one-particle
scene's step about a fifth slower (measured); inlined, the loops compile to the machine
code of the updates written out (to within a few instructions and the registers chosen)
and run as fast. Every array and table is an argument of its own, as the host passes them
(one flat tuple, to :class:`animsim.backends.kernel_calls.FastCall`); the signatures and the
calls of one kernel from another are written a group to a line (state and clock, method and
tableau, elements, stages, work arrays), not one name to a line. Passed as nested tuples
instead, the groups cost each run about half a millisecond more, for the same compiled
code: the host types a run's first call's arguments, and numba types a heterogeneous tuple
by building a union of its members' types (measured: the one-particle scene of
``benchmarks.cpu_goals tiny numba``, 20,000 steps, 3.1 against 3.6 ms a run).

Imported only when numba is in use.
"""

from __future__ import annotations

import types
import warnings
from typing import Any

import numpy as np
from numba import njit, prange
from numba.core.errors import NumbaExperimentalFeatureWarning

from animsim.integrators.base import (
    FUSED_EULER_AVERAGE as EULER_AVERAGE,
)
from animsim.integrators.base import (
    FUSED_RUNGE_KUTTA as RUNGE_KUTTA,
)
from animsim.integrators.base import (
    FUSED_SYMPLECTIC_EULER as SYMPLECTIC_EULER,
)
from animsim.integrators.base import (
    FUSED_VERLET as VERLET,
)

warnings.filterwarnings("ignore", category=NumbaExperimentalFeatureWarning)

#: numba's reference counting off (``_nrt``) in the compiled step loops, which take every
#: array from their caller and allocate none: with it on, each call into an element kernel
#: (a first-class function) was wrapped in an atomic increment and decrement of each of
#: its six arrays' counts, which the compiler could not pair off across the call, about
#: 85 ns a call: most of a tiny scene's step (accelerations on one particle 111 -> 23 ns)
COUNTED = False


@njit(cache=True, _nrt=COUNTED)
def _copy(dst, src):
    """dst[:] = src for (N, 3) arrays: an array assignment may need numba's reference
    counting (for a temporary when the two overlap), which the step loops run without."""
    for i in range(dst.shape[0]):
        for k in range(3):
            dst[i, k] = src[i, k]


@njit(cache=True, _nrt=COUNTED)
def accelerations(x, v, t, out, kernels, fps, ips, mass, inv_mass, pinned):
    """out = F(x, v, t) / m, pinned rows 0 (Dynamics.acceleration)."""
    out[:] = 0.0
    for k in range(len(kernels)):
        kernels[k](x, v, t, out, mass, fps[k], ips[k])
    for i in range(x.shape[0]):
        w = inv_mass[i]
        out[i, 0] *= w
        out[i, 1] *= w
        out[i, 2] *= w
    for p in pinned:
        out[p, 0] = 0.0
        out[p, 1] = 0.0
        out[p, 2] = 0.0


#: rows from which _all_finite tests the numbers as one flat run: reshaping an array in
#: compiled code costs about 60 ns (the views' reference counts), more than testing a
#: few rows one number at a time (about 2 ns a row), against 0.5 ns a row flat
FLAT_FINITE_FROM = 32


@njit(cache=True, _nrt=COUNTED)
def _all_finite(x, v):
    """Every number of x and v is finite: x * 0 is NaN exactly when x is not finite, so
    x * 0 == 0 says x is finite. From FLAT_FINITE_FROM rows the flags of the flat arrays
    are and-ed without a branch, a reduction the compiler may reorder and so runs four
    lanes at a time; a sum of the products (NaN when any is) is a chain of dependent
    float additions it may not reorder: 1.7 against 0.5 ns a row, and with it the
    1e6-particle benchmark 57 against 65 M particle-steps/s on one thread (cloth 32
    gains 5 % over a branch per number)."""
    n = x.shape[0]
    if n < FLAT_FINITE_FROM:
        for i in range(n):
            for k in range(3):
                if not (x[i, k] * 0.0 == 0.0 and v[i, k] * 0.0 == 0.0):
                    return False
        return True
    xf = x.reshape(x.size)
    vf = v.reshape(v.size)
    ok = True
    for i in range(xf.shape[0]):
        ok &= (xf[i] * 0.0 == 0.0) & (vf[i] * 0.0 == 0.0)
    return ok


@njit(cache=True, _nrt=COUNTED)
def _axpy(y, c, z):
    for i in range(y.shape[0]):
        for k in range(3):
            y[i, k] += c * z[i, k]


@njit(cache=True, inline="always", _nrt=COUNTED)
def _symplectic_euler(x, v, a, dt):
    """Symplectic Euler's update from the acceleration ``a``: v += a dt, then x += v dt."""
    for i in range(x.shape[0]):
        for k in range(3):
            v[i, k] += a[i, k] * dt
            x[i, k] += v[i, k] * dt


@njit(cache=True, inline="always", _nrt=COUNTED)
def _euler_average(x, v, a, dt):
    """The averaged Euler update from the acceleration ``a``: v += a dt, and x moves with
    the mean of the old and the new velocity."""
    half = 0.5 * dt
    for i in range(x.shape[0]):
        for k in range(3):
            e = a[i, k] * dt + v[i, k]
            x[i, k] += half * (v[i, k] + e)
            v[i, k] = e


@njit(cache=True, inline="always", _nrt=COUNTED)
def _verlet_drift(x, v, a0, vs, dt):
    """Velocity Verlet's first half from the acceleration ``a0``: x += v dt + a0 dt^2 / 2,
    and vs = v + a0 dt, the velocity the next acceleration is evaluated at."""
    half2 = 0.5 * dt * dt
    for i in range(x.shape[0]):
        for k in range(3):
            vs[i, k] = a0[i, k] * dt + v[i, k]
            x[i, k] += dt * v[i, k] + half2 * a0[i, k]


@njit(cache=True, inline="always", _nrt=COUNTED)
def _verlet_kick(v, a0, a1, dt):
    """Velocity Verlet's second half: v += (a0 + a1) dt / 2."""
    half = 0.5 * dt
    for i in range(v.shape[0]):
        for k in range(3):
            v[i, k] += half * (a0[i, k] + a1[i, k])


@njit(cache=True, inline="always", _nrt=COUNTED)
def _stage_state(xs, vs, x, v, kx, kv, tab_a, j, dt):
    """The state of Runge-Kutta stage j > 0 (xs, vs: x, v plus dt times row j of the
    tableau's a over the earlier stages' slopes kx, kv), and its position slope kx[j] = vs."""
    _copy(xs, x)
    _copy(vs, v)
    for m in range(j):
        if tab_a[j, m] != 0.0:
            _axpy(xs, dt * tab_a[j, m], kx[m])
            _axpy(vs, dt * tab_a[j, m], kv[m])
    _copy(kx[j], vs)


@njit(cache=True, inline="always", _nrt=COUNTED)
def _stage_sum(x, v, kx, kv, tab_b, dt):
    """The Runge-Kutta step: x, v += dt times the tableau's weights b over the stages' slopes."""
    for j in range(tab_b.shape[0]):
        if tab_b[j] != 0.0:
            _axpy(x, dt * tab_b[j], kx[j])
            _axpy(v, dt * tab_b[j], kv[j])


@njit(cache=True, inline="always", _nrt=COUNTED)
def _stages_changed(xo, vo, x, v, dt, inv_mass, stage_fns, stage_fps, stage_ips):
    """Every fusable stage in the loop's order (colliders, then planes), from the step's
    start xo, vo to its end x, v: whether one of them changed the state."""
    changed = False
    for s in range(len(stage_fns)):
        if stage_fns[s](xo, vo, x, v, dt, inv_mass, stage_fps[s], stage_ips[s]):
            changed = True
    return changed


@njit(cache=True, _nrt=COUNTED)
def fused_chunk(
    x, v, times, dts,
    method, tab_c, tab_a, tab_b,
    kernels, fps, ips, mass, inv_mass, pinned,
    stage_fns, stage_fps, stage_ips,
    kx, kv, xs, vs, a0, a1, xo, vo,
    a0_valid, has_stage,
):  # fmt: skip
    """Advance len(dts) steps of dts from times[0]; stop after the first non-finite step.

    ``times`` are the clock's step start times (the loop's clock, not a running sum).

    Returns (steps taken, force evaluations, steps a collision changed, Verlet's
    cache still valid, the last step was not finite).
    """
    evals = 0
    changed_steps = 0
    steps = dts.shape[0]
    for step in range(steps):
        t = times[step]
        dt = dts[step]
        if has_stage:  # the step's start, for the collision stage; without one, no copies
            _copy(xo, x)
            _copy(vo, v)
        if method == SYMPLECTIC_EULER:
            accelerations(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
            evals += 1
            _symplectic_euler(x, v, a0, dt)
        elif method == EULER_AVERAGE:
            accelerations(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
            evals += 1
            _euler_average(x, v, a0, dt)
        elif method == VERLET:
            if not a0_valid:
                accelerations(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
                evals += 1
            _verlet_drift(x, v, a0, vs, dt)
            accelerations(x, vs, t + dt, a1, kernels, fps, ips, mass, inv_mass, pinned)
            evals += 1
            _verlet_kick(v, a0, a1, dt)
            _copy(a0, a1)
            a0_valid = True
        else:  # RUNGE_KUTTA: the engine of runge_kutta.RungeKutta
            for j in range(tab_b.shape[0]):
                if j == 0:
                    _copy(kx[0], v)
                    accelerations(x, v, t, kv[0], kernels, fps, ips, mass, inv_mass, pinned)
                else:
                    _stage_state(xs, vs, x, v, kx, kv, tab_a, j, dt)
                    accelerations(xs, vs, t + tab_c[j] * dt, kv[j], kernels, fps, ips, mass, inv_mass, pinned)
                evals += 1
            _stage_sum(x, v, kx, kv, tab_b, dt)
        if has_stage and _stages_changed(xo, vo, x, v, dt, inv_mass, stage_fns, stage_fps, stage_ips):
            changed_steps += 1
            a0_valid = False  # the state changed behind the integrator's back
        if not _all_finite(x, v):
            return step + 1, evals, changed_steps, a0_valid, True
    return steps, evals, changed_steps, a0_valid, False


@njit(cache=True, error_model="numpy", _nrt=COUNTED)
def _energy_passes(x, v, t, mass, elastic, efps, eips, releasing, rfps, rips, u_refs, x_ref, no_u, books):
    """The watchdog's energy test (EnergyWatch.growth, Guard.check) at a finite state at time t:
    H = kinetic + the elastic elements' potentials, B = h0 + max(released, 0) + wind power *
    movable * t + born + floor, passing when H / B <= ``limit`` (NaN does not pass).

    books = [h0, floor, wind power per particle, movable particles, born energy, limit]: the
    watchdog's constants for a run without births, in the order EnergyWatch.budget adds them.
    """
    s = 0.0
    for i in range(x.shape[0]):
        s += mass[i] * ((v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]) + v[i, 2] * v[i, 2])
    h = 0.5 * s
    for k in range(len(elastic)):
        h += elastic[k](x, x_ref, no_u, mass, efps[k], eips[k])
    released = 0.0
    for k in range(len(releasing)):
        released += releasing[k](x, x_ref, u_refs[k], mass, rfps[k], rips[k])
    return _within_budget(h, released, t, books)


@njit(cache=True, error_model="numpy", _nrt=COUNTED)
def _within_budget(h, released, t, books):
    """H / B <= ``limit`` for the watched energy ``h`` and the energy ``released`` at time t,
    B = h0 + max(released, 0) + wind power * movable * t + born + floor, in the order
    EnergyWatch.budget adds them (``books``: see :func:`_energy_passes`)."""
    # max(released, 0.0) as Python's max decides it (NaN stays NaN)
    gained = 0.0 if released < 0.0 else released
    b = books[0] + gained + books[2] * books[3] * t + books[4] + books[1]
    return h / b <= books[5]


@njit(cache=True, error_model="numpy", _nrt=COUNTED)
def quick_check_state(
    x, v, t, mass, elastic, efps, eips, releasing, rfps, rips, u_refs, x_ref, no_u, books, count
):
    """The watchdog's check at a state, compiled: finite, and the energy test passing below
    the margin (:func:`_energy_passes`). ``count``: the movable particles (books[3]) are
    counted here, as EnergyWatch.budget counts them in a run with births (nonzero masses)."""
    if not _all_finite(x, v):
        return False
    if count:
        movable = 0
        for i in range(mass.shape[0]):
            if mass[i] != 0.0:
                movable += 1
        books[3] = movable
    return _energy_passes(
        x, v, t, mass, elastic, efps, eips, releasing, rfps, rips, u_refs, x_ref, no_u, books
    )


#: rows per piece of the quick check shared among threads (its sums are the pieces' sums
#: added in piece order, so the numbers do not depend on which thread ran which piece)
CHECK_PIECE = 16384


@njit(cache=True, parallel=True, error_model="numpy")
def quick_check_pieces(
    x,
    v,
    t,
    mass,
    elastic,
    efps,
    eips,
    releasing,
    rfps,
    rips,
    u_refs,
    x_ref,
    no_u,
    books,
    count,
    ok,
    movable,
    sums,
):
    """:func:`quick_check_state` on numba's threads, for scenes whose watched elements are all
    pointwise (their energy sums read only each row's own numbers, so a piece of rows is
    summed alone): every piece of CHECK_PIECE rows is tested for finiteness, counted and
    summed (kinetic energy, then each element's share) on some thread, and the pieces'
    sums are added in order. One pass over the state's rows from memory on both cores
    instead of four on one (finite, count, kinetic, released): this check is memory-bound.
    Its sums differ from the one-thread check's in their last bits; like it, it only
    passes states well inside the margin, and Python's check decides the others.
    ``ok``, ``movable``, ``sums``: room for each piece's flag, count and sums (the caller's,
    made once a run)."""
    n = x.shape[0]
    pieces = (n + CHECK_PIECE - 1) // CHECK_PIECE
    ne = len(elastic)
    nr = len(releasing)
    for p in prange(pieces):
        ok[p] = True
        lo = p * CHECK_PIECE
        hi = min(lo + CHECK_PIECE, n)
        xs = x[lo:hi]
        vs = v[lo:hi]
        ms = mass[lo:hi]
        if not _all_finite(xs, vs):
            ok[p] = False
            continue
        c = 0
        s = 0.0
        for i in range(hi - lo):
            c += ms[i] != 0.0
            s += ms[i] * ((vs[i, 0] * vs[i, 0] + vs[i, 1] * vs[i, 1]) + vs[i, 2] * vs[i, 2])
        movable[p] = c
        sums[p, 0] = s
        xr = x_ref[lo:hi]
        for k in range(ne):
            sums[p, 1 + k] = elastic[k](xs, xr, no_u, ms, efps[k], eips[k])
        for k in range(nr):
            sums[p, 1 + ne + k] = releasing[k](xs, xr, u_refs[k][lo:hi], ms, rfps[k], rips[k])
    for p in range(pieces):
        if not ok[p]:
            return False
    if count:
        c = 0
        for p in range(pieces):
            c += movable[p]
        books[3] = c
    s = 0.0
    for p in range(pieces):
        s += sums[p, 0]
    h = 0.5 * s
    for k in range(ne):
        for p in range(pieces):
            h += sums[p, 1 + k]
    released = 0.0
    for k in range(nr):
        for p in range(pieces):
            released += sums[p, 1 + ne + k]
    return _within_budget(h, released, t, books)


@njit(cache=True, _nrt=COUNTED)
def checked_chunk(
    x, v, times, dts,
    method, tab_c, tab_a, tab_b,
    kernels, fps, ips, mass, inv_mass, pinned,
    stage_fns, stage_fps, stage_ips,
    kx, kv, xs, vs, a0, a1, xo, vo,
    a0_valid, has_stage,
    k0, checked, stride, last,
    energy, elastic, efps, eips, releasing, rfps, rips, u_refs, x_ref, no_u, books,
    x_good, v_good,
    rec, shot_x, shot_v,
):  # fmt: skip
    """fused_chunk over len(dts) steps from clock position ``k0`` with the watchdog's checks
    inside: at every position ``checked`` + j ``stride`` and at ``last`` (the clock's end),
    as the loop would check, the energy test (``energy``: it is on) runs and a passing state
    is copied to ``x_good``, ``v_good``. The steps themselves are fused_chunk's calls.

    ``times`` are the clock's times at positions k0 .. k0 + len(dts) (one more than steps).
    At the positions ``rec`` (ascending, after k0) the state is copied to ``shot_x[r]``,
    ``shot_v[r]`` (the frames recorded there).

    Returns (steps taken, force evaluations, steps a collision changed, Verlet's cache still
    valid, the position of the last passed check (``checked`` if none), stopped, states
    copied to the shots), where stopped means the state is where a check did not pass or
    after a non-finite step.
    """
    steps = dts.shape[0]
    evals = 0
    changed = 0
    j = 0
    r = 0
    while j < steps:
        due = checked + stride
        e = min(steps, due - k0)
        if last - k0 < e:
            e = last - k0
        if r < rec.shape[0] and rec[r] - k0 < e:
            e = rec[r] - k0
        taken, ev, ch, a0_valid, bad = fused_chunk(
            x, v, times[j:], dts[j:e],
            method, tab_c, tab_a, tab_b,
            kernels, fps, ips, mass, inv_mass, pinned,
            stage_fns, stage_fps, stage_ips,
            kx, kv, xs, vs, a0, a1, xo, vo,
            a0_valid, has_stage,
        )  # fmt: skip
        evals += ev
        changed += ch
        j += taken
        if bad:
            return j, evals, changed, a0_valid, checked, True, r
        k = k0 + j
        if r < rec.shape[0] and k == rec[r]:
            _copy(shot_x[r], x)
            _copy(shot_v[r], v)
            r += 1
        if k == due or k == last:  # noqa: SIM109 - plain comparisons in compiled code
            if energy and not _energy_passes(
                x, v, times[j], mass, elastic, efps, eips, releasing, rfps, rips, u_refs, x_ref, no_u, books
            ):
                return j, evals, changed, a0_valid, checked, True, r
            _copy(x_good, x)
            _copy(v_good, v)
            checked = k
    return steps, evals, changed, a0_valid, checked, False, r


@njit(cache=True, _nrt=COUNTED)
def _acc_block(x, v, t, out, kernels, fps, ips, mass, inv_mass, pinned):
    """out = F(x, v, t) / m on rows of pointwise forces (``pinned``: those rows' flags), as accelerations."""
    out[:] = 0.0
    for k in range(len(kernels)):
        kernels[k](x, v, t, out, mass, fps[k], ips[k])
    for i in range(x.shape[0]):
        w = inv_mass[i]
        out[i, 0] *= w
        out[i, 1] *= w
        out[i, 2] *= w
        if pinned[i]:
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0


@njit(cache=True, inline="always", _nrt=COUNTED)
def _symplectic_euler_flat(x, v, a, xo, vo, dt, keep):
    """:func:`_symplectic_euler` on a block's rows as one flat run (the same operations).
    ``keep``: the step's start is kept in xo, vo for the stage, in the update's own pass
    (the kernels write only ``a``, so x and v are still the start here)."""
    m = x.shape[0]
    xf = x.reshape(3 * m)
    vf = v.reshape(3 * m)
    af = a.reshape(3 * m)
    if keep:
        xof = xo.reshape(3 * m)
        vof = vo.reshape(3 * m)
        for i in range(3 * m):
            xof[i] = xf[i]
            vof[i] = vf[i]
            vf[i] += af[i] * dt
            xf[i] += vf[i] * dt
    else:
        for i in range(3 * m):
            vf[i] += af[i] * dt
            xf[i] += vf[i] * dt


@njit(cache=True, _nrt=COUNTED)
def _block_steps(
    x, v, a0, t_all, dts, s0, s1, fresh,
    method, tab_c, tab_a, tab_b,
    kernels, fps, ips, mass, inv_mass, pinned,
    stage_fns, stage_fps, stage_ips, has_stage, changed,
    scratch, kx, kv,
):  # fmt: skip
    """Steps s0..s1-1 of one block of rows (x, v, a0, mass, ... are the block's slices).

    The arithmetic of each row is fused_chunk's, operation for operation. ``fresh``:
    Verlet evaluates its first acceleration (its cache is not valid). ``changed[step - s0]``
    says whether a stage changed one of the block's rows at that step. ``kx``, ``kv``: room
    for the Runge-Kutta stages' slopes of exactly the block's rows. Returns (steps run, the
    last was not finite).
    """
    m = x.shape[0]
    acc = scratch[0, :m]
    a1 = scratch[1, :m]
    xs = scratch[2, :m]
    vs = scratch[3, :m]
    xo = scratch[4, :m]
    vo = scratch[5, :m]
    stages = tab_b.shape[0]
    for step in range(s0, s1):
        t = t_all[step]
        dt = dts[step]
        if has_stage and method != SYMPLECTIC_EULER:
            _copy(xo, x)
            _copy(vo, v)
        if method == SYMPLECTIC_EULER:
            _acc_block(x, v, t, acc, kernels, fps, ips, mass, inv_mass, pinned)
            _symplectic_euler_flat(x, v, acc, xo, vo, dt, has_stage)
        elif method == EULER_AVERAGE:
            _acc_block(x, v, t, acc, kernels, fps, ips, mass, inv_mass, pinned)
            _euler_average(x, v, acc, dt)
        elif method == VERLET:
            if fresh and step == s0:
                _acc_block(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
            _verlet_drift(x, v, a0, vs, dt)
            _acc_block(x, vs, t + dt, a1, kernels, fps, ips, mass, inv_mass, pinned)
            _verlet_kick(v, a0, a1, dt)
            _copy(a0, a1)
        else:  # RUNGE_KUTTA
            for j in range(stages):
                if j == 0:
                    _copy(kx[0], v)
                    _acc_block(x, v, t, kv[0], kernels, fps, ips, mass, inv_mass, pinned)
                else:
                    _stage_state(xs, vs, x, v, kx, kv, tab_a, j, dt)
                    _acc_block(xs, vs, t + tab_c[j] * dt, kv[j], kernels, fps, ips, mass, inv_mass, pinned)
            _stage_sum(x, v, kx, kv, tab_b, dt)
        if has_stage:
            changed[step - s0] = _stages_changed(xo, vo, x, v, dt, inv_mass, stage_fns, stage_fps, stage_ips)
        if not _all_finite(x, v):
            return step + 1 - s0, True
    return s1 - s0, False


@njit(cache=True)
def _one_block(
    b, block,
    x, v, a0, x_save, v_save, a0_save, restore, save,
    times, dts, s0, s1, fresh,
    method, tab_c, tab_a, tab_b,
    kernels, fps, ips, mass, inv_mass, pinned,
    stage_fns, stage_fps, stage_ips, has_stage, changed,
):  # fmt: skip
    """Block ``b`` (rows b * block onward) through steps s0..s1-1, with work arrays of its
    own (so blocks may run on different threads at once). ``save``: keep its rows first, so
    it can be put back; ``restore``: put its kept rows back first. Returns _block_steps'."""
    lo = b * block
    hi = min(lo + block, x.shape[0])
    if restore:
        x[lo:hi] = x_save[lo:hi]
        v[lo:hi] = v_save[lo:hi]
        if method == VERLET:
            a0[lo:hi] = a0_save[lo:hi]
    elif save:
        x_save[lo:hi] = x[lo:hi]
        v_save[lo:hi] = v[lo:hi]
        if method == VERLET:
            a0_save[lo:hi] = a0[lo:hi]
    m = hi - lo
    stages = tab_b.shape[0]
    scratch = np.empty((6, m, 3))
    kx = np.empty((stages, m, 3))
    kv = np.empty((stages, m, 3))
    return _block_steps(
        x[lo:hi], v[lo:hi], a0[lo:hi], times, dts, s0, s1, fresh,
        method, tab_c, tab_a, tab_b,
        kernels, fps, ips, mass[lo:hi], inv_mass[lo:hi], pinned[lo:hi],
        stage_fns, stage_fps, stage_ips, has_stage, changed[b],
        scratch, kx, kv,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _first_failure(bad, ran, s0, s1):
    """(whether a block stopped at a step that was not finite, the step after the first such
    step, else s1): ``bad[b]``, ``ran[b]``: block b stopped so, after ``ran[b]`` steps from s0."""
    limit = s1
    failed = False
    for b in range(bad.shape[0]):
        if bad[b]:
            failed = True
            limit = min(limit, s0 + ran[b])
    return failed, limit


@njit(cache=True, inline="always")
def _span_counts(method, stages, s0, limit, changed, a0_valid):
    """fused_chunk's counts over steps s0..limit-1, step by step, which every block ran:
    (force evaluations, steps a stage changed, Verlet's cache still valid after them).
    ``changed[b, step - s0]``: a stage changed one of block b's rows at that step."""
    evals = 0
    changed_steps = 0
    for step in range(s0, limit):
        if method == VERLET:
            evals += 1 if a0_valid else 2
            a0_valid = True
        elif method == RUNGE_KUTTA:
            evals += stages
        else:
            evals += 1
        hit = False
        for b in range(changed.shape[0]):
            if changed[b, step - s0]:
                hit = True
                break
        if hit:
            changed_steps += 1
            a0_valid = False
    return evals, changed_steps, a0_valid


def _blocked_chunk(
    x, v, times, dts,
    method, tab_c, tab_a, tab_b,
    kernels, fps, ips, mass, inv_mass, pinned,
    stage_fns, stage_fps, stage_ips,
    a0, x_save, v_save, a0_save,
    a0_valid, has_stage, block,
):  # fmt: skip
    """fused_chunk for pointwise scenes (every force and stage reads only its own row), with
    the same results to the bit, the same counts and the same first non-finite step.

    Rows are independent, so each block of ``block`` rows runs all the call's steps while
    it sits in the cache: one pass over the arrays per call instead of several per step.
    The blocks do not depend on each other within a call, so ``blocked_chunk_parallel``
    runs them on several threads (``prange``; ``blocked_chunk`` is the same code on one):
    each block writes its own rows, its own work arrays and its own row of ``changed``.
    What couples the rows is settled after the blocks, in block order: a step counts as
    changed when a stage changed any block's row at it, and the chunk stops after the first
    step at which any row is not finite (the blocks that ran past it are put back and run
    again up to it, from their saved rows). Verlet re-evaluates every row's acceleration
    after a step a stage changed (a global decision), so with a stage it goes one step at
    a time over all blocks (on several threads, one parallel loop per step, not per call).
    numba gives each thread an equal run of consecutive blocks.

    Returns what fused_chunk returns.
    """
    n = x.shape[0]
    steps = dts.shape[0]
    stages = tab_b.shape[0]
    nblocks = (n + block - 1) // block
    span = 1 if (method == VERLET and has_stage) else steps
    save = span > 1  # a span of one step is never run past
    changed = np.zeros((nblocks, max(span, 1)), dtype=np.bool_)  # per block, per step of the span
    ran = np.zeros(nblocks, dtype=np.int64)
    bad = np.zeros(nblocks, dtype=np.bool_)
    evals = 0
    changed_steps = 0
    s0 = 0
    while s0 < steps:
        s1 = min(s0 + span, steps)
        fresh = not a0_valid
        for b in prange(nblocks):
            r, f = _one_block(
                b, block,
                x, v, a0, x_save, v_save, a0_save, False, save,
                times, dts, s0, s1, fresh,
                method, tab_c, tab_a, tab_b,
                kernels, fps, ips, mass, inv_mass, pinned,
                stage_fns, stage_fps, stage_ips, has_stage, changed,
            )  # fmt: skip
            ran[b] = r
            bad[b] = f
        failed, limit = _first_failure(bad, ran, s0, s1)
        if failed:  # the blocks that ran past it go back and run up to it
            for b in prange(nblocks):
                if s0 + ran[b] > limit:
                    _one_block(
                        b, block,
                        x, v, a0, x_save, v_save, a0_save, True, False,
                        times, dts, s0, limit, fresh,
                        method, tab_c, tab_a, tab_b,
                        kernels, fps, ips, mass, inv_mass, pinned,
                        stage_fns, stage_fps, stage_ips, has_stage, changed,
                    )  # fmt: skip
        ev, ch, a0_valid = _span_counts(method, stages, s0, limit, changed, a0_valid)
        evals += ev
        changed_steps += ch
        if failed:
            return limit, evals, changed_steps, a0_valid, True
        s0 = s1
    return steps, evals, changed_steps, a0_valid, False


def _twin(fn: Any, name: str) -> Any:
    """``fn`` under another name, so numba's disk cache keeps its own entry for each build."""
    twin = types.FunctionType(fn.__code__, fn.__globals__, name)
    twin.__qualname__ = name
    twin.__module__ = fn.__module__
    twin.__doc__ = fn.__doc__
    return twin


#: the blocks one after another on the calling thread (numba runs ``prange`` as ``range``)
blocked_chunk = njit(cache=True)(_twin(_blocked_chunk, "blocked_chunk"))
#: the blocks on numba's threads; compiled (or loaded) only for a scene with enough blocks
#: while numba has several threads, and only then does numba start its thread pool
blocked_chunk_parallel = njit(cache=True, parallel=True)(_twin(_blocked_chunk, "blocked_chunk_parallel"))
