"""Contacts between particles: every particle a sphere that others cannot enter.

After each step (and after the colliders), pairs of particles closer than the
sum of their radii are found and resolved:

* **Neighbours** never by all pairs, and not searched afresh every step: a
  Verlet list (Verlet, Phys. Rev. 159, 98, 1967; Allen and Tildesley,
  "Computer Simulation of Liquids", section 5.2) keeps the *candidate* pairs
  closer than ``2 * max radius + skin``, found by ``scipy.spatial.cKDTree``
  (NumPy) or a uniform grid of cells that wide, sorted by cell with a counting
  sort (numba; a spatial hash when the particles' box would need too many
  cells, Teschner et al., "Optimized Spatial Hashing for Collision Detection
  of Deformable Objects", VMV 2003). The list stays valid while no two
  particles have closed by more than the skin, which the step checks from how
  far the particles moved since it was built (the spread of their
  displacements, so a pile falling as one never rebuilds it). Each step keeps
  the candidates that overlap, by the same test on both backends, in (i, j)
  order: the pairs are the same whenever the list was built.
* **Impacts**: pairs whose bounce would be faster than twice what the step's
  forces added to a sphere touching either one (slower is resting contact)
  bounce by
  Newton's law of restitution, ``J = -(1 + e) v_n / (1/m_i + 1/m_j)`` along the
  line of centres (the textbook two-body impact, e.g. Goldstein, "Classical
  Mechanics", section 3.11), one pair at a time in pair order, sweep after sweep
  until nothing approaches that fast (:func:`bounce_sweeps`; the collision pass
  of Guendelman, Bridson and Fedkiw, SIGGRAPH 2003). Sequential impacts pass a
  blow on through touching spheres as a Newton's cradle does, and keep the energy
  at e = 1; a simultaneous solution would share it out and lose energy.
* **Velocities**: then no pair may still approach: normal impulses solved by a
  few Jacobi iterations with accumulated, clamped impulses (Catto, "Iterative
  Dynamics with Temporal Coherence", GDC 2005). Each pair's correction is
  scaled by ``RELAX`` over the larger contact count (at most 1) of its two
  particles (averaged, over-relaxed Jacobi as in Macklin et al., "Unified
  Particle Physics for Real-Time Applications", SIGGRAPH 2014), which keeps
  piles from over-correcting and keeps every exchange equal and opposite:
  momentum is conserved exactly. Coulomb friction then takes at most
  ``friction * J`` off the pair's sliding velocity (J: the pair's impact and
  resting impulses together), also equal and opposite, in one pass averaged
  over the contact count but not over-relaxed (an over-relaxed stop overshoots
  and sets a pile jittering).
* **Positions**: the overlap is removed along the line of centres, each
  particle moving in proportion to its inverse mass, so the pair's centre of
  mass does not move (a few Jacobi passes, averaged as above).

A pass that changes nothing (every correction exactly zero, as for grains
that touch and fall together) ends its iterations: the passes after it would
change nothing either.

Both backends do the same operations in the same order: every particle's
corrections are summed from 0.0 in pair order (the numba kernel scatters pair
by pair, NumPy adds with ``np.add.at``, which is unbuffered and in index
order), so the backends agree to the bit (granular flow is chaotic: any
last-bit difference would grow).

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

from typing import Any, NamedTuple

import numpy as np

from animsim.console import format_bytes
from animsim.elements import StepStage, compile_helpers, numba_helper
from animsim.errors import SimulationError
from animsim.vec import dot3

#: velocity and position passes per step
ITERATIONS = 6
RESTING_STEPS = 2.0
#: over-relaxation of the averaged Jacobi passes (1: plain averaging)
RELAX = 1.5
#: at most this many sweeps of the impact pass: a blow crosses one pair of touching spheres per
#: sweep, so a row of up to 33 touching balls passes it on whole
BOUNCE_SWEEPS = 32
#: an approach slower than this (m/s) is never an impact: grains falling together close at
#: rounding speeds (1e-17 m/s) that would bounce back and forth to the sweep limit
BOUNCE_FLOOR = 1e-6
#: the Verlet list's skin, as a fraction of the largest contact distance ``2 * max radius``
SKIN = 0.3
# One candidate pair of the contact list: its (i, j) index pair as built (16), the k-d
# tree's or the grid's output before sorting (16), and the per-step arrays of a pair that
# overlaps (gathered differences and normals, distances, normal speeds, impulses and the
# Jacobi work arrays: about 20 float64), so a list where everything touches costs this much
# (the pre-flight counts the list at the start with it; bound_memory bounds it later).
CONTACT_PAIR_BYTES = 16 + 16 + 20 * 8
#: the list is rebuilt once two particles may have closed by this fraction of the skin
#: (the rest is margin for rounding in the distances)
SKIN_USE = 0.9


def spring_exclusions(index: np.ndarray, rest: np.ndarray, radius: np.ndarray, n: int) -> np.ndarray:
    """Sorted keys ``min(a,b) * n + max(a,b)`` of springs shorter than the sum of their ends' radii."""
    if len(index) == 0:
        return np.zeros(0, dtype=np.int64)
    a = np.minimum(index[:, 0], index[:, 1]).astype(np.int64)
    b = np.maximum(index[:, 0], index[:, 1]).astype(np.int64)
    near = rest < radius[a] + radius[b]
    return np.unique(a[near] * n + b[near])


_EMPTY = np.zeros(0, dtype=np.int64)


def candidates_numpy(
    x: np.ndarray, active: np.ndarray, exclude: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j), i < j, of ``active`` rows at most about ``reach`` apart (cKDTree), sorted by (i, j).

    The tree's own rounding may keep a pair a hair beyond ``reach`` or drop one a
    hair inside it; callers pass a reach with room to spare.
    """
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(active)
    if rows.size < 2 or not reach > 0:
        return _EMPTY, _EMPTY
    # an unbalanced tree builds in half the time and answers as fast for grains
    tree = cKDTree(x[rows], balanced_tree=False, compact_nodes=False)
    local = tree.query_pairs(reach, output_type="ndarray")
    if local.size == 0:
        return _EMPTY, _EMPTY
    pairs = rows[local].astype(np.int64)
    n = np.int64(len(x))
    # (i, j) order by one sort of the keys i n + j (ten times faster than a lexsort)
    keys = np.sort(np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1]))
    if exclude.size:
        keys = keys[~np.isin(keys, exclude, assume_unique=False)]
    return keys // n, keys % n


def count_pairs_numpy(x: np.ndarray, active: np.ndarray, reach: float) -> int:
    """How many pairs of ``active`` rows lie within about ``reach`` (spring-joined ones too),
    counted by a k-d tree without storing them: the list's size before it is built."""
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(active)
    if rows.size < 2 or not reach > 0:
        return 0
    tree = cKDTree(x[rows], balanced_tree=False, compact_nodes=False)
    # count_neighbors counts ordered pairs, each row with itself too
    return int((tree.count_neighbors(tree, reach) - rows.size) // 2)


def find_pairs_numpy(
    x: np.ndarray, radius: np.ndarray, active: np.ndarray, exclude: np.ndarray
) -> np.ndarray:
    """Overlapping pairs (P, 2), i < j, among ``active`` rows, sorted by (i, j).

    The same pairs in the same order as the numba grid: the tree only proposes
    candidates (within a reach a hair larger than ``2 * max radius``, so its own
    rounding never drops one), and the test that keeps a pair is the numba one,
    ``(d0 d0 + d1 d1) + d2 d2 < (r_i + r_j)^2`` with ``d = x_j - x_i``.
    """
    rows = np.flatnonzero(active)
    rmax = float(radius[rows].max()) if rows.size else 0.0
    ci, cj = candidates_numpy(x, active, exclude, 2.0 * rmax * (1.0 + 1e-9))
    d = x[cj] - x[ci]
    reach = radius[ci] + radius[cj]
    keep = dot3(d, d) < reach * reach
    return np.stack([ci[keep], cj[keep]], axis=1).reshape(-1, 2)


class _Buffers:
    """Arrays kept between steps, so a step of 100,000 grains allocates (and page-faults) nothing big."""

    def __init__(self) -> None:
        self._store: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float64) -> np.ndarray:
        size = int(np.prod(shape))
        buf = self._store.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = np.empty(max(16, size + size // 4), dtype=dtype)
            self._store[name] = buf
        return buf[:size].reshape(shape)


def _dot3_into(a: np.ndarray, b: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """:func:`animsim.vec.dot3` into ``out`` ((a0 b0 + a1 b1) + a2 b2, the same bits)."""
    np.multiply(a[:, 0], b[:, 0], out=out)
    np.multiply(a[:, 1], b[:, 1], out=tmp)
    out += tmp
    np.multiply(a[:, 2], b[:, 2], out=tmp)
    out += tmp
    return out


def _gather_diff(a: np.ndarray, i: np.ndarray, j: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """``a[j] - a[i]`` into ``out``."""
    np.take(a, j, axis=0, out=out, mode="clip")  # "raise" would buffer the output
    np.take(a, i, axis=0, out=tmp, mode="clip")
    out -= tmp
    return out


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
    vn = (v[j, 0] - v[i, 0]) * n0 + (v[j, 1] - v[i, 1]) * n1 + (v[j, 2] - v[i, 2]) * n2
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
        vn = (
            (v[j, 0] - v[i, 0]) * nrm[k, 0]
            + (v[j, 1] - v[i, 1]) * nrm[k, 1]
            + (v[j, 2] - v[i, 2]) * nrm[k, 2]
        )
        due[k] = -vn > limit[k]
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


def bounce_sweeps_numpy(
    i: np.ndarray,
    j: np.ndarray,
    n: np.ndarray,
    w: np.ndarray,
    limit: np.ndarray,
    e: float,
    v: np.ndarray,
    inv_mass: np.ndarray,
    sweeps: int = BOUNCE_SWEEPS,
) -> np.ndarray:
    """:func:`bounce_sweeps` for NumPy (``n``: (P, 3) unit normals); returns jb.

    The marking is vectorised, in :func:`approaching`'s order of operations (the same bits);
    the marked pairs are struck by the same :func:`bounce_pair`, in pair order.
    """
    p = i.size
    jb = np.zeros(p)
    n0, n1, n2 = n[:, 0], n[:, 1], n[:, 2]
    for _ in range(sweeps):
        dv = v[j] - v[i]
        vn = dv[:, 0] * n0 + dv[:, 1] * n1
        vn += dv[:, 2] * n2
        due = np.flatnonzero(-vn > limit)
        if due.size == 0:
            break
        for k in due.tolist():
            jb[k] += bounce_pair(
                int(i[k]),
                int(j[k]),
                float(n0[k]),
                float(n1[k]),
                float(n2[k]),
                float(w[k]),
                float(limit[k]),
                e,
                v,
                inv_mass,
            )
    return jb


def resolve_pairs_numpy(
    i: np.ndarray,
    j: np.ndarray,
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
    buffers: _Buffers | None = None,
) -> bool:
    """Impulses and overlap removal for the pairs (i, j) (sorted by (i, j)), in place (NumPy kernel).

    Every operation is the numba kernel's, in its order and association
    (``(a - b) / w * r`` is not ``(a - b) * (r / w)`` in floating point), and
    pair quantities reach the particles in pair order (one ``np.bincount`` over
    interleaved bins ``[3 i0 + (0, 1, 2), 3 j0 + (0, 1, 2), 3 i1 + ...]``, which
    adds its weights bin by bin in array order from 0.0, as the numba kernel's
    per-particle sums do), so both backends give the same bits.
    """
    ok = inv_mass[i] + inv_mass[j] > 0
    if not ok.all():
        i, j = i[ok], j[ok]
    p = i.size
    if p == 0:
        return False
    buf = _Buffers() if buffers is None else buffers
    n_rows = len(x)
    w = inv_mass[i] + inv_mass[j]
    count = np.bincount(i, minlength=n_rows) + np.bincount(j, minlength=n_rows)
    relax = np.minimum(RELAX / np.maximum(count[i], count[j]), 1.0)
    # One coordinate at a time (rows of (3, P) arrays): NumPy's gathers and products run on
    # contiguous memory. The sums per particle are np.add.at over interleaved bins
    # [i0, j0, i1, j1, ...] with weights [-q0, +q0, -q1, ...]: add.at adds in index order,
    # unbuffered, from 0.0, as the numba kernel's loops do (and np.bincount, slower here).
    bins = buf.get("bins", (p, 2), np.int64)
    bins[:, 0] = i
    bins[:, 1] = j
    bins_flat = bins.reshape(-1)
    weights = buf.get("weights", (3, p, 2))
    q = buf.get("q", (3, p))  # what each pair adds to j (and takes from i), per coordinate
    acc = buf.get("acc", (3, n_rows))
    state_t = buf.get("state_t", (3, n_rows))
    d = buf.get("d", (3, p))
    t1 = buf.get("t1", (p,))
    t2 = buf.get("t2", (p,))

    def scatter_add(target: np.ndarray) -> None:
        """target += (sum in pair order of -q on i, +q on j) * inverse mass, for all rows."""
        for a in range(3):
            weights[a, :, 1] = q[a]
            np.negative(q[a], out=weights[a, :, 0])
            acc[a].fill(0.0)
            np.add.at(acc[a], bins_flat, weights[a].reshape(-1))
        np.multiply(acc, inv_mass, out=acc)
        target += acc.T

    def gather_diff(source: np.ndarray) -> np.ndarray:
        """source[j] - source[i] as (3, P)."""
        np.copyto(state_t, source.T)
        for a in range(3):
            # mode "clip": with "raise" (the default) take buffers its output; the rows are valid
            np.take(state_t[a], j, out=d[a], mode="clip")
            np.take(state_t[a], i, out=t1, mode="clip")
            d[a] -= t1
        return d

    def dot(u: np.ndarray, v3: np.ndarray, out: np.ndarray) -> np.ndarray:
        """(u0 v0 + u1 v1) + u2 v2: :func:`animsim.vec.dot3`'s order, the same bits."""
        np.multiply(u[0], v3[0], out=out)
        np.multiply(u[1], v3[1], out=t2)
        out += t2
        np.multiply(u[2], v3[2], out=t2)
        out += t2
        return out

    # unit normals from i to j (a zero distance points up, as in the numba kernel)
    n = buf.get("n", (3, p))
    gather_diff(x)
    dist = np.sqrt(dot(d, d, np.empty(p)))
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(d, dist, out=n)
    pos = dist > 0
    if not pos.all():
        n[0, ~pos], n[1, ~pos], n[2, ~pos] = 0.0, 1.0, 0.0
    # impacts first, sequentially (bounce_sweeps), when anything bounces at all
    jb = None
    if restitution > 0:
        # resting: slower than twice what the step's forces added to a sphere touching either
        # one (in a pile every grain gains g dt, though two grains falling together close at
        # none and one on the floor is held at rest) ...
        dv = v - v_old
        added = np.sqrt((dv[:, 0] * dv[:, 0] + dv[:, 1] * dv[:, 1]) + dv[:, 2] * dv[:, 2])
        pair_added = np.maximum(added[i], added[j])
        near = np.zeros(n_rows)
        np.maximum.at(near, i, pair_added)
        np.maximum.at(near, j, pair_added)
        # ... and an impact only where the bounce, e times the approach, would be faster than that
        limit = (RESTING_STEPS * np.maximum(near[i], near[j]) + BOUNCE_FLOOR) / restitution
        jb = bounce_sweeps_numpy(i, j, np.ascontiguousarray(n.T), w, limit, restitution, v, inv_mass)
    # then the Jacobi passes: no pair left approaching (the target speed is 0)
    lam = np.zeros(p)
    new = np.empty(p)
    vn = np.empty(p)
    dl = np.empty(p)
    for _ in range(iterations):
        dot(gather_diff(v), n, vn)
        np.subtract(0.0, vn, out=dl)
        dl /= w
        dl *= relax
        np.add(lam, dl, out=new)
        np.maximum(new, 0.0, out=new)
        np.subtract(new, lam, out=dl)
        lam, new = new, lam
        if not dl.any():  # nothing changed: neither would any later pass
            break
        np.multiply(n, dl, out=q)
        scatter_add(v)  # +J n on j, -J n on i: momentum kept
    if friction > 0:
        # one pass, so averaged but not over-relaxed: a grain's contacts stop at most its sliding
        share = np.minimum(1.0 / np.maximum(count[i], count[j]), 1.0)
        dvel = gather_diff(v)
        dot(dvel, n, vn)
        vt = dvel - vn * n
        speed = np.sqrt(dot(vt, vt, np.empty(p)))
        with np.errstate(divide="ignore", invalid="ignore"):
            # Coulomb's bound on the whole normal impulse: the impact's and the resting one
            jt = np.minimum(speed / w * share, friction * (lam if jb is None else lam + jb)) / speed
        # pairs at no sliding speed add nothing (a 0.0 weight leaves every sum's bits alone);
        # the numba kernel adds +jt vt on i and -jt vt on j: the scatter of -(jt vt)
        jt = np.where(speed > 0, jt, 0.0)
        np.negative(jt * vt, out=q)
        scatter_add(v)
    reach = radius[i] + radius[j]
    over = np.empty(p)
    c = np.empty(p)
    for _ in range(iterations):
        gather_diff(x)
        np.sqrt(dot(d, d, dist), out=dist)
        np.subtract(reach, dist, out=over)
        # the numba kernel skips a pair with over <= 0 (so a NaN one is not skipped); a skipped
        # pair's weight 0.0 leaves every sum's bits alone
        with np.errstate(divide="ignore", invalid="ignore"):
            np.divide(over, w, out=c)
            c *= relax
            c[over <= 0] = 0.0
            if not c.any():  # no overlap left to remove
                break
            np.divide(d, dist, out=d)
        pos = dist > 0
        if not pos.all():
            d[0, ~pos], d[1, ~pos], d[2, ~pos] = 0.0, 1.0, 0.0
        np.multiply(d, c, out=q)
        scatter_add(x)  # the pair's centre of mass stays
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
        self._kernels = numba_kernels() if backend == "numba" else None
        self.pairs_last = 0
        #: the most candidate pairs the list may hold (bound_memory: the memory budget's
        #: share after the rest of the run; -1 when nothing bounds it)
        self.max_pairs = -1
        #: how often the candidate list was built (a run's statistics, for tests and benchmarks)
        self.rebuilds = 0
        #: colliders (animsim.colliders.Colliders) and impulse planes (animsim.collisions) to push
        #: out of after the contacts moved particles
        self.colliders = None
        self.planes = None
        self._buffers = _Buffers()
        self._forget()
        finder = (
            "a uniform grid (counting sort by cell)" if backend == "numba" else "a k-d tree (scipy cKDTree)"
        )
        self.label = (
            f"particle contacts: {int(self.active.sum())} particle(s) as spheres "
            f"(radius {self.radius[self.active].min():.3g}-{self.radius[self.active].max():.3g} m), "
            f"restitution {restitution:g}, friction {friction:g}, neighbours by {finder} "
            f"kept in a Verlet list, {iterations} Jacobi passes; "
            f"{self.exclude.size} spring-joined pair(s) left out"
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

    def _forget(self) -> None:
        self._ci = self._cj = _EMPTY
        self._reach2: np.ndarray = np.zeros(0)
        self._x_built: np.ndarray | None = None
        self._active_built: np.ndarray | None = None
        self._skin = 0.0

    def reset(self, state) -> None:
        """A run starts: the candidate list of another run is not reused (it would be valid, but
        a run should not depend on what ran before it, even in how long it takes)."""
        self._forget()

    def apply(
        self, state, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float | None = None
    ) -> bool:
        changed = self._apply(state, x_old, v_old, t0, t1)
        if changed and self.colliders is not None:
            # the overlap removal may push a particle into a collider: never leave it there
            self.colliders.project(state, t0, t1)
        if changed and self.planes is not None:
            self.planes.project_rows(
                state.particle_position, state.particle_velocity, np.flatnonzero(self.active)
            )
        return changed

    def _list_is_stale(self, x: np.ndarray, active: np.ndarray) -> bool:
        """True when two particles may have closed by more than the skin since the list was built."""
        if self._x_built is None or self._x_built.shape != x.shape:
            return True
        if not np.array_equal(active, self._active_built):
            return True
        if self._kernels is not None:
            spread = self._kernels.spread(x, self._x_built, active)
        else:
            d = self._buffers.get("shift", x.shape)
            np.subtract(x, self._x_built, out=d)
            if not self._all_active:
                d = d[active]
            if d.shape[0] == 0:
                return False
            hi, lo = d.max(axis=0), d.min(axis=0)
            half = 0.5 * (hi - lo)
            if 2.0 * float(np.sqrt(half @ half)) <= SKIN_USE * self._skin:
                return False  # even the corners of the displacements' box are near enough
            d -= 0.5 * (hi + lo)
            spread = float(np.sqrt(dot3(d, d).max()))
        # every displacement lies within ``spread`` of one common shift c (the centre of
        # their box), so any two particles have closed by at most |d_i - c| + |d_j - c| <= 2 spread
        return not (2.0 * spread <= SKIN_USE * self._skin)

    def bound_memory(self, budget: int) -> None:
        """The candidate list may hold ``budget`` bytes (CONTACT_PAIR_BYTES a pair)."""
        self.max_pairs = max(int(budget) // CONTACT_PAIR_BYTES, 0)

    def _too_many(self, found: int, t: float) -> SimulationError:
        more = "at least " if self._kernels is not None else ""
        return SimulationError(
            f"particle contacts at t = {t:.6g} s: {more}{found} pairs of particles lie within "
            f"2 x radius + skin of each other (births or a pile squeezed together since the "
            f"start), more than the memory budget leaves room for ({self.max_pairs} pairs, "
            f"{format_bytes(self.max_pairs * CONTACT_PAIR_BYTES)}); lower the radius or the "
            "number of particles, or raise the budget with --max-memory"
        )

    def _rebuild(self, x: np.ndarray, active: np.ndarray, t: float = 0.0) -> None:
        rmax = float(self.radius[active].max()) if active.any() else 0.0
        self._skin = SKIN * 2.0 * rmax
        reach = 2.0 * rmax + self._skin
        if self._kernels is not None:
            ci, cj = self._kernels.candidates(x, active, self.exclude, reach, self.max_pairs)
            found = ci.size
        else:
            found = count_pairs_numpy(x, active, reach) if self.max_pairs >= 0 else 0
            if found <= self.max_pairs or self.max_pairs < 0:
                ci, cj = candidates_numpy(x, active, self.exclude, reach)
        if 0 <= self.max_pairs < found:
            raise self._too_many(found, t)
        self._ci, self._cj = ci, cj
        r = self.radius[ci] + self.radius[cj]
        self._reach2 = r * r
        if self._x_built is None or self._x_built.shape != x.shape:
            self._x_built = np.empty_like(x)
        np.copyto(self._x_built, x)
        self._active_built = active.copy()
        self._all_active = bool(active.all())
        self.rebuilds += 1

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
        if self._list_is_stale(x, active):
            self._rebuild(x, active, t0)
        ci, cj = self._ci, self._cj
        if ci.size == 0:
            self.pairs_last = 0
            return False
        if self._kernels is not None:
            p = ci.size
            b = self._buffers
            n_rows = x.shape[0]
            found, changed = self._kernels.step(
                ci,
                cj,
                self._reach2,
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
                b.get("pi", (p,), np.int64),
                b.get("pj", (p,), np.int64),
                b.get("w", (p,)),
                b.get("rel", (p,)),
                b.get("nrm", (p, 3)),
                b.get("tgt", (p,)),
                b.get("lam", (p,)),
                b.get("jb", (p,)),
                b.get("due", (p,), np.bool_),
                b.get("dv", (n_rows, 3)),
                b.get("count", (n_rows,), np.int64),
                RESTING_STEPS,
                BOUNCE_FLOOR,
                BOUNCE_SWEEPS,
            )
            self.pairs_last = int(found)
            return bool(changed)
        # the candidates that overlap now (the numba kernel's test)
        b = self._buffers
        p = ci.size
        d3 = _gather_diff(x, ci, cj, b.get("d3", (p, 3)), b.get("t3", (p, 3)))
        d2 = _dot3_into(d3, d3, b.get("s1", (p,)), b.get("s2", (p,)))
        keep = d2 < self._reach2
        i, j = ci[keep], cj[keep]
        self.pairs_last = len(i)
        if len(i) == 0:
            return False
        return resolve_pairs_numpy(
            i,
            j,
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
            b,
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
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    m = 0
    dense = True  # a dense grid needs every coordinate finite
    for i in range(n):
        if active[i]:
            m += 1
            for a in range(3):
                if not np.isfinite(x[i, a]):
                    dense = False
                lo[a] = min(lo[a], x[i, a])
                hi[a] = max(hi[a], x[i, a])
    if m < 2 or not reach > 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    inv = 1.0 / reach
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
    cc = np.zeros((n, 3), dtype=np.int64)
    key = np.zeros(n, dtype=np.int64)
    if dense:
        size = dims[0] * dims[1] * dims[2]
    else:
        size = 1
        while size < 2 * n:
            size *= 2
    start = np.zeros(size + 1, dtype=np.int64)
    for i in range(n):
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
    for k in range(size):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(m, dtype=np.int64)
    for i in range(n):  # ascending rows within a cell
        if active[i]:
            order[fill[key[i]]] = i
            fill[key[i]] += 1
    # copies in cell order: the scan below reads memory in sequence
    xs = np.empty((m, 3))
    cs = np.empty((m, 3), dtype=np.int64)
    for k in range(m):
        for a in range(3):
            xs[k, a] = x[order[k], a]
            cs[k, a] = cc[order[k], a]
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
                    return raw_i[:npairs].copy(), raw_j[:npairs].copy()
                if npairs == raw_i.shape[0]:
                    gi = np.empty(2 * npairs, dtype=np.int64)
                    gj = np.empty(2 * npairs, dtype=np.int64)
                    gi[:npairs] = raw_i[:npairs]
                    gj[:npairs] = raw_j[:npairs]
                    raw_i, raw_j = gi, gj
                raw_i[npairs] = i
                raw_j[npairs] = j
                npairs += 1
    # (i, j) order: a counting sort by i, then each i's handful of j by insertion
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

    @numba.njit(cache=True)
    def contact_step(
        ci,
        cj,
        reach2,
        x,
        v,
        x_old,
        v_old,
        inv_mass,
        radius,
        e,
        mu,
        dt,
        iterations,
        relax_factor,
        pi,
        pj,
        w,
        rel,
        nrm,
        tgt,
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
        n_rows = x.shape[0]
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
        if p == 0:
            return found, False
        # contacts per particle (the relaxation's averaging)
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
                tgt[k] = max(np.sqrt(si), np.sqrt(sj))
            lam[k] = 0.0
        if e > 0:  # the largest of those touching each sphere (dv[:, 0] as scratch), then the limit
            for r in range(n_rows):
                dv[r, 0] = 0.0
            for k in range(p):
                dv[pi[k], 0] = max(dv[pi[k], 0], tgt[k])
                dv[pj[k], 0] = max(dv[pj[k], 0], tgt[k])
            for k in range(p):
                tgt[k] = (resting_steps * max(dv[pi[k], 0], dv[pj[k], 0]) + bounce_floor) / e
        # impacts first, sequentially (see bounce_sweeps), when anything bounces at all
        if e > 0:
            bounce_sweeps(pi, pj, nrm, w, tgt, e, v, inv_mass, jb, due, p, bounce_limit)
        else:
            for k in range(p):
                jb[k] = 0.0
        # each pass scatters pair by pair into dv (every particle's sum in pair order, from
        # 0.0), then adds dv / m; a pass that changed nothing adds nothing
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
            for r in range(n_rows):
                w_r = inv_mass[r]
                for a in range(3):
                    v[r, a] += dv[r, a] * w_r
        if mu > 0:
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
            for r in range(n_rows):
                w_r = inv_mass[r]
                for a in range(3):
                    v[r, a] += dv[r, a] * w_r
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
            for r in range(n_rows):
                w_r = inv_mass[r]
                for a in range(3):
                    x[r, a] += dv[r, a] * w_r
        return found, True

    _KERNELS = NumbaKernels(candidates, contact_step, find_pairs, spread)
    return _KERNELS
