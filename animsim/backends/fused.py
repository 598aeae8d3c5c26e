"""The numba backend's two ways to step: element kernels called from the loop, or fused chunks.

Every force element and collision stage carries its own numba kernel with one
uniform signature (:mod:`animsim.elements`). Here they are *called*, never
re-implemented:

* :class:`NumbaForces` replaces :meth:`Dynamics.acceleration` with one numba
  call that sums every element's kernel (first-class functions), divides by
  the mass and zeroes pinned rows, so any integrator (including implicit
  Euler, adaptive steps and scenes with emitters) runs on numba kernels
  through the one loop.
* :class:`FusedStepper` runs many steps per call for the fixed-step explicit
  methods: the integrator's arithmetic (the same operations, in the same
  order, as :mod:`animsim.integrators`), the element kernels and the
  collision stage, stopping after the first step that is not finite. When no
  particle acts on another, it steps them a cache-sized block at a time
  (``blocked_chunk``), and from PARALLEL_MIN_BLOCKS blocks on may share the blocks
  among numba's threads (``blocked_chunk_parallel``), with the same bits on any
  thread count; :class:`BuildChooser` times both and keeps the faster.

Imported only when numba is in use.
"""

from __future__ import annotations

import time
import types
import warnings
from collections.abc import Callable
from typing import Any

import numba
import numpy as np
from numba import njit, prange
from numba.core.errors import NumbaExperimentalFeatureWarning

from animsim import backends
from animsim.elements import element_signature, jit_kernel, live_array
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
from animsim.numba_cache import load_cached

warnings.filterwarnings("ignore", category=NumbaExperimentalFeatureWarning)

#: numba's reference counting off (``_nrt``) in the compiled step loops, which take every
#: array from their caller and allocate none: with it on, each call into an element kernel
#: (a first-class function) was wrapped in an atomic increment and decrement of each of
#: its six arrays' counts, which the compiler could not pair off across the call, about
#: 85 ns a call: most of a tiny scene's step (_acc on one particle 111 -> 23 ns)
COUNTED = False

#: largest (particles + springs) x steps one call may do, so Ctrl-C and the
#: progress bar are served about every few tenths of a second
MAX_WORK_PER_CALL = 20_000_000


def _no_force(x, v, t, out, mass, fp, ip):
    """Stands in when a scene has no force at all (numba needs a non-empty tuple)."""


def _no_stage(x_old, v_old, x, v, dt, inv_mass, fp, ip):
    return False


def _no_newborn(x_old, v_old, x, v, rest, fp, ip):
    """Stands in when newborns meet no collider (numba needs a non-empty tuple)."""
    return False


def _no_energy(x, x_ref, u_ref, mass, fp, ip):
    """Stands in when a scene has no elastic (or no releasing) element: adds 0.0, exactly."""
    return 0.0


@njit(cache=True, _nrt=COUNTED)
def _copy(dst, src):
    """dst[:] = src for (N, 3) arrays: an array assignment may need numba's reference
    counting (for a temporary when the two overlap), which the step loops run without."""
    for i in range(dst.shape[0]):
        for k in range(3):
            dst[i, k] = src[i, k]


@njit(cache=True, _nrt=COUNTED)
def _acc(x, v, t, out, kernels, fps, ips, mass, inv_mass, pinned):
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


@njit(cache=True, _nrt=COUNTED)
def fused_chunk(
    x,
    v,
    times,
    dts,
    method,
    tab_c,
    tab_a,
    tab_b,
    kernels,
    fps,
    ips,
    mass,
    inv_mass,
    pinned,
    stage_fns,
    stage_fps,
    stage_ips,
    kx,
    kv,
    xs,
    vs,
    a0,
    a1,
    xo,
    vo,
    a0_valid,
    has_stage,
):
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
            _acc(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
            evals += 1
            for i in range(x.shape[0]):
                for k in range(3):
                    v[i, k] += a0[i, k] * dt
                    x[i, k] += v[i, k] * dt
        elif method == EULER_AVERAGE:
            _acc(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
            evals += 1
            half = 0.5 * dt
            for i in range(x.shape[0]):
                for k in range(3):
                    e = a0[i, k] * dt + v[i, k]
                    x[i, k] += half * (v[i, k] + e)
                    v[i, k] = e
        elif method == VERLET:
            if not a0_valid:
                _acc(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
                evals += 1
            half = 0.5 * dt
            half2 = 0.5 * dt * dt
            for i in range(x.shape[0]):
                for k in range(3):
                    vs[i, k] = a0[i, k] * dt + v[i, k]
                    x[i, k] += dt * v[i, k] + half2 * a0[i, k]
            _acc(x, vs, t + dt, a1, kernels, fps, ips, mass, inv_mass, pinned)
            evals += 1
            for i in range(x.shape[0]):
                for k in range(3):
                    v[i, k] += half * (a0[i, k] + a1[i, k])
            _copy(a0, a1)
            a0_valid = True
        else:  # RUNGE_KUTTA: the engine of runge_kutta.RungeKutta
            stages = tab_b.shape[0]
            for j in range(stages):
                if j == 0:
                    _copy(kx[0], v)
                    _acc(x, v, t, kv[0], kernels, fps, ips, mass, inv_mass, pinned)
                else:
                    _copy(xs, x)
                    _copy(vs, v)
                    for m in range(j):
                        if tab_a[j, m] != 0.0:
                            _axpy(xs, dt * tab_a[j, m], kx[m])
                            _axpy(vs, dt * tab_a[j, m], kv[m])
                    _copy(kx[j], vs)
                    _acc(xs, vs, t + tab_c[j] * dt, kv[j], kernels, fps, ips, mass, inv_mass, pinned)
                evals += 1
            for j in range(stages):
                if tab_b[j] != 0.0:
                    _axpy(x, dt * tab_b[j], kx[j])
                    _axpy(v, dt * tab_b[j], kv[j])
        if has_stage:  # every fusable stage in the loop's order (colliders, then planes)
            changed = False
            for s in range(len(stage_fns)):
                if stage_fns[s](xo, vo, x, v, dt, inv_mass, stage_fps[s], stage_ips[s]):
                    changed = True
            if changed:
                changed_steps += 1
                a0_valid = False  # the state changed behind the integrator's back
        if not _all_finite(x, v):
            return step + 1, evals, changed_steps, a0_valid, True
    return steps, evals, changed_steps, a0_valid, False


#: a compiled check passes only below (1 - CHECK_MARGIN) times the watchdog's allowance; a
#: growth in the band up to the allowance stops the chunk and Python's check decides. The
#: compiled sums add in particle order where NumPy adds pairwise or through BLAS, so the two
#: growths differ by rounding (about 1e-15 relative, more only where released energies of
#: opposite signs cancel); the band makes both checks decide alike wherever they differ by
#: less than it, instead of only away from the threshold's knife edge.
CHECK_MARGIN = 1e-6


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
def _quick_check(
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
def _quick_check_pieces(
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
    """:func:`_quick_check` on numba's threads, for scenes whose watched elements are all
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
    x,
    v,
    times,
    dts,
    method,
    tab_c,
    tab_a,
    tab_b,
    kernels,
    fps,
    ips,
    mass,
    inv_mass,
    pinned,
    stage_fns,
    stage_fps,
    stage_ips,
    kx,
    kv,
    xs,
    vs,
    a0,
    a1,
    xo,
    vo,
    a0_valid,
    has_stage,
    k0,
    checked,
    stride,
    last,
    energy,
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
    x_good,
    v_good,
    rec,
    shot_x,
    shot_v,
):
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
            x,
            v,
            times[j:],
            dts[j:e],
            method,
            tab_c,
            tab_a,
            tab_b,
            kernels,
            fps,
            ips,
            mass,
            inv_mass,
            pinned,
            stage_fns,
            stage_fps,
            stage_ips,
            kx,
            kv,
            xs,
            vs,
            a0,
            a1,
            xo,
            vo,
            a0_valid,
            has_stage,
        )
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
    """out = F(x, v, t) / m on rows of pointwise forces (``pinned``: those rows' flags), as _acc."""
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


@njit(cache=True, _nrt=COUNTED)
def _block_steps(
    x,
    v,
    a0,
    t_all,
    dts,
    s0,
    s1,
    fresh,
    method,
    tab_c,
    tab_a,
    tab_b,
    kernels,
    fps,
    ips,
    mass,
    inv_mass,
    pinned,
    stage_fns,
    stage_fps,
    stage_ips,
    has_stage,
    changed,
    scratch,
    kx,
    kv,
):
    """Steps s0..s1-1 of one block of rows (x, v, a0, mass, ... are the block's slices).

    The arithmetic of each row is fused_chunk's, operation for operation. ``fresh``:
    Verlet evaluates its first acceleration (its cache is not valid). ``changed[step - s0]``
    says whether a stage changed one of the block's rows at that step. Returns (steps run,
    the last was not finite).
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
            xf = x.reshape(3 * m)
            vf = v.reshape(3 * m)
            af = acc.reshape(3 * m)
            if has_stage:
                # the step's start kept for the stage in the update's own pass (the kernels
                # write only acc, so x and v are still the start here)
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
        elif method == EULER_AVERAGE:
            _acc_block(x, v, t, acc, kernels, fps, ips, mass, inv_mass, pinned)
            half = 0.5 * dt
            for i in range(m):
                for k in range(3):
                    e = acc[i, k] * dt + v[i, k]
                    x[i, k] += half * (v[i, k] + e)
                    v[i, k] = e
        elif method == VERLET:
            if fresh and step == s0:
                _acc_block(x, v, t, a0, kernels, fps, ips, mass, inv_mass, pinned)
            half = 0.5 * dt
            half2 = 0.5 * dt * dt
            for i in range(m):
                for k in range(3):
                    vs[i, k] = a0[i, k] * dt + v[i, k]
                    x[i, k] += dt * v[i, k] + half2 * a0[i, k]
            _acc_block(x, vs, t + dt, a1, kernels, fps, ips, mass, inv_mass, pinned)
            for i in range(m):
                for k in range(3):
                    v[i, k] += half * (a0[i, k] + a1[i, k])
            _copy(a0, a1)
        else:  # RUNGE_KUTTA
            for j in range(stages):
                kxj = kx[j, :m]
                kvj = kv[j, :m]
                if j == 0:
                    _copy(kxj, v)
                    _acc_block(x, v, t, kvj, kernels, fps, ips, mass, inv_mass, pinned)
                else:
                    _copy(xs, x)
                    _copy(vs, v)
                    for q in range(j):
                        if tab_a[j, q] != 0.0:
                            _axpy(xs, dt * tab_a[j, q], kx[q, :m])
                            _axpy(vs, dt * tab_a[j, q], kv[q, :m])
                    _copy(kxj, vs)
                    _acc_block(xs, vs, t + tab_c[j] * dt, kvj, kernels, fps, ips, mass, inv_mass, pinned)
            for j in range(stages):
                if tab_b[j] != 0.0:
                    _axpy(x, dt * tab_b[j], kx[j, :m])
                    _axpy(v, dt * tab_b[j], kv[j, :m])
        if has_stage:
            hit = False
            for s in range(len(stage_fns)):
                if stage_fns[s](xo, vo, x, v, dt, inv_mass, stage_fps[s], stage_ips[s]):
                    hit = True
            changed[step - s0] = hit
        if not _all_finite(x, v):
            return step + 1 - s0, True
    return s1 - s0, False


@njit(cache=True)
def _one_block(
    b,
    block,
    x,
    v,
    a0,
    x_save,
    v_save,
    a0_save,
    restore,
    save,
    times,
    dts,
    s0,
    s1,
    fresh,
    method,
    tab_c,
    tab_a,
    tab_b,
    kernels,
    fps,
    ips,
    mass,
    inv_mass,
    pinned,
    stage_fns,
    stage_fps,
    stage_ips,
    has_stage,
    changed,
):
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
        x[lo:hi],
        v[lo:hi],
        a0[lo:hi],
        times,
        dts,
        s0,
        s1,
        fresh,
        method,
        tab_c,
        tab_a,
        tab_b,
        kernels,
        fps,
        ips,
        mass[lo:hi],
        inv_mass[lo:hi],
        pinned[lo:hi],
        stage_fns,
        stage_fps,
        stage_ips,
        has_stage,
        changed[b],
        scratch,
        kx,
        kv,
    )


def _blocked_chunk(
    x,
    v,
    times,
    dts,
    method,
    tab_c,
    tab_a,
    tab_b,
    kernels,
    fps,
    ips,
    mass,
    inv_mass,
    pinned,
    stage_fns,
    stage_fps,
    stage_ips,
    a0,
    x_save,
    v_save,
    a0_save,
    a0_valid,
    has_stage,
    block,
):
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
                b,
                block,
                x,
                v,
                a0,
                x_save,
                v_save,
                a0_save,
                False,
                save,
                times,
                dts,
                s0,
                s1,
                fresh,
                method,
                tab_c,
                tab_a,
                tab_b,
                kernels,
                fps,
                ips,
                mass,
                inv_mass,
                pinned,
                stage_fns,
                stage_fps,
                stage_ips,
                has_stage,
                changed,
            )
            ran[b] = r
            bad[b] = f
        limit = s1  # the step after the first one at which some row is not finite
        failed = False
        for b in range(nblocks):
            if bad[b]:
                failed = True
                limit = min(limit, s0 + ran[b])
        if failed:  # the blocks that ran past it go back and run up to it
            for b in prange(nblocks):
                if s0 + ran[b] > limit:
                    _one_block(
                        b,
                        block,
                        x,
                        v,
                        a0,
                        x_save,
                        v_save,
                        a0_save,
                        True,
                        False,
                        times,
                        dts,
                        s0,
                        limit,
                        fresh,
                        method,
                        tab_c,
                        tab_a,
                        tab_b,
                        kernels,
                        fps,
                        ips,
                        mass,
                        inv_mass,
                        pinned,
                        stage_fns,
                        stage_fps,
                        stage_ips,
                        has_stage,
                        changed,
                    )
        for step in range(s0, limit):  # fused_chunk's counts, step by step
            if method == VERLET:
                evals += 1 if a0_valid else 2
                a0_valid = True
            elif method == RUNGE_KUTTA:
                evals += stages
            else:
                evals += 1
            hit = False
            for b in range(nblocks):  # every block ran this step (limit is the earliest end)
                if changed[b, step - s0]:
                    hit = True
                    break
            if hit:
                changed_steps += 1
                a0_valid = False
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


class _Address(numba.types.WrapperAddressProtocol):
    """A compiled kernel handed to a numba function as a first-class function by its address.

    Passing the dispatcher itself makes numba look its compiled version up on
    every call (about 200 us per kernel per call, measured): a tiny scene's
    frame, or an emitter scene's step, paid that for each element. The address
    is read once; the type (a FunctionType of the uniform signature) is the
    same, so the compiled callers and their disk cache serve both.
    """

    def __init__(self, dispatcher: Any, sig: Any):
        cres = dispatcher.get_compile_result(sig)
        self._address = cres.library.get_pointer_to_function(cres.fndesc.llvm_cfunc_wrapper_name)
        self._signature = sig
        self.dispatcher = dispatcher  # keeps the compiled code alive

    def __wrapper_address__(self) -> int:
        return self._address

    def signature(self) -> Any:
        return self._signature


def _addresses(
    dispatchers: Any, stage: bool = False, energy: bool = False, newborn: bool = False
) -> tuple[Any, ...]:
    sig = element_signature(stage=stage, energy=energy, newborn=newborn)
    return tuple(_Address(d, sig) for d in dispatchers)


class FastCall:
    """Call a numba function's compiled overload directly, skipping the dispatcher's typing
    of every argument on every call (the fused chunk takes 26; with first-class function
    tuples that cost about 150 us a call, measured). Used only for argument types already
    seen by the dispatcher, and only while the arrays whose layout could differ (the
    state's) are C-contiguous float64, as the overload expects; else the dispatcher."""

    def __init__(self, dispatcher: Any, args: tuple[Any, ...]):
        self.dispatcher = dispatcher
        self.entry = None
        self.types: tuple[Any, ...] | None = None
        try:
            self.types = tuple(dispatcher.typeof_pyval(a) for a in args)
        except Exception:  # any typing trouble: keep the dispatcher
            return
        # a disk-cache hit loads here, without numba's start-up of its compiler (numba_cache)
        load_cached(dispatcher, self.types)
        self._find()

    def _find(self) -> None:
        cres = self.dispatcher.overloads.get(self.types)
        if cres is not None:
            self.entry = cres.entry_point

    def __call__(self, *args: Any) -> Any:
        entry = self.entry
        if entry is not None and _plain(args[0]) and _plain(args[1]):
            return entry(*args)
        result = self.dispatcher(*args)  # compiles on a cache miss
        if entry is None and self.types is not None:
            self._find()
        return result


def _plain(a: np.ndarray) -> bool:
    return a.dtype == np.float64 and a.ndim == 2 and a.flags.c_contiguous


def _array_tuple(arrays: list[np.ndarray], dtype: Any) -> tuple[np.ndarray, ...]:
    """The elements' parameter arrays as a tuple, which numba types as a homogeneous tuple.

    A tuple and not a ``numba.typed.List``: a typed list's methods are compiled in every
    new process (its ``append`` is never cached on disk), which cost about 0.7 s of each
    numba run's start (measured with cProfile on a one-particle scene). The callers are
    specialised on the number of kernels anyway (their tuple of functions), so the tuple
    adds no compilation.
    """
    return tuple(np.ascontiguousarray(a, dtype=dtype) for a in arrays)


def _element_tables(terms: Any) -> tuple[tuple[Any, ...], Any, Any]:
    kernels = [t.numba_kernel for t in terms if t.numba_source is not None]
    params = [t.numba_params() for t in terms if t.numba_source is not None]
    if not kernels:
        kernels = [jit_kernel(_no_force)]
        params = [(np.zeros(0), np.zeros(0, dtype=np.int64))]
    fps = _array_tuple([p[0] for p in params], np.float64)
    ips = _array_tuple([p[1] for p in params], np.int64)
    return _addresses(kernels), fps, ips


class NumbaForces:
    """Dynamics.acceleration through the elements' numba kernels (see the module docstring).

    Elements without a numba kernel keep their NumPy kernel, added after.
    """

    def __init__(self, dynamics: Any):
        self.dynamics = dynamics
        self.kernels, self.fps, self.ips = _element_tables(dynamics.terms)
        self.others = tuple(t for t in dynamics.terms if t.numba_source is None)
        self.pinned = np.ascontiguousarray(np.flatnonzero(dynamics.system.particle_pinned), dtype=np.int64)
        self._copies: dict[int, np.ndarray] = {}
        self._acc: Any = None
        self._pointwise = all(t.pointwise for t in dynamics.terms)

    def acceleration(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        d = self.dynamics
        d.evaluations += 1
        for drive in d.drivers:  # keyframed rows on their path (animsim.keyframes)
            drive.drive(t, x, v)
        mass = live_array(d.mass, self._copies)
        if not self.others:
            inv_mass = live_array(d.inv_mass, self._copies)
            args = (x, v, float(t), out, self.kernels, self.fps, self.ips, mass, inv_mass, self.pinned)
            if self._acc is None:  # loads (or compiles) the kernel; then calls its overload directly
                self._acc = FastCall(_acc, args)
            self._acc(*args)
            return out
        # Mixed: sum every force first (numba kernels, then NumPy ones), then divide.
        out.fill(0.0)
        for kern, fp, ip in zip(self.kernels, self.fps, self.ips, strict=True):
            kern.dispatcher(x, v, float(t), out, mass, fp, ip)
        for term in self.others:
            term.accumulate(x, v, t, out)
        for j in range(3):
            out[:, j] *= d.inv_mass
        if len(self.pinned):
            out[self.pinned] = 0.0
        return out

    def newborn_tables(self, colliders: list[Any]) -> tuple[Any, ...] | None:
        """What the compiled birth step (:func:`animsim.emitters.kernels._pool_step`) flies and
        collides an emitter's newborns with: (the force kernels, their float and integer
        parameters, the ``colliders``' newborn kernels, theirs). None unless the newborns'
        rows can be evaluated alone (every force pointwise, none left to NumPy, no row
        driven) and every collider has a newborn kernel; births then take the Python path,
        which evaluates every row."""
        d = self.dynamics
        if self.others or d.drivers or not self._pointwise:
            return None
        if any(st.numba_newborn_source is None for st in colliders):
            return None
        kernels = [st.numba_newborn for st in colliders] or [jit_kernel(_no_newborn, newborn=True)]
        params = [st.numba_stage_params() for st in colliders] or [(np.zeros(0), np.zeros(0, dtype=np.int64))]
        return (
            self.kernels,
            self.fps,
            self.ips,
            _addresses(kernels, newborn=True),
            _array_tuple([p[0] for p in params], np.float64),
            _array_tuple([p[1] for p in params], np.int64),
        )

    def masses(self) -> tuple[np.ndarray, np.ndarray]:
        """The live masses and inverse masses as the kernels take them."""
        d = self.dynamics
        return live_array(d.mass, self._copies), live_array(d.inv_mass, self._copies)


#: calls timed on each blocked build before the faster one is kept
TRIAL_CALLS = 3
#: calls between two trials of the build not kept, so a change of the machine's load is followed
RETRY_EVERY = 64
#: and at least this much time (s) on the kept build between two trials: a trial of one
#: thread where two are kept costs about a call more, so short calls would pay for it often
#: (the 100,000-slot fountain, a step a call, spent 1.8 % of its run on them every 64 calls)
RETRY_SECONDS = 0.25
#: after the trials, the other build is kept only when it is this much faster (its median
#: time per step over its last TRIAL_CALLS calls against the kept build's): on idle cores
#: two threads run about 1.4-2x faster, on busy ones one thread 4-8x, while single calls
#: of a run on a shared machine scatter by tens of percent
SWITCH_MARGIN = 1.25


def _median(values: list[float]) -> float:
    """The median of a few floats, as statistics.median gives it."""
    s = sorted(values)
    h = len(s) // 2
    return s[h] if len(s) % 2 else 0.5 * (s[h - 1] + s[h])


class BuildChooser:
    """Which blocked build (one thread or numba's threads) runs the next call: the faster.

    A parallel call waits for its slowest thread. On idle cores two threads halve a
    call's time; on cores busy with other work the wait for a descheduled thread can
    cost milliseconds a call: the 4,500-particle fountain (one step per call) ran in
    0.25 s on one thread and 1.9 s on two while another job kept both cores busy. Both
    builds give the same bits, so the stepper times them (wall clock, what the user
    waits for): the first calls alternate until each build has TRIAL_CALLS timings, the
    build with the lower time per step (the median of its last TRIAL_CALLS calls) is
    kept, and once RETRY_EVERY calls and RETRY_SECONDS have passed on the kept build, one
    call tries the other build again, which is then kept only if that call was
    SWITCH_MARGIN times faster (a wrong switch on one lucky call is undone once the new
    build's median over its next calls shows it).
    """

    def __init__(self) -> None:
        self.recent: dict[bool, list[float]] = {True: [], False: []}
        self.calls = 0
        #: the build kept (True: numba's threads)
        self.parallel = True
        #: calls and seconds on the kept build since the last trial of the other
        self.kept_calls = 0
        self.kept_seconds = 0.0

    def pick(self) -> bool:
        """True when the next call should run on numba's threads."""
        if self.calls < 2 * TRIAL_CALLS:  # the trials alternate, threads first
            return len(self.recent[True]) <= len(self.recent[False])
        if self.kept_calls >= RETRY_EVERY and self.kept_seconds >= RETRY_SECONDS:
            return not self.parallel
        return self.parallel

    def record(self, parallel: bool, seconds: float, steps: int) -> None:
        """Book a call of ``steps`` steps that took ``seconds`` on that build."""
        if steps <= 0:
            return
        self.calls += 1
        times = self.recent[parallel]
        trials = self.calls <= 2 * TRIAL_CALLS
        if parallel == self.parallel:
            self.kept_calls += 1
            self.kept_seconds += seconds
        else:
            self.kept_calls, self.kept_seconds = 0, 0.0
        if not trials and parallel != self.parallel:
            times.clear()  # a retry of the other build: its old timings are of another load
        times.append(seconds / steps)
        del times[:-TRIAL_CALLS]
        if min(len(self.recent[True]), len(self.recent[False])) >= (TRIAL_CALLS if trials else 1):
            # not NumPy: np.median on three floats took about 37 us, twice a call, which was a
            # twelfth of a fountain step on two threads (statistics.median: about 1.5 us)
            on, off = _median(self.recent[True]), _median(self.recent[False])
            if trials:  # the faster
                self.parallel = on < off
            elif self.parallel:  # a change needs a clear margin (timings of calls scatter)
                self.parallel = not off * SWITCH_MARGIN < on
            else:
                self.parallel = on * SWITCH_MARGIN < off


def check_room(pieces: int, tables: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Room for :func:`_quick_check_pieces`: each piece's flag, movable count and sums (the
    kinetic energy, then a column per energy kernel the check calls). ``tables``: the
    elastic then the releasing :func:`_energy_table`. The columns are counted from the
    tables, not from the element lists: a table holds a kernel that adds nothing where its
    list is empty, and the check writes that kernel's column too."""
    return (
        np.ones(pieces, dtype=np.bool_),
        np.zeros(pieces, dtype=np.int64),
        np.zeros((pieces, 1 + len(tables[0]) + len(tables[3]))),
    )


def _energy_table(terms: list[Any]) -> tuple[Any, ...]:
    """(kernels, float parameters, integer parameters) of the elements' compiled energy sums,
    as the compiled checks take them (a kernel that adds nothing when there is none)."""
    kernels = [t.numba_energy_kernel for t in terms] or [jit_kernel(_no_energy, energy=True)]
    params = [t.numba_energy_params() for t in terms] or [(np.zeros(0), np.zeros(0, dtype=np.int64))]
    return (
        _addresses(kernels, energy=True),
        _array_tuple([p[0] for p in params], np.float64),
        _array_tuple([p[1] for p in params], np.int64),
    )


class FusedStepper:
    """Many fixed steps per numba call (see the module docstring)."""

    def __init__(self, compiled: Any):
        self.compiled = compiled
        integ = compiled.integrator
        n = compiled.system.particle_count
        self.method, tableau = integ.numba_chunk_kind()
        if tableau is None:
            c, a, b = np.zeros(1), np.zeros((1, 1)), np.zeros(1)
        else:
            s = len(tableau.b)
            c = np.array(tableau.c, dtype=np.float64)
            a = np.zeros((s, s))
            for i, row in enumerate(tableau.a):
                a[i, : len(row)] = row
            b = np.array(tableau.b, dtype=np.float64)
        self.tab = (c, a, b)
        stages = b.shape[0]
        self.kernels, self.fps, self.ips = _element_tables(compiled.dynamics.terms)
        fusable = [st for st in compiled.post_step if st.numba_stage_source is not None]
        if fusable:
            self.stages = _addresses([st.numba_stage for st in fusable], stage=True)
            self.stage_owner = fusable[0]
            params = [st.numba_stage_params() for st in fusable]
        else:
            self.stages = _addresses([jit_kernel(_no_stage, stage=True)], stage=True)
            self.stage_owner = None
            params = [(np.zeros(0), np.zeros(0, dtype=np.int64))]
        self.stage_fps = _array_tuple([p[0] for p in params], np.float64)
        self.stage_ips = _array_tuple([p[1] for p in params], np.int64)
        #: rows are independent (animsim.backends.fused_in_blocks): blocked_chunk steps them
        self.blocked = backends.fused_in_blocks(compiled)
        pinned = compiled.system.particle_pinned
        #: the pinned rows' indices, as the plain chunk (and the checked one) takes them
        self.plain_pinned = np.ascontiguousarray(np.flatnonzero(pinned), dtype=np.int64)
        self._checks: Any = None
        if self.blocked:
            # per-row pinned flags for the blocks; Verlet's cached acceleration, and room to
            # save each block's rows (position, velocity, that acceleration) at a call's start
            self.pinned = np.ascontiguousarray(pinned, dtype=np.bool_)
            self.kx = self.kv = np.zeros((stages, 0, 3))
            self.work = tuple(np.zeros((n, 3)) for _ in range(4))  # a0, x, v and a0 saved
        else:
            self.pinned = self.plain_pinned
            self.kx = np.zeros((stages, n, 3))
            self.kv = np.zeros((stages, n, 3))
            self.work = tuple(np.zeros((n, 3)) for _ in range(6))  # xs, vs, a0, a1, xo, vo
        #: enough blocks to share among numba's threads (when it has several): the blocked
        #: chunk's calls then run them in parallel (blocked_chunk_parallel)
        self.parallel_blocks = self.blocked and -(-n // backends.BLOCK) >= backends.PARALLEL_MIN_BLOCKS
        #: which of the two builds runs a call, by timing them (BuildChooser)
        self.chooser = BuildChooser()
        self.a0_valid = False
        work = n + compiled.system.spring_count
        self.max_steps_per_call = max(1, MAX_WORK_PER_CALL // max(work, 1))
        self.compile_seconds = 0.0
        self._copies: dict[int, np.ndarray] = {}
        #: the chunk kernels this stepper has called, each called directly from then on
        self._chunks: dict[Any, FastCall] = {}
        #: steps a collision changed, over every call so far
        self.changed_steps = 0

    def reset(self) -> None:
        self.a0_valid = False

    def warm_up(self, state: Any) -> float:
        """Compile (or load from the disk cache) every kernel with a zero-step call; its seconds."""
        t0 = time.perf_counter()
        no_steps = (state, np.array([state.time]), np.zeros(0))
        self._advance(*no_steps, False)
        if self.threaded():  # both blocked builds: the run times them and may switch
            self._advance(*no_steps, True)
        self.compile_seconds = time.perf_counter() - t0
        return self.compile_seconds

    def threaded(self) -> bool:
        """Whether the blocked chunk may share its blocks among threads for this call."""
        # numba's thread count is asked only for scenes big enough to use it: asking
        # starts numba's thread pool, which a small scene's run should not wait for
        return self.parallel_blocks and numba.get_num_threads() > 1

    def _common(self, state: Any, times: np.ndarray, dts: np.ndarray, pinned: np.ndarray) -> tuple[Any, ...]:
        """The arguments every chunk kernel starts with (state, clock, method, elements, stages)."""
        d = self.compiled.dynamics
        c, a, b = self.tab
        return (
            state.particle_position,
            state.particle_velocity,
            times,
            dts,
            self.method,
            c,
            a,
            b,
            self.kernels,
            self.fps,
            self.ips,
            live_array(d.mass, self._copies),
            live_array(d.inv_mass, self._copies),
            pinned,
            # a tuple of addresses, so numba types them as first-class functions (by
            # signature), not as these dispatchers: the cached kernel then serves every stage
            self.stages,
            self.stage_fps,
            self.stage_ips,
        )

    def advance(
        self, state: Any, times: np.ndarray, dts: np.ndarray, threaded: bool | None = None
    ) -> tuple[int, int, bool]:
        """len(dts) steps from times[0]; (steps taken, force evaluations, failed).
        ``threaded``: what :meth:`threaded` answers, when the caller asked it already (a
        caller making many one-step calls asks once: each ask takes about 8 us right after
        a large call)."""
        if threaded is None:
            threaded = self.threaded()
        return self._advance(state, times, dts, threaded and self.chooser.pick(), threaded)

    def _advance(
        self, state: Any, times: np.ndarray, dts: np.ndarray, threaded: bool, timed: bool | None = None
    ) -> tuple[int, int, bool]:
        """advance, on numba's threads when ``threaded`` (blocked scenes only); ``timed``: the
        chooser books the call (None: ask, as :meth:`threaded` does; asking numba for its thread
        count takes about 8 us after a large call, so advance asks once)."""
        common = self._common(state, times, dts, self.pinned)
        has_stage = self.stage_owner is not None
        if self.blocked:  # work: a0 and the rows saved at the call's start (x, v, a0)
            kernel = blocked_chunk_parallel if threaded else blocked_chunk
            args = (*common, *self.work, self.a0_valid, has_stage, backends.BLOCK)
        else:  # work: xs, vs, a0, a1, xo, vo
            kernel = fused_chunk
            args = (*common, self.kx, self.kv, *self.work, self.a0_valid, has_stage)
        call = self._chunks.get(kernel)
        if call is None:  # loads (or compiles) the chunk; then calls its overload directly
            call = self._chunks[kernel] = FastCall(kernel, args)
        t0 = time.perf_counter()
        result = call(*args)
        taken, evals, changed, self.a0_valid, failed = result
        if timed is None:
            timed = self.threaded()
        if timed:
            self.chooser.record(kernel is blocked_chunk_parallel, time.perf_counter() - t0, int(taken))
        self.changed_steps += int(changed)
        if changed:
            state.revision += 1
        return int(taken), int(evals), bool(failed)

    def check_inside(self, watch: Any) -> bool:
        """Take the watchdog's checks into the chunks (:meth:`advance_checked`) for the books of
        ``watch`` (an opened :class:`animsim.measures.watchdog.EnergyWatch`), when every
        element its energy test sums has a compiled energy kernel; False leaves them to Python.

        Only for a run without births (the books never change after they opened) and
        without rigid bodies (the fused stepper has none).
        """
        self._checks = None
        if watch.alive_prev is not None:
            return False
        energy = watch.disabled is None
        elastic: list[Any] = watch.elastic if energy else []
        releasing: list[Any] = watch.releasing if energy else []
        if any(t.numba_energy_source is None for t in (*elastic, *releasing)):
            return False
        no_u = np.zeros(0)
        u_refs = _array_tuple(list(watch.u_ref) if releasing else [no_u], np.float64)
        books = np.array([*watch.budget_constants(), watch.allowance * (1.0 - CHECK_MARGIN)])
        n = self.compiled.system.particle_count
        stages = self.kx.shape[0]
        if self.blocked:  # the blocked chunk's Verlet acceleration is shared, so either may go on
            a0 = self.work[0]
            work = (np.zeros((n, 3)), np.zeros((n, 3)), a0, *(np.zeros((n, 3)) for _ in range(3)))
            kx, kv = np.zeros((stages, n, 3)), np.zeros((stages, n, 3))
        else:
            work, kx, kv = self.work, self.kx, self.kv
        self._checks = (
            (kx, kv, *work),
            (
                energy,
                *_energy_table(elastic),
                *_energy_table(releasing),
                u_refs,
                np.ascontiguousarray(watch.x_ref),
                no_u,
                books,
            ),
            (np.zeros((n, 3)), np.zeros((n, 3))),
        )
        self._checked_call: Any = None
        return True

    def quick_check(self, watch: Any) -> Callable[[Any], bool] | None:
        """The watchdog's check of a state compiled, for runs whose checks stay in Python
        (births, or more particles than the chunks check themselves): a function of the
        state that is True only where ``Guard.check`` passes it, finite and below
        (1 - CHECK_MARGIN) times the allowance, so the loop may skip Python's check; where
        it is False, Python's check decides. None when the energy test is off or an element
        the watchdog sums has no compiled energy sum.

        Python's check sums the kinetic energy with NumPy (an ``einsum`` and a dot product
        over every particle) and tests finiteness with two more sums: 0.96 ms of a
        100,000-slot fountain's check, against one compiled pass.
        """
        if watch.disabled is not None:
            return None
        elastic, releasing = watch.elastic, watch.releasing
        if any(t.numba_energy_source is None for t in (*elastic, *releasing)):
            return None
        tables = (*_energy_table(elastic), *_energy_table(releasing))
        no_u = np.zeros(0)
        births = watch.alive_prev is not None
        books = np.zeros(6)
        call: dict[Any, FastCall] = {}
        copies: dict[int, np.ndarray] = {}
        # several pieces of rows, every watched element pointwise: the check may share them
        # among numba's threads, when the stepper's own calls do (its chooser keeps them)
        n = self.compiled.system.particle_count
        pieces = self.blocked and n >= 2 * CHECK_PIECE and all(t.pointwise for t in (*elastic, *releasing))
        npieces = -(-n // CHECK_PIECE)
        room = check_room(npieces, tables)

        def quick(state: Any) -> bool:
            watch.book_births(state)  # as EnergyWatch.budget does first (a no-op when booked)
            books[:5] = watch.budget_constants()
            books[5] = watch.allowance * (1.0 - CHECK_MARGIN)
            args = (
                state.particle_position,
                state.particle_velocity,
                float(state.time),
                live_array(watch.mass, copies),
                *tables,
                _array_tuple(list(watch.u_ref) if releasing else [no_u], np.float64),
                watch.x_ref,
                no_u,
                books,
                births,
            )
            kernel = _quick_check
            if pieces and self.threaded() and self.chooser.parallel:
                kernel = _quick_check_pieces
                args = (*args, *room)
            fast = call.get(kernel)
            if fast is None:  # loads (or compiles) the check; then calls its overload directly
                fast = call[kernel] = FastCall(kernel, args)
            return bool(fast(*args))

        return quick

    def advance_checked(
        self,
        state: Any,
        k0: int,
        times: np.ndarray,
        dts: np.ndarray,
        checked: int,
        stride: int,
        last: int,
        rec: np.ndarray,
        shots: tuple[np.ndarray, np.ndarray],
    ) -> tuple[int, int, int, bool, int]:
        """len(dts) steps from clock position k0 with the watchdog's checks inside
        (:func:`checked_chunk`; ``times`` has one more entry than ``dts``), copying the
        states at the positions ``rec`` into ``shots``; (steps taken, force evaluations,
        the position of the last passed check, stopped, states copied)."""
        work, books, good = self._checks
        args = (
            *self._common(state, times, dts, self.plain_pinned),
            *work,
            self.a0_valid,
            self.stage_owner is not None,
            k0,
            checked,
            stride,
            last,
            *books,
            *good,
            rec,
            *shots,
        )
        if self._checked_call is None:  # loads (or compiles) the chunk; then calls its overload
            self._checked_call = FastCall(checked_chunk, args)
        result = self._checked_call(*args)
        taken, evals, changed, self.a0_valid, passed, stopped, copied = result
        self.changed_steps += int(changed)
        if changed:
            state.revision += 1
        return int(taken), int(evals), int(passed), bool(stopped), int(copied)

    def good_state(self, dest: Any) -> None:
        """Copy the positions and velocities of the last passed check into ``dest``."""
        x_good, v_good = self._checks[2]
        dest.particle_position[...] = x_good
        dest.particle_velocity[...] = v_good


__all__ = ["FusedStepper", "NumbaForces", "numba"]
