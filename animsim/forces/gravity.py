"""Uniform gravity, f = m*g (course notes: "Forces - gravity")."""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.elements import RELEASING, BuildContext, ForceElement, register
from animsim.scene import models as m
from animsim.vec import dot3


def _kernel(x, v, t, out, mass, fp, ip):  # numba: KERNEL_SIGNATURE
    g0, g1, g2 = fp[0], fp[1], fp[2]
    for i in range(x.shape[0]):
        mi = mass[i]
        out[i, 0] += g0 * mi
        out[i, 1] += g1 * mi
        out[i, 2] += g2 * mi


class Gravity(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    #: its force reads neither positions, velocities nor time (only the masses)
    constant_force = True
    watch_role = RELEASING
    energy_part = "gravitational"

    def __init__(self, g: np.ndarray, particle_mass: np.ndarray):
        self.g = np.asarray(g, dtype=np.float64)
        self.mass = particle_mass  # rebound to the live state's masses by bind()
        self.label = f"gravity g = {self.g.tolist()} m/s^2"
        # Column by column, skipping zero components: broadcasting an (N, 1)
        # array against (3,) is several times slower than three strided axpys.
        self.axes = tuple(int(j) for j in np.flatnonzero(self.g))
        self.closed_form = {"gravity": self.g}

    def bind(self, state: Any) -> None:
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

    numba_source = staticmethod(_kernel)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return self.g.copy(), np.zeros(0, dtype=np.int64)


@register(m.Gravity)
def build(entries: list[tuple[int, m.Gravity]], ctx: BuildContext) -> list[ForceElement]:
    return [Gravity(np.array(f.g), ctx.system.particle_mass) for _, f in entries]
