"""Point gravity toward a fixed centre: f = -m gm r / |r|^3 (negative gm repels).

With ``softening`` eps the law is Plummer's, f = -m gm r / (|r|^2 + eps^2)^(3/2),
which stays finite at the centre; eps = 0 is the exact inverse-square law.
"""

from __future__ import annotations

import numpy as np


class Attractor:
    def __init__(self, position: np.ndarray, gm: float, softening: float, particle_mass: np.ndarray):
        self.center = np.asarray(position, dtype=np.float64)
        self.gm = float(gm)
        self.eps2 = float(softening) ** 2
        self.mass = particle_mass
        self.label = f"attractor at {self.center.tolist()} gm = {self.gm} m^3/s^2"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        r = x - self.center
        d2 = np.einsum("ij,ij->i", r, r) + self.eps2
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(d2 > 0, -self.gm * self.mass / (d2 * np.sqrt(d2)), 0.0)
        out += s[:, None] * r

    def potential(self, x: np.ndarray) -> float:
        r = x - self.center
        d = np.sqrt(np.einsum("ij,ij->i", r, r) + self.eps2)
        # invalid too: a massless slot (a dead emitter slot) at the centre is 0/0, masked out here.
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(d > 0, -self.gm * self.mass / d, 0.0)
        return float(u.sum())
