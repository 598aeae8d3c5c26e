"""Uniform gravity, f = m*g (course notes: "Forces - gravity")."""

from __future__ import annotations

import numpy as np


class Gravity:
    def __init__(self, g: np.ndarray, particle_mass: np.ndarray):
        self.g = np.asarray(g, dtype=np.float64)
        self.mass = particle_mass  # shared with the System, so pool births are seen
        self.label = f"gravity g = {self.g.tolist()} m/s^2"
        # Column by column, skipping zero components: broadcasting an (N, 1)
        # array against (3,) is several times slower than three strided axpys.
        self.axes = tuple(int(j) for j in np.flatnonzero(self.g))

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        for j in self.axes:
            out[:, j] += self.g[j] * self.mass

    def potential(self, x: np.ndarray) -> float:
        # U = -sum m g.x (zero at the origin)
        return float(-np.dot(self.mass, x @ self.g))
