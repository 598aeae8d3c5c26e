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


class ConstraintGroups:
    """The springs that are constraints, sorted by colour: one contiguous slice per colour."""

    def __init__(self, index: np.ndarray, rest: np.ndarray, ks: np.ndarray, kd: np.ndarray):
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
        # the NumPy pass's gathers: flat indices of both ends' coordinates, (2, 3, m) flattened,
        # of every constraint and of each colour's
        self._flat_ends = np.concatenate([_flat_rows(self.a), _flat_rows(self.b)]).ravel()
        self._flat_ab = [
            np.concatenate([_flat_rows(self.a[sl]), _flat_rows(self.b[sl])]).ravel() for sl in self.slices
        ]
        self._rest = [self.rest[sl] for sl in self.slices]

    @property
    def count(self) -> int:
        return len(self.spring)

    def coefficients(self, w: np.ndarray, h: float, intact: Any) -> tuple[np.ndarray, ...]:
        """Per constraint, what does not change within a step: with den = (ks + kd / h)
        (w_a + w_b) + 1 / h^2 the update of :mod:`animsim.integrators.xpbd` is

            p_a -= (ca C + da g) n,   p_b += (cb C + db g) n,
            ca = w_a ks / den,  da = w_a (kd / h) / den  (cb, db with w_b),

        and for an inextensible spring ca = w_a / (w_a + w_b), da = 0. A torn spring's are 0."""
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
        return wa * ks_den, wb * ks_den, wa * kd_den, wb * kd_den

    def stacked(self, coef: tuple[np.ndarray, ...]) -> list[tuple[np.ndarray, np.ndarray]]:
        """The NumPy pass's form of :meth:`coefficients`: per colour, (ca, -cb) and (da, -db)
        as (2, 1, m) arrays, the moves of both ends in one product."""
        ca, cb, da, db = coef
        return [
            (np.stack([ca[sl], -cb[sl]])[:, None, :], np.stack([da[sl], -db[sl]])[:, None, :])
            for sl in self.slices
        ]

    def project(self, x: np.ndarray, p_old: np.ndarray, stacked: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """One Gauss-Seidel pass over the distance constraints, a colour group at a time (the
        constraints of a colour share no particle, so plain gathers and stores do).

        With d = x_a - x_b and L = |d|: n = d / L, g = d.moved / L, so each end moves by
        (c C + e g) n = ((c C + e g) / L) d, computed on d (one division per constraint).
        Both ends' coordinates are gathered at once as (2, 3, m) from the flat positions."""
        xf = _flat(x)
        if any(self.damped):  # x_a - x_b at the substep's start, for every constraint at once
            start = _flat(p_old).take(self._flat_ends).reshape(2, 3, -1)
            d_old = start[0] - start[1]
        for k, sl in enumerate(self.slices):
            ends = self._flat_ab[k]
            xab = xf.take(ends).reshape(2, 3, -1)
            d = xab[0] - xab[1]
            sq = np.einsum("ij,ij->j", d, d)
            length = np.sqrt(sq)
            if length.all():
                inv = 1.0 / length
            else:  # coincident ends: no direction, no move
                inv = np.divide(1.0, length, out=np.zeros_like(length), where=length > 0.0)
            c_ab, d_ab = stacked[k]
            f = c_ab * (length - self._rest[k])  # (ca C, -cb C)
            if self.damped[k]:
                # d.moved = d.d - d.d_old, moved = (x_a - p_a) - (x_b - p_b): one product less;
                # its cancellation costs eps |d|^2 against a term that only damps
                gdot = sq - np.einsum("ij,ij->j", d, d_old[:, sl])
                gdot *= inv
                f += d_ab * gdot
            f *= inv
            xab -= f * d
            xf[ends] = xab.reshape(-1)


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
