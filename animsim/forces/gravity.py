"""Uniform gravity, f = m*g (course notes: "Forces - gravity")."""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.elements import RELEASING, BuildContext, ForceElement, live_array, register
from animsim.scene import models as m
from animsim.system import State
from animsim.vec import dot3


def _kernel(  # numba: KERNEL_SIGNATURE
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    # Axis by axis, zero components skipped, as accumulate does: adding 0.0 * m to a row
    # would turn an -0.0 left by an earlier force into +0.0, and a ground scene's one
    # nonzero axis is one load, multiply-add and store a row where all three were three
    # (100,000 rows on one thread, in cache: 90 -> 50 us a call).
    for k in range(3):
        gk = fp[k]
        if gk != 0.0:
            for i in range(x.shape[0]):
                out[i, k] += gk * mass[i]


def _released_terms(  # numba: compiled by Gravity.released_numba
    x: np.ndarray, x_ref: np.ndarray, g: np.ndarray, mass: np.ndarray, out: np.ndarray
) -> None:
    """out_i = m_i g.(x_i - x_ref_i) with dot3's operations in dot3's order,
    ((d0 g0) + (d1 g1)) + d2 g2: the array Gravity.released sums, in one pass."""
    g0, g1, g2 = g[0], g[1], g[2]
    for i in range(x.shape[0]):
        r = (x[i, 0] - x_ref[i, 0]) * g0
        r = r + (x[i, 1] - x_ref[i, 1]) * g1
        r = r + (x[i, 2] - x_ref[i, 2]) * g2
        out[i] = mass[i] * r


def _released_energy(  # numba: ENERGY_SIGNATURE
    x: np.ndarray, x_ref: np.ndarray, u_ref: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> float:
    """U(x_ref) - U(x) = sum m_i g.(x_i - x_ref_i), each term as _released_terms makes it,
    summed in particle order (the watchdog's checks inside the fused chunks)."""
    g0, g1, g2 = fp[0], fp[1], fp[2]
    total = 0.0
    for i in range(x.shape[0]):
        r = (x[i, 0] - x_ref[i, 0]) * g0
        r = r + (x[i, 1] - x_ref[i, 1]) * g1
        r = r + (x[i, 2] - x_ref[i, 2]) * g2
        total += mass[i] * r
    return total


_RELEASED: list[Any] = []


class Gravity(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    #: its force reads neither positions, velocities nor time (only the masses)
    constant_force = True
    #: uniform and constant: a body at rest on a floor feels the same pull every step, so it may sleep
    lets_bodies_sleep = True
    watch_role = RELEASING
    energy_part = "gravitational"
    #: released from x - x_ref directly: its per-particle reference potential stays zero
    books_reference_potential = False

    def __init__(self, g: np.ndarray, particle_mass: np.ndarray):
        self.g = np.asarray(g, dtype=np.float64)
        self.mass = particle_mass  # rebound to the live state's masses by bind()
        self.label = f"gravity g = {self.g.tolist()} m/s^2"
        # Column by column, skipping zero components: broadcasting an (N, 1)
        # array against (3,) is several times slower than three strided axpys.
        self.axes = tuple(int(j) for j in np.flatnonzero(self.g))
        self.closed_form = {"gravity": self.g}
        self._copies: dict[int, np.ndarray] = {}  # see live_array

    def bind(self, state: State) -> None:
        self.mass = state.particle_mass

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        for j in self.axes:
            out[:, j] += self.g[j] * self.mass

    def potential(self, x: np.ndarray) -> float:
        # U = -sum m g.x (zero at the origin)
        return float(-np.dot(self.mass, x @ self.g))

    def per_particle_potential(self, x: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray:
        """Not needed for booking: gravity is released from x - x_ref directly (zeros)."""
        return np.zeros(len(x))

    def released(self, x: np.ndarray, x_ref: np.ndarray, u_ref: np.ndarray) -> float:
        """U(x_ref) - U(x) = sum m g.(x - x_ref): differences first, so 1e17 keeps its digits."""
        # dot3 and a plain sum, not np.dot / @: BLAS calls cost milliseconds when
        # its threads wait for busy cores, and the watchdog calls this every check
        return float((self.mass * dot3(x - x_ref, self.g)).sum())  # the method: np.sum adds a Python layer

    def released_numba(self, x: np.ndarray, x_ref: np.ndarray, u_ref: np.ndarray) -> float:
        """:meth:`released` with its per-particle terms from one compiled pass (the numba
        backend's watchdog): the same numbers, summed by the same ``sum``, in a third of the
        time at 1e5 particles (five NumPy passes and their temporaries otherwise)."""
        if not _RELEASED:
            import numba

            _RELEASED.append(numba.njit(cache=True)(_released_terms))
        mass = live_array(self.mass, self._copies)  # one compiled version for every mass array
        terms = np.empty(len(x))
        _RELEASED[0](x, x_ref, self.g, mass, terms)
        return float(terms.sum())

    numba_source = staticmethod(_kernel)
    numba_energy_source = staticmethod(_released_energy)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return self.g.copy(), np.zeros(0, dtype=np.int64)


@register(m.Gravity)
def build(entries: list[tuple[int, m.Gravity]], ctx: BuildContext) -> list[ForceElement]:
    return [Gravity(np.array(f.g), ctx.system.particle_mass) for _, f in entries]
