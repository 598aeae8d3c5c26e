"""The right-hand side every integrator sees: a(x, v, t) = F(x, v, t) / m.

It sums the scene's force elements (only those it uses) and counts
evaluations, the machine-independent cost that ``compare`` reports. Masses
are the live ones of the run's state (:meth:`bind`): pool births switch them on.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from animsim.elements import DISSIPATIVE, ELASTIC, RELEASING, ForceElement
from animsim.system import State, System

#: rows per block when a step runs a block of rows at a time (:meth:`Dynamics.blocks`): the
#: block's position, velocity, force and scratch rows (about 1.3 MB) stay in a core's cache
#: through the force sum and the update, where whole-array passes go out to memory
BLOCK_ROWS = 8192
#: particles from which a step runs in blocks (below, whole arrays fit in cache anyway)
BLOCKS_FROM = 4 * BLOCK_ROWS


def _uniform_rows(f0: np.ndarray | None, inv3: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(a block of f0's rows, the inverse mass) when every row of f0 and every entry of inv3
    are bit for bit the same (equal masses under gravity), else None: a block then starts
    from one cached block and is scaled by one number, the same values without reading two
    (N, 3) arrays from memory each step."""
    if not len(inv3):
        return None
    bits = inv3.view(np.int64)
    if not (bits == bits[0, 0]).all():
        return None
    row = np.zeros(3) if f0 is None else f0[0]
    if f0 is not None and not (f0.view(np.int64) == row.view(np.int64)).all():
        return None
    return np.tile(row, (BLOCK_ROWS, 1)), float(inv3[0, 0])


class Driver(Protocol):
    """Puts driven rows on their path (animsim.keyframes.KeyframeDrive, a layer above)."""

    def drive(self, t: float, x: np.ndarray, v: np.ndarray) -> None:
        """Write the driven rows' positions and velocities at time ``t`` into ``x`` and ``v``."""
        ...


class Dynamics:
    def __init__(self, system: System, terms: Sequence[ForceElement]):
        self.system = system
        self.terms = tuple(terms)
        self.evaluations = 0
        self.mass = system.particle_mass
        self.inv_mass = system.particle_inv_mass
        # Pinned particles are driven, never pushed: an infinite force on one
        # times its zero inverse mass would be NaN and poison a moving anchor.
        self._pinned = np.flatnonzero(system.particle_pinned)
        #: keyframe drives (animsim.keyframes.KeyframeDrive): driven rows are put on their
        #: path before every force evaluation, so springs to them see the path inside a step
        self.drivers: tuple[Driver, ...] = ()
        #: the rotational half when the scene has rigid bodies (animsim.bodies.dynamics)
        # Any: BodyDynamics is a layer above (the model may not name it, even for types) and
        # its callers use most of it (accelerations, energies, inertia, terms, rows, ...)
        self.bodies: Any = None
        self._has_pinned = bool(len(self._pinned))
        # Inverse masses repeated on three columns, so a = F/m is one same-shape
        # multiply (the same products as per column, a fraction of the calls on a
        # small scene). None while masses can change (pools: births switch them on).
        self._inv3: np.ndarray | None = self._repeat3(self.inv_mass)
        self._constants()

    def _constants(self) -> None:
        """Precompute what does not change while the masses stay (a fixed population).

        The leading terms whose force depends on nothing that steps (``constant_force``:
        gravity) are summed once, in order, from zero, exactly as :meth:`force` would;
        each evaluation then starts from that sum (the same numbers, a fraction of the
        NumPy calls of a small scene). When every term is constant, so is a = F/m.
        """
        self._f0: np.ndarray | None = None
        self._rest = self.terms
        self._a0: np.ndarray | None = None
        self._uniform: tuple[np.ndarray, float] | None = None  # see _uniform_rows
        self._uniform_known = False
        if self._inv3 is None:
            return
        lead = 0
        while lead < len(self.terms) and self.terms[lead].constant_force:
            lead += 1
        if lead == 0:
            return
        n = len(self.mass)
        f0 = np.zeros((n, 3))
        zeros = np.zeros((n, 3))
        for term in self.terms[:lead]:
            term.accumulate(zeros, zeros, 0.0, f0)
        self._f0 = f0
        self._rest = self.terms[lead:]
        if not self._rest:
            a0 = f0 * self._inv3
            if self._has_pinned:
                a0[self._pinned] = 0.0
            self._a0 = a0

    @property
    def constant_acceleration(self) -> np.ndarray | None:
        """a = F/m when every force is constant and no row is driven (what :meth:`acceleration`
        copies out at every call), else None; a new array whenever the masses are rebound."""
        return None if self.drivers else self._a0

    @property
    def blocks(self) -> bool:
        """Whether :meth:`acceleration_blocks` may evaluate a block of rows at a time: a fixed
        population of many particles, none pinned or driven, every non-constant force
        ``row_blocks``. Each value is then computed by the same operations as
        :meth:`acceleration` (row i of every term reads only row i)."""
        return (
            self._inv3 is not None
            and len(self.mass) >= BLOCKS_FROM
            and not self._has_pinned
            and not self.drivers
            and self._a0 is None
            and all(term.row_blocks for term in self._rest)
        )

    def acceleration_blocks(
        self,
        x: np.ndarray,
        v: np.ndarray,
        t: float,
        out: np.ndarray,
        then: Callable[[slice, np.ndarray], None],
        rows_per_block: int | None = None,
    ) -> None:
        """:meth:`acceleration` a block of rows at a time (only when :attr:`blocks`), calling
        ``then(rows, a_rows)`` after each block, while its rows are still in cache (the
        integrator's update). One evaluation. ``rows_per_block``: at most (and by default)
        BLOCK_ROWS."""
        self.evaluations += 1
        f0, inv3, n = self._f0, self._inv3, len(x)
        assert inv3 is not None  # blocks: a fixed population (see the property)
        if not self._uniform_known:  # once per run (_constants forgets it)
            self._uniform = _uniform_rows(f0, inv3)
            self._uniform_known = True
        uniform = self._uniform
        rows_per_block = BLOCK_ROWS if rows_per_block is None else min(rows_per_block, BLOCK_ROWS)
        for lo in range(0, n, rows_per_block):
            rows = slice(lo, min(lo + rows_per_block, n))
            a = out[rows]
            if uniform is not None:  # every row the same: the same values from cache
                a[...] = uniform[0][: len(a)]
            elif f0 is None:
                a.fill(0.0)
            else:
                a[...] = f0[rows]
            xr, vr = x[rows], v[rows]
            for term in self._rest:
                term.accumulate(xr, vr, t, a)
            if uniform is not None:
                a *= uniform[1]
            else:
                a *= inv3[rows]
            then(rows, a)

    @staticmethod
    def _repeat3(inv_mass: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.repeat(inv_mass[:, None], 3, axis=1))

    def bind(self, state: State) -> None:
        """Use ``state``'s live masses, and hand it to every element that reads state arrays."""
        self.mass = state.particle_mass
        self.inv_mass = state.particle_inv_mass
        self._inv3 = self._repeat3(self.inv_mass) if state.particle_alive is None else None
        for term in self.terms:
            term.bind(state)
        self._constants()

    def force(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        f0 = self._f0
        if f0 is None:
            out.fill(0.0)
        else:
            out[...] = f0
        for term in self._rest:
            term.accumulate(x, v, t, out)
        return out

    def acceleration(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
        """Write a = F/m into ``out``; pinned particles and dead slots get 0 (inverse mass 0)."""
        self.evaluations += 1
        for drive in self.drivers:
            drive.drive(t, x, v)
        a0 = self._a0
        if a0 is not None:  # every force constant: a = F/m was computed once
            out[...] = a0  # (a plain copy; cheaper to call than np.copyto)
            return out
        self.force(x, v, t, out)
        inv3 = self._inv3
        if inv3 is not None:
            out *= inv3
        else:
            inv_mass = self.inv_mass
            for j in range(3):  # per column: much faster than broadcasting (N, 1)
                out[:, j] *= inv_mass
        if self._has_pinned:
            out[self._pinned] = 0.0
        return out

    def potential_energy(self, x: np.ndarray) -> float:
        total = 0.0
        for term in self.terms:
            u = term.potential(x)
            if u is not None:
                total += u
        return total

    def kinetic_energy(self, v: np.ndarray) -> float:
        # Pinned particles are driven, not dynamic: they carry no kinetic energy here.
        m = np.where(self.inv_mass > 0, self.mass, 0.0)
        return float(0.5 * np.dot(m, np.einsum("ij,ij->i", v, v)))

    def energy(
        self, x: np.ndarray, v: np.ndarray, q: np.ndarray | None = None, w: np.ndarray | None = None
    ) -> float:
        """Kinetic + potential energy; with bodies (q, w given) also rotational and body-spring energy."""
        total = self.kinetic_energy(v) + self.potential_energy(x)
        if self.bodies is not None and q is not None and w is not None:
            total += self.bodies.rotational_energy(q, w) + self.bodies.potential(x, q)
        return total

    @property
    def has_damping(self) -> bool:
        return any(term.has_damping for term in self.terms)

    @property
    def conservative(self) -> bool:
        """True when every term is conservative (elastic or releasing) and none damps."""
        return all(t.watch_role in (ELASTIC, RELEASING) for t in self.terms) and not self.has_damping

    @property
    def dissipative_only(self) -> bool:
        """Every non-conservative term only removes energy."""
        return all(t.watch_role in (ELASTIC, RELEASING, DISSIPATIVE) for t in self.terms)
