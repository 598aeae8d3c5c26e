"""Vortex: a swirl about an axis, f = k * (axis x r), r = x - centre.

A force field that turns particles around a line, as tornado and whirlpool
effects in particle tools do (it is the "vortex" force of Houdini's POP and
Blender's force fields, in its simplest, linear form). It is not the gradient
of a potential (its curl is 2 k axis), so it can feed energy in without bound:
the watchdog's energy test is off for it and only the finiteness test stays.

Its Jacobian dF/dx = k [axis]x is constant and skew-symmetric; implicit
Euler takes it exactly.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from animsim.elements import UNKNOWN, BuildContext, ForceElement, register
from animsim.forces.jacobian import diagonal_blocks
from animsim.scene import models as m

if TYPE_CHECKING:  # SciPy loads only when implicit Euler asks for a Jacobian
    import scipy.sparse as sp


def _kernel(
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    c0, c1, c2, a0, a1, a2, k = fp[0], fp[1], fp[2], fp[3], fp[4], fp[5], fp[6]
    for i in range(x.shape[0]):
        r0 = x[i, 0] - c0
        r1 = x[i, 1] - c1
        r2 = x[i, 2] - c2
        out[i, 0] += k * (a1 * r2 - a2 * r1)
        out[i, 1] += k * (a2 * r0 - a0 * r2)
        out[i, 2] += k * (a0 * r1 - a1 * r0)


class Vortex(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    watch_role = UNKNOWN  # not conservative, and no bound on the power it puts in
    no_closed_form = "a vortex has no closed form here"
    numba_source = staticmethod(_kernel)

    def __init__(self, center: np.ndarray, axis: np.ndarray, k: float):
        self.center = np.asarray(center, dtype=np.float64)
        self.axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
        self.k = float(k)
        self.label = f"vortex about {self.axis.tolist()} through {self.center.tolist()}, k = {self.k} N/m"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        r = x - self.center
        a0, a1, a2 = self.axis
        k = self.k
        # the cross product a x r written out, in the numba kernel's order of operations
        out[:, 0] += k * (a1 * r[:, 2] - a2 * r[:, 1])
        out[:, 1] += k * (a2 * r[:, 0] - a0 * r[:, 2])
        out[:, 2] += k * (a0 * r[:, 1] - a1 * r[:, 0])

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        # |dF/dx| = k (the skew matrix k [axis]x has eigenvalues 0, +-i k)
        k_rows += abs(self.k) * inv_mass

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[sp.csr_matrix, None]:
        """dF/dx = k [axis]x on every particle's diagonal block; nothing depends on v."""
        a0, a1, a2 = self.axis
        skew = self.k * np.array([[0.0, -a2, a1], [a2, 0.0, -a0], [-a1, a0, 0.0]])
        n = len(x)
        return diagonal_blocks(np.arange(n), np.broadcast_to(skew, (n, 3, 3)), n), None

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate([self.center, self.axis, [self.k]]), np.zeros(0, dtype=np.int64)


@register(m.Vortex)
def build(entries: list[tuple[int, m.Vortex]], ctx: BuildContext) -> list[ForceElement]:
    return [Vortex(np.array(f.center), np.array(f.axis), f.k) for _, f in entries]
