"""Wind: a steady part k (w - v) that pulls particles toward the wind velocity.

The course notes' smoke example: "a wind force accelerates the particles in
the direction of the wind". The turbulent part (a seeded smooth random field
of position and time) is added by :mod:`animsim.forces.turbulence` when the
scene asks for it.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from animsim.forces.jacobian import scaled_identity


class Wind:
    def __init__(self, velocity: np.ndarray, k: float):
        self.w = np.asarray(velocity, dtype=np.float64)
        self.k = float(k)
        self.label = f"wind {self.w.tolist()} m/s, k = {self.k} N*s/m"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        out += self.k * (self.w - v)

    def potential(self, x: np.ndarray) -> None:
        return None

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[None, sp.csr_matrix]:
        """The steady part k (w - v) has dF/dv = -k I."""
        return None, scaled_identity(-self.k, len(v))
