"""Penalty contact: a plane pushes back with a stiff one-sided spring.

CSE 3541 notes, "Penalty method: spring force as collision response". For a
particle at signed distance d < 0 behind the plane (unit normal n):

    f = (-stiffness * d - damping * min(v.n, 0)) n

Penalty contact lets a particle sink in a little; that is the method, and the
stiffness counts in the stability analysis like any spring's.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from animsim.forces.jacobian import diagonal_blocks


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

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[sp.csr_matrix | None, sp.csr_matrix | None]:
        """-k n n^T for particles behind the plane; -c n n^T for those also approaching it."""
        n = len(x)
        d = (x - self.p) @ self.n
        behind = np.flatnonzero(d < 0)
        if behind.size == 0:
            return None, None
        nn = np.outer(self.n, self.n)
        kx = diagonal_blocks(behind, np.broadcast_to(-self.k * nn, (behind.size, 3, 3)), n)
        kv = None
        if self.c > 0:
            closing = behind[(v[behind] @ self.n) < 0]
            if closing.size:
                kv = diagonal_blocks(closing, np.broadcast_to(-self.c * nn, (closing.size, 3, 3)), n)
        return kx, kv
