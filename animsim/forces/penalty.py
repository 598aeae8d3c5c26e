"""Penalty contact: a plane pushes back with a stiff one-sided spring.

CSE 3541 notes, "Penalty method: spring force as collision response". For a
particle at signed distance d < 0 behind the plane (unit normal n):

    f = (-stiffness * d - damping * min(v.n, 0)) n

Penalty contact lets a particle sink in a little; that is the method, and the
stiffness counts in the stability analysis like any spring's.
"""

from __future__ import annotations

import numpy as np


class PenaltyPlane:
    def __init__(self, point: np.ndarray, normal: np.ndarray, stiffness: float, damping: float):
        self.p = np.asarray(point, dtype=np.float64)
        self.n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
        self.k = float(stiffness)
        self.c = float(damping)
        self.label = f"penalty plane through {self.p.tolist()} normal {self.n.tolist()} k = {self.k} N/m"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        d = (x - self.p) @ self.n
        push = np.where(d < 0, -self.k * d, 0.0)
        if self.c > 0:
            vn = v @ self.n
            push -= np.where((d < 0) & (vn < 0), self.c * vn, 0.0)
        out += push[:, None] * self.n

    def potential(self, x: np.ndarray) -> float:
        d = (x - self.p) @ self.n
        return float(0.5 * self.k * np.sum(np.minimum(d, 0.0) ** 2))
