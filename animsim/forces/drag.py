"""Drag: viscous (f = -k v) and quadratic (f = -1/2 rho cd A |v| v).

Viscous drag is Lander's "Other Forces" (Game Developer 1999); the quadratic
law is the aerodynamic drag of the CSE 3541 notes ("Opposing forces").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from animsim.forces.jacobian import diagonal_blocks, scaled_identity


class Drag:
    def __init__(self, k: float):
        self.k = float(k)
        self.label = f"viscous drag k = {self.k} N*s/m"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        out -= self.k * v

    def potential(self, x: np.ndarray) -> None:
        return None

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[None, sp.csr_matrix]:
        """dF/dv = -k I (Baraff and Witkin put drag in the implicit part too)."""
        return None, scaled_identity(-self.k, len(v))


class QuadraticDrag:
    def __init__(self, rho: float, cd: float, area: float):
        self.c = 0.5 * rho * cd * area
        self.label = f"quadratic drag 1/2 rho cd A = {self.c} kg/m"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        speed = np.sqrt(np.einsum("ij,ij->i", v, v))
        out -= (self.c * speed)[:, None] * v

    def potential(self, x: np.ndarray) -> None:
        return None

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[None, sp.csr_matrix]:
        """dF_i/dv_i = -c (|v| I + v v^T / |v|), 0 at rest."""
        speed = np.sqrt(np.einsum("ij,ij->i", v, v))
        with np.errstate(divide="ignore", invalid="ignore"):
            vv = np.where(speed[:, None, None] > 0, v[:, :, None] * v[:, None, :] / speed[:, None, None], 0.0)
        blocks = -self.c * (speed[:, None, None] * np.eye(3)[None] + vv)
        return None, diagonal_blocks(np.arange(len(v)), blocks, len(v))
