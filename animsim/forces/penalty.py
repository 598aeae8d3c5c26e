"""Penalty contact: a plane pushes back with a stiff one-sided spring.

CSE 3541 notes, "Penalty method: spring force as collision response". For a
particle at signed distance d < 0 behind the plane (unit normal n):

    f = (-stiffness * d - damping * min(v.n, 0)) n

Penalty contact lets a particle sink in a little; that is the method, and the
stiffness counts in the stability analysis like any spring's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from animsim.elements import ELASTIC, ForceElement
from animsim.forces.jacobian import diagonal_blocks
from animsim.vec import dot3

if TYPE_CHECKING:  # SciPy loads only when implicit Euler asks for a Jacobian
    import scipy.sparse as sp


def _kernel(
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    p0, p1, p2, n0, n1, n2, k, c = fp[0], fp[1], fp[2], fp[3], fp[4], fp[5], fp[6], fp[7]
    for i in range(x.shape[0]):
        d = (x[i, 0] - p0) * n0 + (x[i, 1] - p1) * n1 + (x[i, 2] - p2) * n2
        if d < 0:
            push = -k * d
            if c > 0:
                vn = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
                if vn < 0:
                    push -= c * vn
            out[i, 0] += push * n0
            out[i, 1] += push * n1
            out[i, 2] += push * n2


def _energy(  # numba: ENERGY_SIGNATURE
    x: np.ndarray, x_ref: np.ndarray, u_ref: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> float:
    """The potential 1/2 k sum min(d_i, 0)^2, d_i = (x_i - p).n (PenaltyPlane.potential)."""
    p0, p1, p2, n0, n1, n2 = fp[0], fp[1], fp[2], fp[3], fp[4], fp[5]
    k: float = fp[6]
    total = 0.0
    for i in range(x.shape[0]):
        d = (x[i, 0] - p0) * n0 + (x[i, 1] - p1) * n1 + (x[i, 2] - p2) * n2
        if not d >= 0.0:  # NaN too, as np.minimum(d, 0) keeps it
            total += d * d
    return 0.5 * k * total


class PenaltyPlane(ForceElement):
    """Built by the plane module (:mod:`animsim.collisions.stage`) for planes with ``response: penalty``."""

    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True

    watch_role = ELASTIC
    no_closed_form = "it has planes (collisions have no closed form here)"

    def __init__(self, point: np.ndarray, normal: np.ndarray, stiffness: float, damping: float):
        self.p = np.asarray(point, dtype=np.float64)
        self.n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
        self.k = float(stiffness)
        self.c = float(damping)
        self.label = f"penalty plane through {self.p.tolist()} normal {self.n.tolist()} k = {self.k} N/m"
        self.has_damping = self.c > 0
        self.contact_stiffness = self.k

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        # Any particle may touch the plane: its stiffness and damping count on every row.
        k_rows += self.k * inv_mass
        c_rows += self.c * inv_mass

    numba_source = staticmethod(_kernel)
    numba_energy_source = staticmethod(_energy)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate([self.p, self.n, [self.k, self.c]]), np.zeros(0, dtype=np.int64)

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        d = dot3(x - self.p, self.n)
        push = np.where(d < 0, -self.k * d, 0.0)
        if self.c > 0:
            vn = dot3(v, self.n)
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
