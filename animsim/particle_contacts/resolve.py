"""The NumPy contact passes of one step: impacts (:func:`bounce_sweeps_numpy`), then the warm-started
Jacobi passes of the resting contacts with the walls and the position passes
(:func:`resolve_pairs_numpy`), in the numba kernel's order
(:func:`animsim.particle_contacts.step_kernels.contact_step`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from animsim.particle_contacts.constants import (
    BOUNCE_FLOOR,
    BOUNCE_SWEEPS,
    CONVERGED,
    ITERATIONS,
    OVERLAP_PASSES,
    RELAX,
    RESTING_STEPS,
)
from animsim.particle_contacts.step_kernels import bounce_pair
from animsim.particle_contacts.walls import NO_WALLS, WallContacts


class Buffers:
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


def dot3_into(a: np.ndarray, b: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """:func:`animsim.vec.dot3` into ``out`` ((a0 b0 + a1 b1) + a2 b2, the same bits)."""
    np.multiply(a[:, 0], b[:, 0], out=out)
    np.multiply(a[:, 1], b[:, 1], out=tmp)
    out += tmp
    np.multiply(a[:, 2], b[:, 2], out=tmp)
    out += tmp
    return out


def gather_diff(a: np.ndarray, i: np.ndarray, j: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """``a[j] - a[i]`` into ``out``."""
    np.take(a, j, axis=0, out=out, mode="clip")  # "raise" would buffer the output
    np.take(a, i, axis=0, out=tmp, mode="clip")
    out -= tmp
    return out


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


class Kept(NamedTuple):
    """The impulses kept between steps for the warm start: per candidate pair of the Verlet list
    (``lam``, ``ft`` (C, 3) and the step ``stamp`` they were kept at), this step's stamp
    ``now``, and the wall contacts' remembered impulses (``wlam``, ``wft``, in and out)."""

    lam: np.ndarray
    ft: np.ndarray
    stamp: np.ndarray
    now: int
    wlam: np.ndarray
    wft: np.ndarray


class _PairScratch:
    """The working arrays of one step's pairs and wall contacts (kept in :class:`Buffers`) and
    the fixed-order gathers, sums and scatters of the passes on them."""

    def __init__(
        self, i: np.ndarray, j: np.ndarray, wr: np.ndarray, inv_mass: np.ndarray, n_rows: int, buf: Buffers
    ) -> None:
        p, nw = i.size, wr.size
        self.i, self.j, self.inv_mass = i, j, inv_mass
        # One coordinate at a time (rows of (3, P) arrays): NumPy's gathers and products run on
        # contiguous memory. The sums per particle are np.add.at over interleaved bins
        # [i0, j0, i1, j1, ..., then the walls' rows] with weights [-q0, +q0, -q1, ..., qw0, ...]:
        # add.at adds in index order, unbuffered, from 0.0, as the numba kernel's loops do (pairs,
        # then walls; np.bincount is slower here).
        bins = buf.get("bins", (2 * p + nw,), np.int64)
        bins[0 : 2 * p : 2] = i
        bins[1 : 2 * p : 2] = j
        bins[2 * p :] = wr
        self.bins_all, self.bins_pairs = bins, bins[: 2 * p]
        self.weights = buf.get("weights", (3, 2 * p + nw))
        self.q = buf.get("q", (3, p))  # what each pair adds to j (and takes from i), per coordinate
        self.qw = buf.get("qw", (3, nw))  # what each wall contact adds to its row
        self.acc = buf.get("acc", (3, n_rows))
        self.state_t = buf.get("state_t", (3, n_rows))
        self.d = buf.get("d", (3, p))
        self.t1 = buf.get("t1", (p,))
        self.t2 = buf.get("t2", (max(p, nw),))

    def scatter_add(self, target: np.ndarray, walls: bool = False) -> None:
        """target += (sum in contact order of -q on i, +q on j, then qw on the walls' rows) *
        inverse mass, for all rows."""
        p = self.i.size
        weights, q, acc = self.weights, self.q, self.acc
        bins = self.bins_all if walls else self.bins_pairs
        for a in range(3):
            weights[a, 1 : 2 * p : 2] = q[a]
            np.negative(q[a], out=weights[a, 0 : 2 * p : 2])
            if walls:
                weights[a, 2 * p :] = self.qw[a]
            acc[a].fill(0.0)
            np.add.at(acc[a], bins, weights[a, : bins.size])
        np.multiply(acc, self.inv_mass, out=acc)
        target += acc.T

    def gather_diff(self, source: np.ndarray) -> np.ndarray:
        """source[j] - source[i] as (3, P)."""
        state_t, d, t1 = self.state_t, self.d, self.t1
        np.copyto(state_t, source.T)
        for a in range(3):
            # mode "clip": with "raise" (the default) take buffers its output; the rows are valid
            np.take(state_t[a], self.j, out=d[a], mode="clip")
            np.take(state_t[a], self.i, out=t1, mode="clip")
            d[a] -= t1
        return d

    def dot(self, u: np.ndarray, v3: np.ndarray, out: np.ndarray) -> np.ndarray:
        """(u0 v0 + u1 v1) + u2 v2: :func:`animsim.vec.dot3`'s order, the same bits."""
        t2 = self.t2[: out.size]
        np.multiply(u[0], v3[0], out=out)
        np.multiply(u[1], v3[1], out=t2)
        out += t2
        np.multiply(u[2], v3[2], out=t2)
        out += t2
        return out


def resolve_pairs_numpy(
    i: np.ndarray,
    j: np.ndarray,
    pk: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    v_old: np.ndarray,
    inv_mass: np.ndarray,
    radius: np.ndarray,
    restitution: float,
    friction: float,
    dt: float,
    kept: Kept,
    walls: WallContacts = NO_WALLS,
    iterations: int = ITERATIONS,
    buffers: Buffers | None = None,
) -> tuple[bool, int]:
    """Impulses and overlap removal for the pairs (i, j) (sorted by (i, j); ``pk``: their
    candidates in the Verlet list) and the wall contacts, in place (NumPy kernel).

    Every operation is the numba kernel's, in its order and association
    (``(a - b) / w * r`` is not ``(a - b) * (r / w)`` in floating point), and
    contact quantities reach the particles in contact order (``np.add.at`` over
    interleaved bins, which adds its weights bin by bin in array order from 0.0, as the
    numba kernel's per-particle sums do), so both backends give the same bits. Returns whether
    any pair was resolved and how many resting passes ran.
    """
    ok = inv_mass[i] + inv_mass[j] > 0
    if not ok.all():
        i, j, pk = i[ok], j[ok], pk[ok]
    p = i.size
    if p == 0:
        return False, 0
    buf = Buffers() if buffers is None else buffers
    n_rows = len(x)
    w = inv_mass[i] + inv_mass[j]
    wr = walls.rows
    count = (
        np.bincount(i, minlength=n_rows)
        + np.bincount(j, minlength=n_rows)
        + np.bincount(wr, minlength=n_rows)
    )
    # each contact's relaxation (averaged over the contacts per particle) over its summed
    # inverse masses: a change of relative velocity or position times it is its share
    relax = np.minimum(RELAX / np.maximum(count[i], count[j]), 1.0) / w
    s = _PairScratch(i, j, wr, inv_mass, n_rows, buf)
    n = _pair_normals(s, x, buf)
    near = _step_change(i, j, v, v_old, n_rows)
    # impacts first, sequentially (bounce_sweeps), when anything bounces at all
    jb = np.zeros(p)
    if restitution > 0:
        # resting: slower than twice what the step's forces added to a sphere touching either
        # one (in a pile every grain gains g dt, though two grains falling together close at
        # none and one on the floor is held at rest); an impact only where the bounce, e
        # times the approach, would be faster than that
        limit = (RESTING_STEPS * np.maximum(near[i], near[j]) + BOUNCE_FLOOR) / restitution
        jb = bounce_sweeps_numpy(i, j, np.ascontiguousarray(n.T), w, limit, restitution, v, inv_mass)
    v0 = v.copy()
    lam, ft = _warm_start(s, v, n, pk, kept, jb, friction, walls)
    passes = _resting_passes(
        s,
        v,
        n,
        w,
        relax,
        lam,
        ft,
        jb,
        friction,
        walls,
        kept,
        np.minimum(RELAX / count[wr], 1.0) / inv_mass[wr],
        iterations,
    )
    _follow(x, v, v0, RESTING_STEPS * near, dt)
    _overlap_passes(s, x, radius, relax, OVERLAP_PASSES)
    kept.lam[pk] = lam
    kept.ft[pk] = ft.T
    kept.stamp[pk] = kept.now
    return True, passes


def _pair_normals(s: _PairScratch, x: np.ndarray, buf: Buffers) -> np.ndarray:
    """The unit normals from i to j, (3, P)."""
    p = s.i.size
    d = s.d
    # unit normals from i to j (a zero distance points up, as in the numba kernel)
    n = buf.get("n", (3, p))
    s.gather_diff(x)
    dist = np.sqrt(s.dot(d, d, np.empty(p)))
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(d, dist, out=n)
    pos = dist > 0
    if not pos.all():
        n[0, ~pos], n[1, ~pos], n[2, ~pos] = 0.0, 1.0, 0.0
    return n


def _step_change(i: np.ndarray, j: np.ndarray, v: np.ndarray, v_old: np.ndarray, n_rows: int) -> np.ndarray:
    """:func:`animsim.particle_contacts.step_kernels.step_change`: per row, the largest change
    of velocity the step made to it or to a sphere touching it."""
    dv = v - v_old
    added = np.sqrt((dv[:, 0] * dv[:, 0] + dv[:, 1] * dv[:, 1]) + dv[:, 2] * dv[:, 2])
    pair_added = np.maximum(added[i], added[j])
    near = np.zeros(n_rows)
    np.maximum.at(near, i, pair_added)
    np.maximum.at(near, j, pair_added)
    return near


def _cone(f: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """:func:`animsim.particle_contacts.step_kernels.cone` on (3, K) impulses, in place."""
    m = np.sqrt((f[0] * f[0] + f[1] * f[1]) + f[2] * f[2])
    over = m > cap
    if over.any():
        f[:, over] *= cap[over] / m[over]
    return f


def _tangential(f: np.ndarray, n: np.ndarray) -> np.ndarray:
    """f without its part along n ((3, K) both): f - (f.n) n."""
    fn = (f[0] * n[0] + f[1] * n[1]) + f[2] * n[2]
    return f - fn * n


def _warm_start(
    s: _PairScratch,
    v: np.ndarray,
    n: np.ndarray,
    pk: np.ndarray,
    kept: Kept,
    jb: np.ndarray,
    friction: float,
    walls: WallContacts,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`animsim.particle_contacts.step_kernels.warm_start`: the impulses of the last step
    applied again, in place on v (and on ``kept.wlam``, ``kept.wft``); returns the pairs' lam, ft."""
    fresh = kept.stamp[pk] == kept.now - 1
    lam = np.where(fresh, kept.lam[pk], 0.0)
    ft = _cone(_tangential(np.ascontiguousarray(kept.ft[pk].T), n), friction * (lam + jb))
    ft[:, ~fresh] = 0.0
    wn = walls.normal.T
    wft = _cone(_tangential(np.ascontiguousarray(kept.wft.T), wn), walls.friction * kept.wlam)
    kept.wft[:] = wft.T
    np.multiply(n, lam, out=s.q)
    s.q += ft
    np.multiply(wn, kept.wlam, out=s.qw)
    s.qw += wft
    s.scatter_add(v, walls=True)
    return lam, ft


def _updates(
    r: np.ndarray, n: np.ndarray, rw: np.ndarray, lam: np.ndarray, f: np.ndarray, cap_mu, extra
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`animsim.particle_contacts.step_kernels.contact_update` for (3, K) relative
    velocities r: returns the new lam and f and their changes."""
    vn = (r[0] * n[0] + r[1] * n[1]) + r[2] * n[2]
    new = np.maximum(lam - vn * rw, 0.0)
    cap = cap_mu * (new + extra)
    g = _cone(f - (r - vn * n) * rw, cap)
    g[:, (cap == 0.0) & ~f.any(axis=0)] = 0.0  # no friction to give: none
    return new, g, new - lam, g - f


def _resting_passes(
    s: _PairScratch,
    v: np.ndarray,
    n: np.ndarray,
    w: np.ndarray,
    relax: np.ndarray,
    lam: np.ndarray,
    ft: np.ndarray,
    jb: np.ndarray,
    friction: float,
    walls: WallContacts,
    kept: Kept,
    wrel: np.ndarray,
    iterations: int,
) -> int:
    """:func:`animsim.particle_contacts.step_kernels.resting_passes`, in place on v, lam, ft
    and the walls' ``kept.wlam``, ``kept.wft``; returns how many passes ran."""
    wr, wn, wu = walls.rows, walls.normal.T, walls.velocity.T
    wlam, wft = kept.wlam, np.ascontiguousarray(kept.wft.T)
    passes = 0
    for _ in range(iterations):
        passes += 1
        lam_new, ft_new, dl, df = _updates(s.gather_diff(v), n, relax, lam, ft, friction, jb)
        wlam_new, wft_new, dlw, dfw = _updates(v[wr].T - wu, wn, wrel, wlam, wft, walls.friction, 0.0)
        lam[:], ft[:], wlam[:], wft[:] = lam_new, ft_new, wlam_new, wft_new
        if dl.any() or df.any() or dlw.any() or dfw.any():  # else neither would any later pass
            np.multiply(n, dl, out=s.q)
            s.q += df
            np.multiply(wn, dlw, out=s.qw)
            s.qw += dfw
            s.scatter_add(v, walls=True)  # +J n on j, -J n on i: momentum kept
        if _below(dl, df, w, CONVERGED) and _below(dlw, dfw, s.inv_mass[wr], CONVERGED):
            break  # converged: the last pass's changes are applied, and were all tiny
    kept.wft[:] = wft.T
    return passes


def _below(dl: np.ndarray, df: np.ndarray, w: np.ndarray, tol: float) -> bool:
    """:func:`animsim.particle_contacts.step_kernels.small` for every contact (changes (K,) and
    (3, K))."""
    return bool((np.abs(dl) * w <= tol).all() and (np.abs(df) * w <= tol).all())


def _follow(x: np.ndarray, v: np.ndarray, v0: np.ndarray, allow: np.ndarray, dt: float) -> None:
    """:func:`animsim.particle_contacts.step_kernels.follow`, in place on x (and v0)."""
    d = np.subtract(v, v0, out=v0)
    m = np.sqrt((d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2])
    cut = m > allow
    s = np.full(m.shape, dt)
    s[cut] = dt * (allow[cut] / m[cut])
    d *= s[:, None]
    x += d


def _overlap_passes(
    s: _PairScratch, x: np.ndarray, radius: np.ndarray, relax: np.ndarray, iterations: int
) -> None:
    """The Jacobi passes that remove the overlaps, in place on x."""
    i, j, d = s.i, s.j, s.d
    p = i.size
    dist = np.empty(p)
    reach = radius[i] + radius[j]
    over = np.empty(p)
    c = np.empty(p)
    for _ in range(iterations):
        s.gather_diff(x)
        np.sqrt(s.dot(d, d, dist), out=dist)
        np.subtract(reach, dist, out=over)
        # the numba kernel skips a pair with over <= 0 (so a NaN one is not skipped); a skipped
        # pair's weight 0.0 leaves every sum's bits alone
        with np.errstate(divide="ignore", invalid="ignore"):
            np.multiply(over, relax, out=c)
            c[over <= 0] = 0.0
            if not c.any():  # no overlap left to remove
                break
            np.divide(d, dist, out=d)
        pos = dist > 0
        if not pos.all():
            d[0, ~pos], d[1, ~pos], d[2, ~pos] = 0.0, 1.0, 0.0
        np.multiply(d, c, out=s.q)
        s.scatter_add(x)  # the pair's centre of mass stays
