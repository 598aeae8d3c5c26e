"""xpbd's constraints, built once per run: the springs as distance constraints in colour
groups, the long range attachments of the inextensible ones, the per-substep coefficients,
and the NumPy passes that project them. The stepping is :mod:`animsim.integrators.xpbd`
(its docstring derives the update), the numba twins of the passes are
:mod:`animsim.integrators.xpbd_kernels`.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from animsim.forces.springs import Springs
from animsim.methods.xpbd import DEFAULT_SUBSTEPS  # the one place it is set
from animsim.system import System


def realised_stiffness(system: System, h: float) -> np.ndarray:
    """The stiffness each spring has as a constraint solved once per substep of h:
    ks / (1 + ks (w_a + w_b) h^2), and 1 / ((w_a + w_b) h^2) for ks = inf.

    One substep moves a lone constraint so that its stretch becomes C / (1 + ks w h^2)
    (w = w_a + w_b), and its force is then ks times that stretch: the response of a spring
    of compliance 1 / ks + w h^2 to the stretch the prediction made. Where ks w h^2 << 1
    this is ks (the springs are as stiff as written); where it is large (very stiff or
    inextensible springs) one iteration caps it at 1 / (w h^2). The watched energy of an
    xpbd run uses it: the positions a single Gauss-Seidel pass leaves keep a small stretch
    that is solver error, not elastic energy at ks (at ks 1e9 it would read as a blow-up).
    """
    inv = system.particle_inv_mass
    w = inv[system.spring_index[:, 0]] + inv[system.spring_index[:, 1]]
    ks = system.spring_ks
    cap = w * h * h
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(np.isinf(ks), np.where(cap > 0, 1.0 / cap, 0.0), ks / (1.0 + ks * cap))
    return out


def spring_energy_term(system: System, label: str, dt: float, substeps: int | None) -> Springs:
    """The force term that stands for the springs in an xpbd run of steps ``dt``: it is never
    summed into a step (the constraints move the particles), but the energy watch, ``explain``
    and the stability report read it; its stiffness is :func:`realised_stiffness`."""

    h = dt / (DEFAULT_SUBSTEPS if substeps is None else substeps)

    class ConstraintSprings(Springs):
        """Springs whose energy is at the realised stiffness, and whose stiffness rows (the
        stability report's table of every method's dt limit) are at the scene's own ks:
        the other methods would step these springs as written. Inextensible springs count
        there as nothing: no force-based method can step them."""

        def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
            realised = self.ks
            self.ks = scene_ks
            try:
                super().stiffness_rows(inv_mass, k_rows, c_rows)
            finally:
                self.ks = realised

    stiff = int(np.isinf(system.spring_ks).sum())
    scene_ks = np.where(np.isinf(system.spring_ks), 0.0, system.spring_ks)
    return ConstraintSprings(
        system.spring_index,
        system.spring_rest_length,
        realised_stiffness(system, h),
        system.spring_kd,
        system.particle_count,
        f"{label}, as xpbd distance constraints" + (f" ({stiff} inextensible)" if stiff else ""),
    )


def colour_springs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A colour per spring, greedily in spring order (the lowest colour neither end uses yet),
    so that no two springs of a colour share a particle. Made once per run; the solve then
    treats each colour as one vectorised Gauss-Seidel group.

    On a cloth this is as few colours as can be: a particle with structural, shear and bend
    springs has 12 of them, and 12 springs at one particle need 12 colours."""
    n = int(max(a.max(initial=-1), b.max(initial=-1))) + 1
    used = [0] * n  # per particle, a bit mask of the colours its springs have
    colour = [0] * len(a)
    for s, (i, j) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
        taken = used[i] | used[j]
        bit = ~taken & (taken + 1)  # the lowest clear bit
        colour[s] = bit.bit_length() - 1
        used[i] |= bit
        used[j] |= bit
    return np.array(colour, dtype=np.int64)


def _flat_rows(rows: np.ndarray) -> np.ndarray:
    """The (3, m) indices of rows' x, y and z in a C-ordered (n, 3) array seen flat: a gather
    of one-dimensional indices is several times faster in NumPy than one of whole rows."""
    return 3 * rows[None, :] + np.arange(3)[:, None]


#: a colour of the NumPy pass (ConstraintGroups.stacked): the gather into its order, its
#: size m, rest lengths, ks / den, (kd / h) / den (None: the colour does not damp),
#: (w_a, -w_b) as (2, 1, m), and the view of the start separations (None with it)
Colour = tuple[np.ndarray, int, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]


class ConstraintGroups:
    """The springs that are constraints, sorted by colour: one contiguous slice per colour."""

    def __init__(self, index: np.ndarray, rest: np.ndarray, ks: np.ndarray, kd: np.ndarray, n: int):
        active = np.flatnonzero((ks > 0) | (kd > 0))  # ks = kd = 0 is no constraint at all
        colour = colour_springs(index[active, 0], index[active, 1]) if len(active) else np.zeros(0, int)
        order = np.argsort(colour, kind="stable")
        self.spring = active[order]  # the scene's spring index of each constraint
        self.a = np.ascontiguousarray(index[self.spring, 0], dtype=np.int64)
        self.b = np.ascontiguousarray(index[self.spring, 1], dtype=np.int64)
        self.rest = rest[self.spring]
        ks = ks[self.spring]
        self.inextensible = np.isinf(ks)
        self.ks = np.where(self.inextensible, 0.0, ks)
        self.kd = np.where(self.inextensible, 0.0, kd[self.spring])
        counts = np.bincount(colour, minlength=1) if len(colour) else np.zeros(0, int)
        #: colour k is constraints bounds[k]:bounds[k + 1] (the numba kernels' form)
        self.bounds = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.slices = [slice(int(lo), int(hi)) for lo, hi in itertools.pairwise(self.bounds.tolist())]
        self.any_inextensible = bool(self.inextensible.any())
        #: per colour, whether any of its springs damps (the others skip the velocity term)
        self.damped = [bool((self.kd[sl] > 0).any()) for sl in self.slices]
        self.any_damped = any(self.damped)
        # the NumPy pass's gathers: the flat indices of both ends' coordinates, (2, 3 count),
        # colour after colour as (3, m) blocks (so each colour's start separations are one
        # contiguous block), and the colours' orders
        self._flat_ends = np.stack([_colour_blocks(end, self.slices) for end in (self.a, self.b)])
        self._orders, self._back = _colour_orders(self.a, self.b, self.slices, n)
        self._rest = [self.rest[sl] for sl in self.slices]
        #: x_a - x_b at the substep's start in those blocks, filled by each pass (damped colours)
        self._d_old = np.empty(3 * self.count)

    @property
    def count(self) -> int:
        return len(self.spring)

    def factors(self, w: np.ndarray, h: float, intact: Any) -> tuple[np.ndarray, ...]:
        """Per constraint, what does not change within a step: (w_a, w_b, k, e) with, for
        den = (ks + kd / h) (w_a + w_b) + 1 / h^2, k = ks / den and e = (kd / h) / den: the
        update of :mod:`animsim.integrators.xpbd` is

            p_a -= w_a (k C + e g) n,   p_b += w_b (k C + e g) n,

        and for an inextensible spring k = 1 / (w_a + w_b), e = 0. A torn spring's k and e
        are 0."""
        wa, wb = w[self.a], w[self.b]
        wsum = wa + wb
        kdh = self.kd / h
        den = (self.ks + kdh) * wsum + 1.0 / (h * h)
        ks_den = self.ks / den
        kd_den = kdh / den
        if self.any_inextensible:
            with np.errstate(divide="ignore", invalid="ignore"):
                ks_den = np.where(self.inextensible, np.where(wsum > 0.0, 1.0 / wsum, 0.0), ks_den)
        if intact is not None:
            live = intact[self.spring]  # a torn spring is no constraint
            ks_den = ks_den * live
            kd_den = kd_den * live
        return wa, wb, ks_den, kd_den

    @staticmethod
    def coefficients(factors: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """The numba kernels' form of :meth:`factors`: p_a -= (ca C + da g) n,
        p_b += (cb C + db g) n with ca = w_a k, da = w_a e (cb, db with w_b)."""
        wa, wb, k, e = factors
        return wa * k, wb * k, wa * e, wb * e

    def stacked(self, factors: tuple[np.ndarray, ...]) -> list[Colour]:
        """The NumPy pass's form of :meth:`factors`, per colour: its gather indices, rest
        lengths, k, e (None when the colour does not damp), (w_a, -w_b) as (2, 1, m) (the moves
        of both ends in one product) and its view of the start separations (None with e).
        Made once per set of factors, so the pass does no lookups of its own."""
        wa, wb, k, e = factors
        return [
            (
                self._orders[c],
                sl.stop - sl.start,
                self._rest[c],
                k[sl],
                e[sl] if self.damped[c] else None,
                np.stack([wa[sl], -wb[sl]])[:, None, :],
                self._d_old[3 * sl.start : 3 * sl.stop].reshape(3, -1) if self.damped[c] else None,
            )
            for c, sl in enumerate(self.slices)
        ]

    def project(self, x: np.ndarray, p_old: np.ndarray, colours: list[Colour]) -> None:
        """One Gauss-Seidel pass over the distance constraints, a colour group at a time (the
        constraints of a colour share no particle, so each is projected on its own ends only).

        Coincident ends have no direction and get no move. Rather than test every colour's
        lengths for zero (a test per colour and substep, about 6 % of the pass on a cloth),
        the pass divides by them as they are: a zero length leaves a non-finite position,
        which one sum at the end finds, and the pass is then made again with the test (it
        works on copies: ``x`` is written once, at the end). A pass that ends finite divided
        by no zero, so it is the tested pass."""
        if not colours:
            return
        xf = _flat(x)
        if self.any_damped:  # x_a - x_b at the substep's start, for every constraint at once
            start = _flat(p_old).take(self._flat_ends)
            np.subtract(start[0], start[1], out=self._d_old)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            pos = _pass(xf, colours, False)
        if not np.isfinite(np.add.reduce(pos)):  # coincident ends (or x was not finite already)
            pos = _pass(xf, colours, True)
        xf[...] = pos.take(self._back)  # back to the particles' order


def _pass(xf: np.ndarray, colours: list[Colour], guarded: bool) -> np.ndarray:
    """The colours one after the other, from the flat positions ``xf`` (left as they are);
    returns the positions moved, in the last colour's order. ``guarded``: coincident ends get
    no move (else their division is left to make a non-finite value).

    Each colour first carries the positions into its own order (one gather of all of them),
    in which its constraints' ends come first as (2, 3, m): both ends of every constraint are
    then one contiguous block, moved in place, with no store back by index.

    With d = x_a - x_b and L = |d|: n = d / L, g = d.moved / L, so each end moves by
    w (k C + e g) n = w ((k C + e g) / L) d, computed on d (one division per constraint) and
    on per-constraint numbers until the last two products, which make both ends' moves."""
    dot = np.add.reduce  # over the 3 coordinates, in the numba kernel's order: (x + y) + z
    pos = xf
    for order, m, rest, k, e, w_ab, d_old in colours:
        pos = pos.take(order)
        xab = pos[: 6 * m].reshape(2, 3, m)
        d = xab[0] - xab[1]
        sq = dot(d * d, 0)
        length = np.sqrt(sq)
        if guarded:  # coincident ends: no direction, no move
            inv = np.divide(1.0, length, out=np.zeros_like(length), where=length > 0.0)
        else:
            inv = 1.0 / length
        length -= rest
        s = k * length  # k C
        if d_old is not None and e is not None:
            # d.moved = d.d - d.d_old, moved = (x_a - p_a) - (x_b - p_b): one product less;
            # its cancellation costs eps |d|^2 against a term that only damps
            gdot = sq - dot(d * d_old, 0)
            gdot *= inv
            gdot *= e
            s += gdot  # + e g
        s *= inv
        xab -= (w_ab * s) * d
    return pos


def _colour_blocks(end: np.ndarray, slices: list[slice]) -> np.ndarray:
    """The flat coordinates of one end of every constraint, colour after colour as (3, m)."""
    return np.concatenate([_flat_rows(end[sl]).ravel() for sl in slices] + [np.zeros(0, np.int64)])


def _colour_orders(
    a: np.ndarray, b: np.ndarray, slices: list[slice], n: int
) -> tuple[list[np.ndarray], np.ndarray]:
    """The orders of the NumPy pass: per colour, the gather that carries the flat positions
    (3 n) from the previous colour's order (the particles' own before the first) into its
    own, where its constraints' a ends' coordinates come first as (3, m), then their b ends',
    then every other coordinate; and the gather back to the particles' order after the last.
    A colour shares no particle, so its block holds each coordinate once."""
    natural = np.arange(3 * n)
    where = natural  # where[i]: the position of flat coordinate i in the current order
    orders = []
    for sl in slices:
        ends = np.concatenate([_flat_rows(a[sl]).ravel(), _flat_rows(b[sl]).ravel()])
        others = np.setdiff1d(natural, ends, assume_unique=True)
        order = np.concatenate([ends, others])  # the flat coordinate at each position
        orders.append(where[order])
        where = np.empty(3 * n, dtype=np.int64)
        where[order] = natural
    return orders, where


def _flat(x: np.ndarray) -> np.ndarray:
    """``x`` (n, 3) seen as one flat array: a view, so stores through it land in ``x``."""
    if not x.flags.c_contiguous:  # reshape would copy, and the stores would be lost
        raise ValueError("xpbd works on C-ordered position arrays")
    return x.reshape(-1)


class Tethers:
    """Long range attachments for the inextensible springs (Kim, Chentanez and Mueller, "Long
    Range Attachments - A Method to Simulate Inextensible Clothing in Computer Games", SCA 2012).

    Every free particle joined to a pinned one through a path of inextensible springs may be
    at most the shortest such path's rest length from it (the geodesic distance, by
    Dijkstra's algorithm over the rest lengths). The exact solution meets these inequalities
    already, so they change nothing it allows; they only stop a single Gauss-Seidel pass per
    substep from letting a long hanging chain stretch (at 10 substeps a 32 x 32 hanging cloth
    stretched 15 % without them). Each pin's tethers move only the free ends (the pin is
    immovable), all together, one pin after the other.
    """

    def __init__(self, index: np.ndarray, rest: np.ndarray, ks: np.ndarray, pinned: np.ndarray):
        self.pins: list[tuple[int, np.ndarray, np.ndarray]] = []  # (pin, free rows, limits)
        stiff = np.flatnonzero(np.isinf(ks))
        if not len(stiff) or not pinned.any():
            return
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import dijkstra

        n = len(pinned)
        a, b = index[stiff, 0], index[stiff, 1]
        graph = csr_matrix((rest[stiff], (a, b)), shape=(n, n))
        on_graph = np.zeros(n, dtype=bool)
        on_graph[a] = on_graph[b] = True
        pins = np.flatnonzero(pinned & on_graph)
        if not len(pins):
            return
        dist = dijkstra(graph, directed=False, indices=pins)
        for k, pin in enumerate(pins):
            rows = np.flatnonzero(np.isfinite(dist[k]) & ~pinned)
            if len(rows):
                self.pins.append((int(pin), rows, dist[k, rows]))

    @property
    def count(self) -> int:
        return sum(len(rows) for _, rows, _ in self.pins)

    def flat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(pins, ptr, rows, limits): pin k's rows are rows[ptr[k]:ptr[k + 1]] (numba kernel)."""
        pins = np.array([p for p, _, _ in self.pins], dtype=np.int64)
        sizes = [len(r) for _, r, _ in self.pins]
        ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        rows = np.concatenate([r for _, r, _ in self.pins]) if self.pins else np.zeros(0, np.int64)
        limits = np.concatenate([lim for _, _, lim in self.pins]) if self.pins else np.zeros(0)
        return pins, ptr, rows.astype(np.int64), limits

    def project(self, x: np.ndarray) -> None:
        for pin, rows, limit in self.pins:
            d = x[rows] - x[pin]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            over = length > limit
            if over.any():
                r = rows[over]
                x[r] -= ((length[over] - limit[over]) / length[over])[:, None] * d[over]
