"""The numba kernels of particle contacts: the impact pass (:func:`bounce_pair`, written once and
run by NumPy too), the grid search of the Verlet list and one step's contact passes.

The kernels and every helper they call live in this one module: numba's disk cache checks
only the file of the function it cached, so a helper in another file could go stale in the
cache after an edit. ``contact_step`` runs the step's passes, one helper each; they share the
per-pair buffers ``pair_setup`` fills once.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from animsim.elements import compile_helpers, numba_helper, numba_inline_helper


@numba_inline_helper
def normal_speed(v, i, j, n0, n1, n2):  # pragma: no cover - compiled too
    """How fast sphere j moves away from sphere i along the unit normal n (negative: closing)."""
    return (v[j, 0] - v[i, 0]) * n0 + (v[j, 1] - v[i, 1]) * n1 + (v[j, 2] - v[i, 2]) * n2


@numba_helper
def bounce_pair(i, j, n0, n1, n2, w, limit, e, v, inv_mass):  # pragma: no cover - compiled too
    """One impact between two spheres, in place on ``v``; returns the normal impulse (0.0: none).

    Newton's law of restitution for a two-body impact along the line of centres
    ``n`` (Goldstein, "Classical Mechanics", section 3.11): ``J = -(1 + e) v_n / w``
    with ``w = 1/m_i + 1/m_j``, ``+J n`` on j and ``-J n`` on i. Only an approach
    faster than ``limit`` is an impact (its bounce, e times it, would be faster than twice
    what the step's forces added to a sphere touching either); a slower one is resting contact, left
    to the Jacobi passes (a grain settling into a pile does not bounce by a hair).
    """
    vn = normal_speed(v, i, j, n0, n1, n2)
    if not -vn > limit:
        return 0.0
    jn = -(1.0 + e) * vn / w
    ci = inv_mass[i] * jn
    cj = inv_mass[j] * jn
    v[i, 0] -= ci * n0
    v[i, 1] -= ci * n1
    v[i, 2] -= ci * n2
    v[j, 0] += cj * n0
    v[j, 1] += cj * n1
    v[j, 2] += cj * n2
    return jn


@numba_helper
def approaching(pi, pj, nrm, limit, v, due, p):  # pragma: no cover - compiled
    """due[k]: pair k approaches faster than its limit now; returns how many do."""
    count = 0
    for k in range(p):
        i = pi[k]
        j = pj[k]
        due[k] = -normal_speed(v, i, j, nrm[k, 0], nrm[k, 1], nrm[k, 2]) > limit[k]
        if due[k]:
            count += 1
    return count


@numba_helper
def bounce_sweeps(pi, pj, nrm, w, limit, e, v, inv_mass, jb, due, p, sweeps):  # pragma: no cover - compiled
    """The impact pass; ``jb[k]``: pair k's impulses. Each sweep marks the pairs that approach
    faster than resting, then strikes them one after the other in pair order
    (:func:`bounce_pair`, which looks again: an earlier impact may have parted the pair),
    until no pair approaches (at most ``sweeps``).

    Sequential, not simultaneous: an impact is passed on through touching spheres one pair
    per sweep, as in the collision pass of Guendelman, Bridson and Fedkiw, "Nonconvex rigid
    bodies with stacking", SIGGRAPH 2003 (section 6). So a ball hitting a row of touching
    equal balls stops and the last one leaves with its speed (Newton's cradle); a
    simultaneous (Jacobi) solution shares the impulse and loses energy even at e = 1.
    Marking first and striking only the marked is what lets NumPy run the same pass as
    cheaply (:func:`bounce_sweeps_numpy`): its Python loop sees the impacts, not every pair.
    """
    for k in range(p):
        jb[k] = 0.0
    for _ in range(sweeps):
        if approaching(pi, pj, nrm, limit, v, due, p) == 0:
            return
        for k in range(p):
            if due[k]:
                jb[k] += bounce_pair(
                    pi[k], pj[k], nrm[k, 0], nrm[k, 1], nrm[k, 2], w[k], limit[k], e, v, inv_mass
                )


class NumbaKernels(NamedTuple):
    """The numba twins of this module's NumPy code."""

    #: (x, active, exclude, reach) -> (ci, cj): the Verlet list's candidates, sorted by (i, j)
    candidates: Any
    #: one step's contacts from the candidates (see ``contact_step``)
    step: Any
    #: (x, radius, active, exclude, cell) -> (P, 2) overlapping pairs, as :func:`find_pairs_numpy`
    find_pairs: Any
    #: (x, x_built, active) -> how far the displacements spread since the list was built
    spread: Any


_KERNELS: NumbaKernels | None = None


# Helpers the kernels below call. They live at module level, not inside numba_kernels():
# numba keys a closure's disk-cache entry on its captured values, and a captured
# dispatcher pickles differently in every process, so a kernel calling a nested kernel
# missed the cache and compiled again on every run (seconds for every contact scene).
@numba_helper
def cell_hash(cx, cy, cz, size):  # pragma: no cover - compiled
    # Teschner et al. 2003: XOR of the cell coordinates times three large primes.
    # size is a power of two: the mask is the modulo, for negative h too
    return ((cx * 73856093) ^ (cy * 19349663) ^ (cz * 83492791)) & (size - 1)


@numba_helper
def excluded(keys, key):  # pragma: no cover - compiled
    lo, hi = 0, keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo < keys.shape[0] and keys[lo] == key


@numba_helper
def active_box(x, active):  # pragma: no cover - compiled
    """The box of the active rows (lo, hi), how many they are, and whether every coordinate
    of theirs is finite (a dense grid needs that)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    m = 0
    dense = True
    for i in range(x.shape[0]):
        if active[i]:
            m += 1
            for a in range(3):
                if not np.isfinite(x[i, a]):
                    dense = False
                lo[a] = min(lo[a], x[i, a])
                hi[a] = max(hi[a], x[i, a])
    return lo, hi, m, dense


@numba_helper
def grid_shape(lo, hi, inv, m, dense):  # pragma: no cover - compiled
    """The dense grid's cells per axis, and whether to use it: every span finite and not
    many more cells than the ``m`` rows."""
    dims = np.ones(3, dtype=np.int64)
    total = 1.0
    for a in range(3):
        if not dense:
            break
        span = (hi[a] - lo[a]) * inv
        if not np.isfinite(span):
            dense = False
            break
        dims[a] = np.int64(span) + 1
        total *= dims[a]
    if total > 8.0 * m + 4096:
        dense = False
    return dims, dense


@numba_helper
def fill_cells(x, active, lo, inv, dims, dense, size, cc, key, start):  # pragma: no cover - compiled
    """Each active row's cell ``cc`` and its key (the dense grid's index, or its hash into
    ``size`` buckets), counted into ``start[key + 1]``."""
    for i in range(x.shape[0]):
        if active[i]:
            if dense:
                for a in range(3):
                    cc[i, a] = min(np.int64((x[i, a] - lo[a]) * inv), dims[a] - 1)
                key[i] = (cc[i, 0] * dims[1] + cc[i, 1]) * dims[2] + cc[i, 2]
            else:
                for a in range(3):
                    f = np.floor(x[i, a] * inv)
                    # a non-finite or huge coordinate: a cell of its own kind, never near others
                    cc[i, a] = np.int64(f) if abs(f) < 1e15 else np.int64(1) << 62
                key[i] = cell_hash(cc[i, 0], cc[i, 1], cc[i, 2], size)
            start[key[i] + 1] += 1


@numba_helper
def cell_order(x, active, cc, key, start, m, size):  # pragma: no cover - compiled
    """``start``: where each key's rows begin (counts summed); returns the active rows in
    key order (ascending within a key) and copies of their positions and cells in that order
    (the scan reads memory in sequence)."""
    for k in range(size):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(m, dtype=np.int64)
    for i in range(x.shape[0]):  # ascending rows within a cell
        if active[i]:
            order[fill[key[i]]] = i
            fill[key[i]] += 1
    xs = np.empty((m, 3))
    cs = np.empty((m, 3), dtype=np.int64)
    for k in range(m):
        for a in range(3):
            xs[k, a] = x[order[k], a]
            cs[k, a] = cc[order[k], a]
    return order, xs, cs


@numba_helper
def near_pairs(
    order, xs, cs, start, dims, dense, size, reach, exclude, n, limit
):  # pragma: no cover - compiled
    """The pairs within ``reach``, in scan order: returns (i's, j's, how many, complete);
    not complete: more than ``limit`` (>= 0), the first ``limit + 1`` found."""
    m = order.shape[0]
    r2 = reach * reach
    raw_i = np.empty(max(16, 8 * m), dtype=np.int64)
    raw_j = np.empty(max(16, 8 * m), dtype=np.int64)
    npairs = 0
    for ka in range(m):
        # the own cell and the 13 cells after it in (x, y, z) order: each pair of cells once
        for q in range(13, 27):
            gx = cs[ka, 0] + q // 9 - 1
            gy = cs[ka, 1] + (q // 3) % 3 - 1
            gz = cs[ka, 2] + q % 3 - 1
            if dense:
                if gx < 0 or gy < 0 or gz < 0 or gx >= dims[0] or gy >= dims[1] or gz >= dims[2]:
                    continue
                b = (gx * dims[1] + gy) * dims[2] + gz
            else:
                b = cell_hash(gx, gy, gz, size)
            first = ka + 1 if q == 13 else start[b]
            for kb in range(first, start[b + 1]):
                if not dense and (cs[kb, 0] != gx or cs[kb, 1] != gy or cs[kb, 2] != gz):
                    continue
                t0 = xs[kb, 0] - xs[ka, 0]
                t1 = xs[kb, 1] - xs[ka, 1]
                t2 = xs[kb, 2] - xs[ka, 2]
                if not (t0 * t0 + t1 * t1 + t2 * t2 <= r2):  # NaN too
                    continue
                i = min(order[ka], order[kb])
                j = max(order[ka], order[kb])
                if exclude.shape[0] and excluded(exclude, i * n + j):
                    continue
                if npairs == limit + 1 and limit >= 0:
                    return raw_i, raw_j, npairs, False
                if npairs == raw_i.shape[0]:
                    gi = np.empty(2 * npairs, dtype=np.int64)
                    gj = np.empty(2 * npairs, dtype=np.int64)
                    gi[:npairs] = raw_i[:npairs]
                    gj[:npairs] = raw_j[:npairs]
                    raw_i, raw_j = gi, gj
                raw_i[npairs] = i
                raw_j[npairs] = j
                npairs += 1
    return raw_i, raw_j, npairs, True


@numba_helper
def sort_pairs(raw_i, raw_j, npairs, n):  # pragma: no cover - compiled
    """The first ``npairs`` pairs in (i, j) order: a counting sort by i, then each i's
    handful of j by insertion."""
    ptr = np.zeros(n + 1, dtype=np.int64)
    for k in range(npairs):
        ptr[raw_i[k] + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    at = ptr[:-1].copy()
    out_i = np.empty(npairs, dtype=np.int64)
    out_j = np.empty(npairs, dtype=np.int64)
    for k in range(npairs):
        i = raw_i[k]
        out_i[at[i]] = i
        out_j[at[i]] = raw_j[k]
        at[i] += 1
    for i in range(n):
        for a in range(ptr[i] + 1, ptr[i + 1]):
            t = out_j[a]
            b2 = a - 1
            while b2 >= ptr[i] and out_j[b2] > t:
                out_j[b2 + 1] = out_j[b2]
                b2 -= 1
            out_j[b2 + 1] = t
    return out_i, out_j


@numba_helper
def candidates(x, active, exclude, reach, limit):  # pragma: no cover - compiled
    """Pairs (i, j), i < j, of active rows with |x_j - x_i|^2 <= reach^2, sorted by (i, j).

    ``limit`` >= 0: more than ``limit`` pairs is too many (the memory budget's share):
    the search stops at the first ``limit + 1`` and returns them unsorted, so the
    caller sees the excess without the list growing past it (-1: no limit).

    Cells ``reach`` wide: a dense grid over the particles' box when it has not
    many more cells than particles (grains in a box), else a spatial hash.
    Rows are counting-sorted by cell; each one looks at the later rows of its
    own cell and at the rows of the 13 cells after its own (half of the 26
    around it: every pair of cells once), and the pairs found are put in
    (i, j) order by a counting sort on i.
    """
    n = x.shape[0]
    lo, hi, m, dense = active_box(x, active)
    if m < 2 or not reach > 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    inv = 1.0 / reach
    dims, dense = grid_shape(lo, hi, inv, m, dense)
    cc = np.zeros((n, 3), dtype=np.int64)
    key = np.zeros(n, dtype=np.int64)
    if dense:
        size = dims[0] * dims[1] * dims[2]
    else:
        size = 1
        while size < 2 * n:
            size *= 2
    start = np.zeros(size + 1, dtype=np.int64)
    fill_cells(x, active, lo, inv, dims, dense, size, cc, key, start)
    order, xs, cs = cell_order(x, active, cc, key, start, m, size)
    raw_i, raw_j, npairs, complete = near_pairs(
        order, xs, cs, start, dims, dense, size, reach, exclude, n, limit
    )
    if not complete:
        return raw_i[:npairs].copy(), raw_j[:npairs].copy()
    return sort_pairs(raw_i, raw_j, npairs, n)


# The step kernel's pieces, in the order contact_step runs them; the per-pair buffers they
# share are filled once by ``pair_setup``.
@numba_helper
def overlapping(ci, cj, reach2, x, inv_mass, pi, pj):  # pragma: no cover - compiled
    """The candidates that overlap: returns (how many, how many of them are between
    particles not both fixed); those pairs into ``pi``, ``pj``."""
    found = 0
    p = 0
    for k in range(ci.shape[0]):
        i = ci[k]
        j = cj[k]
        t0 = x[j, 0] - x[i, 0]
        t1 = x[j, 1] - x[i, 1]
        t2 = x[j, 2] - x[i, 2]
        if not (t0 * t0 + t1 * t1 + t2 * t2 < reach2[k]):
            continue
        found += 1
        if inv_mass[i] + inv_mass[j] > 0:
            pi[p] = i
            pj[p] = j
            p += 1
    return found, p


@numba_helper
def pair_setup(
    pi, pj, p, x, v, v_old, inv_mass, e, relax_factor, w, rel, nrm, limit, lam, count
):  # pragma: no cover - compiled
    """Per pair: ``w`` the summed inverse masses, ``rel`` the relaxation (averaged over the
    contacts per particle, ``count``), ``nrm`` the unit line of centres, ``limit`` the faster
    change of velocity of its two spheres this step (when e > 0), ``lam`` 0."""
    count[:] = 0
    for k in range(p):
        count[pi[k]] += 1
        count[pj[k]] += 1
    for k in range(p):
        i = pi[k]
        j = pj[k]
        w[k] = inv_mass[i] + inv_mass[j]
        rel[k] = min(relax_factor / max(count[i], count[j]), 1.0)
        d2 = 0.0
        for a in range(3):
            t = x[j, a] - x[i, a]
            nrm[k, a] = t
            d2 += t * t
        dist = np.sqrt(d2)
        if dist > 0:
            for a in range(3):
                nrm[k, a] /= dist
        else:
            nrm[k, 0], nrm[k, 1], nrm[k, 2] = 0.0, 1.0, 0.0
        if e > 0:  # the impact pass's limit (resolve_pairs_numpy's)
            si = 0.0
            sj = 0.0
            for a in range(3):
                t = v[i, a] - v_old[i, a]
                si += t * t
                t = v[j, a] - v_old[j, a]
                sj += t * t
            limit[k] = max(np.sqrt(si), np.sqrt(sj))
        lam[k] = 0.0


@numba_helper
def bounce_limits(pi, pj, p, limit, dv, e, resting_steps, bounce_floor):  # pragma: no cover - compiled
    """``limit``: each pair's impact limit (in place of its larger change of velocity), from the largest change of velocity among the pairs
    touching either sphere (``dv[:, 0]`` as scratch)."""
    for r in range(dv.shape[0]):
        dv[r, 0] = 0.0
    for k in range(p):
        dv[pi[k], 0] = max(dv[pi[k], 0], limit[k])
        dv[pj[k], 0] = max(dv[pj[k], 0], limit[k])
    for k in range(p):
        limit[k] = (resting_steps * max(dv[pi[k], 0], dv[pj[k], 0]) + bounce_floor) / e


@numba_helper
def add_scaled(out, dv, inv_mass):  # pragma: no cover - compiled
    """out += dv / m, row by row."""
    for r in range(out.shape[0]):
        w_r = inv_mass[r]
        for a in range(3):
            out[r, a] += dv[r, a] * w_r


@numba_helper
def velocity_passes(pi, pj, p, nrm, w, rel, lam, v, dv, inv_mass, iterations):  # pragma: no cover - compiled
    """The Jacobi passes on velocity: each scatters pair by pair into dv (every particle's sum
    in pair order, from 0.0), then adds dv / m; a pass that changed nothing adds nothing."""
    for _ in range(iterations):
        dv[:] = 0.0
        moved = False
        for k in range(p):
            i = pi[k]
            j = pj[k]
            vn = 0.0
            for a in range(3):
                vn += (v[j, a] - v[i, a]) * nrm[k, a]
            dl = (0.0 - vn) / w[k] * rel[k]
            new = max(lam[k] + dl, 0.0)
            dl = new - lam[k]
            lam[k] = new
            if dl != 0.0:
                moved = True
            for a in range(3):
                dv[i, a] -= dl * nrm[k, a]
                dv[j, a] += dl * nrm[k, a]
        if not moved:
            break
        add_scaled(v, dv, inv_mass)


@numba_helper
def friction_pass(pi, pj, p, nrm, w, count, lam, jb, mu, v, dv, inv_mass):  # pragma: no cover - compiled
    """One Jacobi pass of friction: each pair's sliding stopped, its share at most mu times
    its normal impulses (``lam`` + ``jb``)."""
    dv[:] = 0.0
    for k in range(p):
        i = pi[k]
        j = pj[k]
        vn = 0.0
        for a in range(3):
            vn += (v[j, a] - v[i, a]) * nrm[k, a]
        t0 = v[j, 0] - v[i, 0] - vn * nrm[k, 0]
        t1 = v[j, 1] - v[i, 1] - vn * nrm[k, 1]
        t2 = v[j, 2] - v[i, 2] - vn * nrm[k, 2]
        speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        if speed > 0:  # else it adds nothing
            share = min(1.0 / max(count[i], count[j]), 1.0)
            jt = min(speed / w[k] * share, mu * (lam[k] + jb[k])) / speed
            dv[i, 0] += jt * t0
            dv[i, 1] += jt * t1
            dv[i, 2] += jt * t2
            dv[j, 0] -= jt * t0
            dv[j, 1] -= jt * t1
            dv[j, 2] -= jt * t2
    add_scaled(v, dv, inv_mass)


@numba_helper
def position_passes(pi, pj, p, x, radius, w, rel, dv, inv_mass, iterations):  # pragma: no cover - compiled
    """The Jacobi passes on position: each pair's overlap pushed apart along its current line
    of centres, as :func:`velocity_passes` does velocities."""
    for _ in range(iterations):
        dv[:] = 0.0
        moved = False
        for k in range(p):
            i = pi[k]
            j = pj[k]
            d0 = x[j, 0] - x[i, 0]
            d1 = x[j, 1] - x[i, 1]
            d2 = x[j, 2] - x[i, 2]
            dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            over = radius[i] + radius[j] - dist
            if over <= 0:
                continue
            if dist > 0:
                d0, d1, d2 = d0 / dist, d1 / dist, d2 / dist
            else:
                d0, d1, d2 = 0.0, 1.0, 0.0
            c = over / w[k] * rel[k]
            if c != 0.0:
                moved = True
            dv[i, 0] -= c * d0
            dv[i, 1] -= c * d1
            dv[i, 2] -= c * d2
            dv[j, 0] += c * d0
            dv[j, 1] += c * d1
            dv[j, 2] += c * d2
        if not moved:
            break
        add_scaled(x, dv, inv_mass)


@numba_helper
def contact_step(
    ci,
    cj,
    reach2,
    x,
    v,
    v_old,
    inv_mass,
    radius,
    e,
    mu,
    iterations,
    relax_factor,
    pi,
    pj,
    w,
    rel,
    nrm,
    limit,
    lam,
    jb,
    due,
    dv,
    count,
    resting_steps,
    bounce_floor,
    bounce_limit,
):  # pragma: no cover - compiled
    """Keep the candidates that overlap, then the passes of :func:`resolve_pairs_numpy`.

    ``pi`` .. ``jb``: buffers of at least the candidates' length; ``dv`` (N, 3)
    and ``count`` (N,): per particle. Returns (overlapping pairs, whether any
    pair was resolved).
    """
    found, p = overlapping(ci, cj, reach2, x, inv_mass, pi, pj)
    if p == 0:
        return found, False
    pair_setup(pi, pj, p, x, v, v_old, inv_mass, e, relax_factor, w, rel, nrm, limit, lam, count)
    # impacts first, sequentially (see bounce_sweeps), when anything bounces at all
    if e > 0:
        bounce_limits(pi, pj, p, limit, dv, e, resting_steps, bounce_floor)
        bounce_sweeps(pi, pj, nrm, w, limit, e, v, inv_mass, jb, due, p, bounce_limit)
    else:
        for k in range(p):
            jb[k] = 0.0
    velocity_passes(pi, pj, p, nrm, w, rel, lam, v, dv, inv_mass, iterations)
    if mu > 0:
        friction_pass(pi, pj, p, nrm, w, count, lam, jb, mu, v, dv, inv_mass)
    position_passes(pi, pj, p, x, radius, w, rel, dv, inv_mass, iterations)
    return found, True


def numba_kernels() -> NumbaKernels:
    """The numba kernels (compiled, or loaded from numba's disk cache, on first use)."""
    global _KERNELS
    if _KERNELS is not None:
        return _KERNELS
    import numba

    compile_helpers(globals())

    @numba.njit(cache=True)
    def find_pairs(x, radius, active, exclude, cell):  # pragma: no cover - compiled
        """Overlapping pairs (P, 2) sorted by (i, j): candidates within ``cell`` (>= 2 max radius)."""
        ci, cj = candidates(x, active, exclude, cell, -1)
        out = np.empty((ci.shape[0], 2), dtype=np.int64)
        p = 0
        for k in range(ci.shape[0]):
            i, j = ci[k], cj[k]
            r = radius[i] + radius[j]
            t0 = x[j, 0] - x[i, 0]
            t1 = x[j, 1] - x[i, 1]
            t2 = x[j, 2] - x[i, 2]
            if t0 * t0 + t1 * t1 + t2 * t2 < r * r:
                out[p, 0] = i
                out[p, 1] = j
                p += 1
        return out[:p].copy()

    @numba.njit(cache=True)
    def spread(x, x_built, active):  # pragma: no cover - compiled
        """The farthest active row's displacement from the centre of all their box (inf if not finite)."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for i in range(x.shape[0]):
            if active[i]:
                for a in range(3):
                    d = x[i, a] - x_built[i, a]
                    if not np.isfinite(d):
                        return np.inf
                    lo[a] = min(lo[a], d)
                    hi[a] = max(hi[a], d)
        if not hi[0] >= lo[0]:
            return 0.0
        c0 = 0.5 * (hi[0] + lo[0])
        c1 = 0.5 * (hi[1] + lo[1])
        c2 = 0.5 * (hi[2] + lo[2])
        s = 0.0
        for i in range(x.shape[0]):
            if active[i]:
                e0 = (x[i, 0] - x_built[i, 0]) - c0
                e1 = (x[i, 1] - x_built[i, 1]) - c1
                e2 = (x[i, 2] - x_built[i, 2]) - c2
                s = max(s, e0 * e0 + e1 * e1 + e2 * e2)
        return np.sqrt(s)

    _KERNELS = NumbaKernels(candidates, contact_step, find_pairs, spread)
    return _KERNELS
