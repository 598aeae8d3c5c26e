"""Drag: viscous (f = -k v) and quadratic (f = -1/2 rho cd A |v| v).

Viscous drag is Lander's "Other Forces" (Game Developer 1999); the quadratic
law is the aerodynamic drag of the CSE 3541 notes ("Opposing forces").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from animsim.elements import DISSIPATIVE, BuildContext, ForceElement, register
from animsim.forces.jacobian import diagonal_blocks, scaled_identity
from animsim.scene import models as m
from animsim.vec import dot3

if TYPE_CHECKING:  # SciPy loads only when implicit Euler asks for a Jacobian
    import scipy.sparse as sp


def _drag_kernel(
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    k = fp[0]
    for i in range(x.shape[0]):
        out[i, 0] -= k * v[i, 0]
        out[i, 1] -= k * v[i, 1]
        out[i, 2] -= k * v[i, 2]


def _quadratic_kernel(
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    c = fp[0]
    for i in range(x.shape[0]):
        s = c * np.sqrt(v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
        out[i, 0] -= s * v[i, 0]
        out[i, 1] -= s * v[i, 1]
        out[i, 2] -= s * v[i, 2]


class Drag(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    #: accumulate on row slices x[lo:hi], v[lo:hi], out[lo:hi] gives those rows of the whole
    #: evaluation (it reads no per-particle array of its own), so it may run a block at a time
    row_blocks = True
    #: zero on a body at rest, so it may sleep
    lets_bodies_sleep = True
    watch_role = DISSIPATIVE
    has_damping = True

    def __init__(self, k: float):
        self.k = float(k)
        self.label = f"viscous drag k = {self.k} N*s/m"
        self.closed_form = {"drag": self.k}

    _scratch: np.ndarray | None = None

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        buf = self._scratch  # k v into a buffer of our own: no (N, 3) temporary per evaluation
        if buf is None or len(buf) < len(v) or buf.shape[1:] != v.shape[1:]:
            buf = self._scratch = np.empty(v.shape)
        buf = buf[: len(v)]  # a block of rows uses the front of the buffer
        np.multiply(v, self.k, out=buf)
        out -= buf

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        c_rows += self.k * inv_mass

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[None, sp.csr_matrix]:
        """dF/dv = -k I (Baraff and Witkin put drag in the implicit part too)."""
        return None, scaled_identity(-self.k, len(v))

    numba_source = staticmethod(_drag_kernel)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([self.k]), np.zeros(0, dtype=np.int64)


class QuadraticDrag(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    #: zero on a body at rest, so it may sleep
    lets_bodies_sleep = True
    watch_role = DISSIPATIVE
    has_damping = True

    no_closed_form = "quadratic drag has no closed form in more than one dimension"
    stability_caveat = "quadratic drag damps in proportion to speed and is not counted"

    def __init__(self, rho: float, cd: float, area: float):
        self.c = 0.5 * rho * cd * area
        self.label = f"quadratic drag 1/2 rho cd A = {self.c} kg/m"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        speed = np.sqrt(dot3(v, v))
        out -= (self.c * speed)[:, None] * v

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[None, sp.csr_matrix]:
        """dF_i/dv_i = -c (|v| I + v v^T / |v|), 0 at rest."""
        speed = np.sqrt(np.einsum("ij,ij->i", v, v))
        with np.errstate(divide="ignore", invalid="ignore"):
            vv = np.where(speed[:, None, None] > 0, v[:, :, None] * v[:, None, :] / speed[:, None, None], 0.0)
        blocks = -self.c * (speed[:, None, None] * np.eye(3)[None] + vv)
        return None, diagonal_blocks(np.arange(len(v)), blocks, len(v))

    numba_source = staticmethod(_quadratic_kernel)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([self.c]), np.zeros(0, dtype=np.int64)


@register(m.Drag)
def build_drag(entries: list[tuple[int, m.Drag]], ctx: BuildContext) -> list[ForceElement]:
    return [Drag(f.k) for _, f in entries]


@register(m.QuadraticDrag)
def build_quadratic(entries: list[tuple[int, m.QuadraticDrag]], ctx: BuildContext) -> list[ForceElement]:
    return [QuadraticDrag(f.rho, f.cd, f.area) for _, f in entries]
