"""The numba kernels of particle contacts: the grid search of the Verlet list here, one step's
contact passes in :mod:`animsim.particle_contacts.step_kernels`.

Each kernel and every helper it calls live in one module: numba's disk cache checks only the
file of the function it cached, so a helper in another file could go stale in the cache after
an edit.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from animsim.elements import compile_helpers, numba_helper
from animsim.particle_contacts.step_kernels import compiled_step


class NumbaKernels(NamedTuple):
    """The numba twins of this module's NumPy code."""

    #: (x, active, exclude, reach) -> (ci, cj): the Verlet list's candidates, sorted by (i, j)
    candidates: Any
    #: one step's contacts from the candidates (see ``contact_step``)
    step: Any
    #: (x, radius, active, exclude, cell) -> (P, 2) overlapping pairs, as :func:`find_pairs_numpy`
    find_pairs: Any
    #: (x, x_built, active) -> (how far the displacements spread since the list was built,
    #: a bound on the farthest displacement)
    spread: Any
    #: (old ci, cj, lam, ft, stamp, new ci, cj, lam, ft, stamp): the kept impulses moved to
    #: the new list's candidates, as :meth:`ParticleContacts._carry_impulses` does on NumPy
    carry: Any


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


@numba_helper
def carry(oi, oj, lam_o, ft_o, stamp_o, ni, nj, lam, ft, stamp):  # pragma: no cover - compiled
    """Each new candidate (``ni``, ``nj``) takes the impulses the old list kept for the same pair
    (none: 0 and stamp -1); both lists sorted by (i, j), so one merge finds them."""
    a = 0
    m = oi.shape[0]
    for k in range(ni.shape[0]):
        i = ni[k]
        j = nj[k]
        while a < m and (oi[a] < i or (oi[a] == i and oj[a] < j)):
            a += 1
        if a < m and oi[a] == i and oj[a] == j:
            lam[k] = lam_o[a]
            ft[k, 0], ft[k, 1], ft[k, 2] = ft_o[a, 0], ft_o[a, 1], ft_o[a, 2]
            stamp[k] = stamp_o[a]
        else:
            lam[k] = 0.0
            ft[k, 0], ft[k, 1], ft[k, 2] = 0.0, 0.0, 0.0
            stamp[k] = -1


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
        """(The farthest active row's displacement from the centre of all their box, the length of
        the box's farthest corner from 0: no row moved farther); (inf, inf) if not finite."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for i in range(x.shape[0]):
            if active[i]:
                for a in range(3):
                    d = x[i, a] - x_built[i, a]
                    if not np.isfinite(d):
                        return np.inf, np.inf
                    lo[a] = min(lo[a], d)
                    hi[a] = max(hi[a], d)
        if not hi[0] >= lo[0]:
            return 0.0, 0.0
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
        far = 0.0
        for a in range(3):
            far += max(-lo[a], hi[a]) ** 2
        return np.sqrt(s), np.sqrt(far)

    _KERNELS = NumbaKernels(candidates, compiled_step(), find_pairs, spread, globals()["carry"])
    return _KERNELS
