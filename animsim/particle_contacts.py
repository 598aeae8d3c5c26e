"""Contacts between particles: every particle a sphere that others cannot enter.

After each step (and after the colliders), pairs of particles closer than the
sum of their radii are found and resolved:

* **Neighbours** never by all pairs: NumPy asks ``scipy.spatial.cKDTree`` for
  the pairs within ``2 * max radius`` (``query_pairs``); numba hashes the
  particles into a uniform grid of cells ``2 * max radius`` wide (Teschner et
  al., "Optimized Spatial Hashing for Collision Detection of Deformable
  Objects", VMV 2003) and looks in the 27 cells around each one. Both keep a
  pair by the same test and sort the pairs by (i, j), and the passes below do
  the same operations in the same order on both, so the backends agree to the
  bit (granular flow is chaotic: any last-bit difference would grow).
* **Velocities**: pairwise normal impulses along the line of centres, mass
  weighted (``J = -(1 + e) v_n / (1/m_i + 1/m_j)``, the textbook two-body
  impact, e.g. Goldstein, "Classical Mechanics", section 3.11), solved by a
  few Jacobi iterations with accumulated, clamped impulses (Catto,
  "Iterative Dynamics with Temporal Coherence", GDC 2005). The restitution
  target is set from the approach speed before the iterations, so repeated
  passes never re-bounce. An approach slower than what the relative
  acceleration adds in two steps is resting (restitution 0), as on planes.
  Each pair's correction is scaled by ``RELAX`` over the larger contact count (at most 1)
  of its two particles (averaged, over-relaxed Jacobi as in Macklin et al.,
  "Unified Particle Physics for Real-Time Applications", SIGGRAPH 2014), which
  keeps piles from over-correcting and keeps every exchange equal and
  opposite: momentum is conserved exactly.
  Coulomb friction then takes at most ``friction * J`` off the pair's sliding
  velocity, also equal and opposite.
* **Positions**: the overlap is removed along the line of centres, each
  particle moving in proportion to its inverse mass, so the pair's centre of
  mass does not move (a few Jacobi passes, averaged as above).

Pinned particles act as infinitely heavy; dead emitter slots and rigid-body
rows take no part. Two particles joined by a spring whose rest length is
shorter than the sum of their radii would touch at rest: their contact is
left out (the spring keeps them apart), or a cloth with a radius would push
its own neighbours apart and explode. So cloth with a radius does not pass
through itself where its particles meet in a fold (vertex against vertex);
a thin fold can still slip between vertices, since triangles do not collide.
Contacts are found at the end of each step: two particles fast enough to pass
through each other within one step are not caught.
"""

from __future__ import annotations

import numpy as np

from animsim.elements import StepStage
from animsim.vec import dot3

#: velocity and position passes per step
ITERATIONS = 6
RESTING_STEPS = 2.0
#: over-relaxation of the averaged Jacobi passes (1: plain averaging)
RELAX = 1.5


def spring_exclusions(index: np.ndarray, rest: np.ndarray, radius: np.ndarray, n: int) -> np.ndarray:
    """Sorted keys ``min(a,b) * n + max(a,b)`` of springs shorter than the sum of their ends' radii."""
    if len(index) == 0:
        return np.zeros(0, dtype=np.int64)
    a = np.minimum(index[:, 0], index[:, 1]).astype(np.int64)
    b = np.maximum(index[:, 0], index[:, 1]).astype(np.int64)
    near = rest < radius[a] + radius[b]
    return np.unique(a[near] * n + b[near])


def find_pairs_numpy(
    x: np.ndarray, radius: np.ndarray, active: np.ndarray, exclude: np.ndarray
) -> np.ndarray:
    """Overlapping pairs (P, 2), i < j, among ``active`` rows (cKDTree), sorted by (i, j).

    The same pairs in the same order as the numba grid: the tree only proposes
    candidates (within a reach a hair larger than ``2 * max radius``, so its own
    rounding never drops one), and the test that keeps a pair is the numba one,
    ``(d0 d0 + d1 d1) + d2 d2 < (r_i + r_j)^2`` with ``d = x_j - x_i``.
    """
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(active)
    if rows.size < 2:
        return np.zeros((0, 2), dtype=np.int64)
    rmax = float(radius[rows].max())
    if rmax <= 0:
        return np.zeros((0, 2), dtype=np.int64)
    tree = cKDTree(x[rows])
    local = tree.query_pairs(2.0 * rmax * (1.0 + 1e-9), output_type="ndarray")
    if local.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = rows[local].astype(np.int64)
    pairs.sort(axis=1)
    d = x[pairs[:, 1]] - x[pairs[:, 0]]
    dist2 = dot3(d, d)
    reach = radius[pairs[:, 0]] + radius[pairs[:, 1]]
    keep = dist2 < reach * reach
    if exclude.size:
        keys = pairs[:, 0] * np.int64(len(x)) + pairs[:, 1]
        keep &= ~np.isin(keys, exclude, assume_unique=False)
    pairs = pairs[keep]
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return np.ascontiguousarray(pairs[order])


class _Scatter:
    """Per-particle sums (n_rows, 3) of ``-q`` on ``i`` and ``+q`` on ``j``, in pair order.

    ``np.bincount`` adds its weights bin by bin in array order from 0.0, so the
    interleaved bins ``[3 i0 + (0, 1, 2), 3 j0 + (0, 1, 2), 3 i1 + ...]`` give
    exactly the numba loop ``dv[i] -= q; dv[j] += q`` over the pairs, to the bit.
    """

    def __init__(self, i: np.ndarray, j: np.ndarray, n_rows: int):
        axes = np.arange(3)
        self.bins = np.stack([3 * i[:, None] + axes, 3 * j[:, None] + axes], axis=1).ravel()
        self.n_rows = n_rows
        self.weights = np.empty((i.size, 2, 3))

    def __call__(self, q: np.ndarray) -> np.ndarray:
        np.negative(q, out=self.weights[:, 0])
        self.weights[:, 1] = q
        return np.bincount(self.bins, weights=self.weights.ravel(), minlength=3 * self.n_rows).reshape(
            self.n_rows, 3
        )


def _unit(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit rows of ``d`` and their lengths; a zero row points up, as in the numba kernel."""
    dist = np.sqrt(dot3(d, d))
    ok = dist > 0
    out = np.empty_like(d)
    out[ok] = d[ok] / dist[ok, None]
    out[~ok] = (0.0, 1.0, 0.0)
    return out, dist


def resolve_pairs_numpy(
    pairs: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    x_old: np.ndarray,
    v_old: np.ndarray,
    inv_mass: np.ndarray,
    radius: np.ndarray,
    restitution: float,
    friction: float,
    dt: float,
    iterations: int = ITERATIONS,
) -> bool:
    """Impulses and overlap removal for ``pairs`` (NumPy kernel), in place.

    Every operation is the numba kernel's, in its order and association
    (``(a - b) / w * r`` is not ``(a - b) * (r / w)`` in floating point), and
    pair quantities reach the particles in pair order (:func:`_scatter`), so
    both backends give the same bits; granular flow is chaotic and would
    otherwise part within a fraction of a second.
    """
    i, j = pairs[:, 0], pairs[:, 1]
    ok = inv_mass[i] + inv_mass[j] > 0
    i, j = i[ok], j[ok]
    if i.size == 0:
        return False
    n_rows = len(x)
    w = inv_mass[i] + inv_mass[j]
    count = np.bincount(np.concatenate([i, j]), minlength=n_rows)
    relax = np.minimum(RELAX / np.maximum(count[i], count[j]), 1.0)
    inv = inv_mass[:, None]
    scatter = _Scatter(i, j, n_rows)

    n, _ = _unit(x[j] - x[i])
    # restitution target from the approach before any pass
    vn0 = dot3(v[j] - v[i], n)
    ar = dot3((v[j] - v_old[j]) - (v[i] - v_old[i]), n) / dt
    resting = -vn0 <= RESTING_STEPS * np.maximum(-ar, 0.0) * dt
    target = np.where((vn0 < 0) & ~resting, -restitution * vn0, 0.0)
    lam = np.zeros(i.size)
    for _ in range(iterations):
        vn = dot3(v[j] - v[i], n)
        dl = (target - vn) / w * relax
        new = np.maximum(lam + dl, 0.0)
        dl = new - lam
        lam = new
        v += scatter(dl[:, None] * n) * inv  # +J n on j, -J n on i: momentum kept
    if friction > 0:
        dvel = v[j] - v[i]
        vn = dot3(dvel, n)
        vt = dvel - vn[:, None] * n
        speed = np.sqrt(dot3(vt, vt))
        with np.errstate(divide="ignore", invalid="ignore"):
            jt = np.minimum(speed / w * relax, friction * lam) / speed
        # pairs at no sliding speed add nothing (a 0.0 weight leaves every sum's bits alone);
        # the numba kernel adds +jt vt on i and -jt vt on j: the scatter of -(jt vt)
        jt = np.where(speed > 0, jt, 0.0)
        v += scatter(-(jt[:, None] * vt)) * inv
    reach = radius[i] + radius[j]
    for _ in range(iterations):
        d = x[j] - x[i]
        dist = np.sqrt(dot3(d, d))
        over = reach - dist
        # the numba kernel skips a pair with over <= 0 (so a NaN one is not skipped); a skipped
        # pair's weight 0.0 leaves every sum's bits alone
        with np.errstate(divide="ignore", invalid="ignore"):
            nn = np.where(dist[:, None] > 0, d / dist[:, None], (0.0, 1.0, 0.0))
            c = np.where(over <= 0, 0.0, over / w * relax)
        x += scatter(c[:, None] * nn) * inv  # the pair's centre of mass stays
    return True


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
        self._kernel = numba_kernels() if backend == "numba" else None
        self.pairs_last = 0
        #: colliders (animsim.colliders.Colliders) and impulse planes (animsim.collisions) to push
        #: out of after the contacts moved particles
        self.colliders = None
        self.planes = None
        finder = "uniform grid hash" if backend == "numba" else "k-d tree (scipy cKDTree)"
        self.label = (
            f"particle contacts: {int(self.active.sum())} particle(s) as spheres "
            f"(radius {self.radius[self.active].min():.3g}-{self.radius[self.active].max():.3g} m), "
            f"restitution {restitution:g}, friction {friction:g}, neighbours by {finder}, "
            f"{iterations} Jacobi passes; {self.exclude.size} spring-joined pair(s) left out"
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

    def reset(self, state) -> None:
        """Contacts keep no state between steps."""

    def apply(
        self, state, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float | None = None
    ) -> bool:
        changed = self._apply(state, x_old, v_old, t0, t1)
        if changed and self.colliders is not None:
            # the overlap removal may push a particle into a collider: never leave it there
            self.colliders.project(state, t0, t1)
        if changed and self.planes is not None:
            self.planes._project(
                state.particle_position, state.particle_velocity, np.flatnonzero(self.active)
            )
        return changed

    def _apply(self, state, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float) -> bool:
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
        if self._kernel is not None:
            find, resolve = self._kernel
            rmax = float(self.radius[active].max()) if active.any() else 0.0
            if rmax <= 0:
                return False
            pairs = find(x, self.radius, active, self.exclude, 2.0 * rmax)
            self.pairs_last = len(pairs)
            if len(pairs) == 0:
                return False
            return bool(
                resolve(
                    pairs,
                    x,
                    v,
                    x_old,
                    v_old,
                    inv_mass,
                    self.radius,
                    self.restitution,
                    self.friction,
                    dt,
                    self.iterations,
                    RELAX,
                )
            )
        pairs = find_pairs_numpy(x, self.radius, active, self.exclude)
        self.pairs_last = len(pairs)
        if len(pairs) == 0:
            return False
        return resolve_pairs_numpy(
            pairs,
            x,
            v,
            x_old,
            v_old,
            inv_mass,
            self.radius,
            self.restitution,
            self.friction,
            dt,
            self.iterations,
        )


_KERNELS = None


def numba_kernels():
    """The numba twins: a uniform-grid hash for the pairs, and the same Jacobi passes."""
    global _KERNELS
    if _KERNELS is not None:
        return _KERNELS
    import numba

    @numba.njit(cache=True)
    def cell_hash(cx, cy, cz, size):  # pragma: no cover - compiled
        # Teschner et al. 2003: XOR of the cell coordinates times three large primes.
        # size is a power of two: the mask is the modulo, for negative h too
        return ((cx * 73856093) ^ (cy * 19349663) ^ (cz * 83492791)) & (size - 1)

    @numba.njit(cache=True)
    def excluded(keys, key):  # pragma: no cover - compiled
        lo, hi = 0, keys.shape[0]
        while lo < hi:
            mid = (lo + hi) // 2
            if keys[mid] < key:
                lo = mid + 1
            else:
                hi = mid
        return lo < keys.shape[0] and keys[lo] == key

    @numba.njit(cache=True)
    def sort_pairs(pairs, n):  # pragma: no cover - compiled
        # by (i, j), as the NumPy kernel's lexsort: both backends then resolve the
        # same pairs in the same order, which the Jacobi scatter's rounding depends on
        keys = pairs[:, 0] * n + pairs[:, 1]
        order = np.argsort(keys)
        out = np.empty_like(pairs)
        for k in range(order.shape[0]):
            out[k, 0] = pairs[order[k], 0]
            out[k, 1] = pairs[order[k], 1]
        return out

    @numba.njit(cache=True)
    def find_pairs(x, radius, active, exclude, cell):  # pragma: no cover - compiled
        return sort_pairs(find_pairs_any(x, radius, active, exclude, cell), x.shape[0])

    @numba.njit(cache=True)
    def find_pairs_any(x, radius, active, exclude, cell):  # pragma: no cover - compiled
        # a dense grid over the particles' bounding box when it is not much larger than
        # the particle count (the common case: grains in a box), else the spatial hash
        n = x.shape[0]
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        m = 0
        for i in range(n):
            if active[i]:
                m += 1
                for a in range(3):
                    lo[a] = min(lo[a], x[i, a])
                    hi[a] = max(hi[a], x[i, a])
        if m < 2:
            return np.empty((0, 2), dtype=np.int64)
        dims = np.empty(3, dtype=np.int64)
        total = 1.0
        for a in range(3):
            span = (hi[a] - lo[a]) / cell
            if not np.isfinite(span):
                return find_pairs_hashed(x, radius, active, exclude, cell)
            dims[a] = np.int64(span) + 1
            total *= dims[a]
        if total > 8.0 * m + 4096:
            return find_pairs_hashed(x, radius, active, exclude, cell)
        return find_pairs_dense(x, radius, active, exclude, cell, lo, dims, m)

    @numba.njit(cache=True)
    def find_pairs_dense(x, radius, active, exclude, cell, lo, dims, m):  # pragma: no cover - compiled
        n = x.shape[0]
        ny, nz = dims[1], dims[2]
        ncell = dims[0] * ny * nz
        inv = 1.0 / cell
        key = np.empty(n, dtype=np.int64)
        start = np.zeros(ncell + 1, dtype=np.int64)
        for i in range(n):
            if active[i]:
                cx = min(np.int64((x[i, 0] - lo[0]) * inv), dims[0] - 1)
                cy = min(np.int64((x[i, 1] - lo[1]) * inv), ny - 1)
                cz = min(np.int64((x[i, 2] - lo[2]) * inv), nz - 1)
                key[i] = (cx * ny + cy) * nz + cz
                start[key[i] + 1] += 1
        for k in range(ncell):
            start[k + 1] += start[k]
        fill = start[:-1].copy()
        order = np.empty(m, dtype=np.int64)
        xs = np.empty((m, 3))
        rs = np.empty(m)
        for i in range(n):  # ascending rows within a cell: a deterministic order
            if active[i]:
                k = fill[key[i]]
                order[k] = i
                for a in range(3):
                    xs[k, a] = x[i, a]
                rs[k] = radius[i]
                fill[key[i]] += 1
        out = np.empty((max(16, 4 * m), 2), dtype=np.int64)
        npairs = 0
        for c in range(ncell):
            c0 = start[c]
            c1 = start[c + 1]
            if c0 == c1:
                continue
            cz = c % nz
            cy = (c // nz) % ny
            cx = c // (ny * nz)
            # the cell itself and its 13 "forward" neighbours: each pair of cells once
            for nb in range(14):
                if nb == 0:
                    dx, dy, dz = 0, 0, 0
                else:
                    q = nb + 13  # offsets 14..26 of the 3x3x3 block, i.e. after the centre
                    dx, dy, dz = q // 9 - 1, (q // 3) % 3 - 1, q % 3 - 1
                gx, gy, gz = cx + dx, cy + dy, cz + dz
                if gx < 0 or gy < 0 or gz < 0 or gx >= dims[0] or gy >= ny or gz >= nz:
                    continue
                g = (gx * ny + gy) * nz + gz
                for ka in range(c0, c1):
                    kb0 = ka + 1 if nb == 0 else start[g]
                    for kb in range(kb0, start[g + 1]):
                        r = rs[ka] + rs[kb]
                        d2 = 0.0
                        for a in range(3):
                            t = xs[kb, a] - xs[ka, a]
                            d2 += t * t
                        if not (d2 < r * r):  # the NumPy test, NaN included
                            continue
                        i = order[ka]
                        j = order[kb]
                        if i > j:
                            i, j = j, i
                        if exclude.shape[0] and excluded(exclude, i * n + j):
                            continue
                        if npairs == out.shape[0]:
                            grown = np.empty((2 * out.shape[0], 2), dtype=np.int64)
                            grown[:npairs] = out
                            out = grown
                        out[npairs, 0] = i
                        out[npairs, 1] = j
                        npairs += 1
        return out[:npairs].copy()

    @numba.njit(cache=True)
    def find_pairs_hashed(x, radius, active, exclude, cell):  # pragma: no cover - compiled
        n = x.shape[0]
        size = 1
        while size < 2 * n:
            size *= 2
        ci = np.empty((n, 3), dtype=np.int64)
        start = np.zeros(size + 1, dtype=np.int64)
        inv = 1.0 / cell
        m = 0
        for i in range(n):
            if active[i]:
                for a in range(3):
                    ci[i, a] = np.int64(np.floor(x[i, a] * inv))
                start[cell_hash(ci[i, 0], ci[i, 1], ci[i, 2], size) + 1] += 1
                m += 1
        for k in range(size):
            start[k + 1] += start[k]
        fill = start[:-1].copy()
        order = np.empty(m, dtype=np.int64)
        for i in range(n):  # ascending rows within a bucket: a deterministic order
            if active[i]:
                hb = cell_hash(ci[i, 0], ci[i, 1], ci[i, 2], size)
                order[fill[hb]] = i
                fill[hb] += 1
        # one pass in bucket order (neighbouring particles are near in memory),
        # into a buffer that doubles when full
        out = np.empty((max(16, 4 * m), 2), dtype=np.int64)
        # copies in bucket order: the inner loop then reads memory in sequence
        xs = np.empty((m, 3))
        cs = np.empty((m, 3), dtype=np.int64)
        rs = np.empty(m)
        for k in range(m):
            i = order[k]
            for a in range(3):
                xs[k, a] = x[i, a]
                cs[k, a] = ci[i, a]
            rs[k] = radius[i]
        npairs = 0
        for ki in range(m):
            i = order[ki]
            for dx in range(-1, 2):
                for dy in range(-1, 2):
                    for dz in range(-1, 2):
                        gx, gy, gz = cs[ki, 0] + dx, cs[ki, 1] + dy, cs[ki, 2] + dz
                        hb = cell_hash(gx, gy, gz, size)
                        for k in range(start[hb], start[hb + 1]):
                            if cs[k, 0] != gx or cs[k, 1] != gy or cs[k, 2] != gz:
                                continue
                            j = order[k]
                            if j <= i:
                                continue
                            r = rs[ki] + rs[k]
                            d2 = 0.0
                            for a in range(3):
                                t = xs[k, a] - xs[ki, a]
                                d2 += t * t
                            if not (d2 < r * r):  # the NumPy test, NaN included
                                continue
                            if exclude.shape[0] and excluded(exclude, i * n + j):
                                continue
                            if npairs == out.shape[0]:
                                grown = np.empty((2 * out.shape[0], 2), dtype=np.int64)
                                grown[:npairs] = out
                                out = grown
                            out[npairs, 0] = i
                            out[npairs, 1] = j
                            npairs += 1
        out = out[:npairs].copy()
        return out

    @numba.njit(cache=True)
    def resolve(
        pairs, x, v, x_old, v_old, inv_mass, radius, e, mu, dt, iterations, relax_factor
    ):  # pragma: no cover
        p = pairs.shape[0]
        n_rows = x.shape[0]
        count = np.zeros(n_rows, dtype=np.int64)
        use = np.zeros(p, dtype=np.bool_)
        for k in range(p):
            if inv_mass[pairs[k, 0]] + inv_mass[pairs[k, 1]] > 0:
                use[k] = True
                count[pairs[k, 0]] += 1
                count[pairs[k, 1]] += 1
        nrm = np.zeros((p, 3))
        target = np.zeros(p)
        lam = np.zeros(p)
        relax = np.zeros(p)
        any_ = False
        for k in range(p):
            if not use[k]:
                continue
            any_ = True
            i, j = pairs[k, 0], pairs[k, 1]
            relax[k] = min(relax_factor / max(count[i], count[j]), 1.0)
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
            vn0 = 0.0
            ar = 0.0
            for a in range(3):
                vn0 += (v[j, a] - v[i, a]) * nrm[k, a]
                ar += ((v[j, a] - v_old[j, a]) - (v[i, a] - v_old[i, a])) * nrm[k, a]
            ar /= dt
            resting = -vn0 <= 2.0 * max(-ar, 0.0) * dt
            if vn0 < 0 and not resting:
                target[k] = -e * vn0
        if not any_:
            return False
        dv = np.zeros((n_rows, 3))
        for _ in range(iterations):
            dv[:] = 0.0
            for k in range(p):
                if not use[k]:
                    continue
                i, j = pairs[k, 0], pairs[k, 1]
                w = inv_mass[i] + inv_mass[j]
                vn = 0.0
                for a in range(3):
                    vn += (v[j, a] - v[i, a]) * nrm[k, a]
                dl = (target[k] - vn) / w * relax[k]
                new = max(lam[k] + dl, 0.0)
                dl = new - lam[k]
                lam[k] = new
                for a in range(3):
                    dv[i, a] -= dl * nrm[k, a]
                    dv[j, a] += dl * nrm[k, a]
            for r in range(n_rows):
                for a in range(3):
                    v[r, a] += dv[r, a] * inv_mass[r]
        if mu > 0:
            dv[:] = 0.0
            for k in range(p):
                if not use[k]:
                    continue
                i, j = pairs[k, 0], pairs[k, 1]
                w = inv_mass[i] + inv_mass[j]
                vn = 0.0
                for a in range(3):
                    vn += (v[j, a] - v[i, a]) * nrm[k, a]
                t0 = v[j, 0] - v[i, 0] - vn * nrm[k, 0]
                t1 = v[j, 1] - v[i, 1] - vn * nrm[k, 1]
                t2 = v[j, 2] - v[i, 2] - vn * nrm[k, 2]
                speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                if speed > 0:
                    jt = min(speed / w * relax[k], mu * lam[k]) / speed
                    dv[i, 0] += jt * t0
                    dv[i, 1] += jt * t1
                    dv[i, 2] += jt * t2
                    dv[j, 0] -= jt * t0
                    dv[j, 1] -= jt * t1
                    dv[j, 2] -= jt * t2
            for r in range(n_rows):
                for a in range(3):
                    v[r, a] += dv[r, a] * inv_mass[r]
        for _ in range(iterations):
            dv[:] = 0.0
            for k in range(p):
                if not use[k]:
                    continue
                i, j = pairs[k, 0], pairs[k, 1]
                w = inv_mass[i] + inv_mass[j]
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
                c = over / w * relax[k]
                dv[i, 0] -= c * d0
                dv[i, 1] -= c * d1
                dv[i, 2] -= c * d2
                dv[j, 0] += c * d0
                dv[j, 1] += c * d1
                dv[j, 2] += c * d2
            for r in range(n_rows):
                for a in range(3):
                    x[r, a] += dv[r, a] * inv_mass[r]
        return True

    _KERNELS = (find_pairs, resolve)
    return _KERNELS
