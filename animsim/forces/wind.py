"""Wind: a steady part k (w - v) that pulls particles toward the wind velocity.

The course notes' smoke example: "a wind force accelerates the particles in
the direction of the wind". The turbulent part (a seeded smooth random field
of position and time) is added by :mod:`animsim.forces.turbulence` when the
scene asks for it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from animsim.elements import INJECTING, BuildContext, ForceElement, register
from animsim.forces.jacobian import scaled_identity
from animsim.forces.turbulence import Turbulence
from animsim.scene import models as m

if TYPE_CHECKING:  # SciPy loads only when implicit Euler asks for a Jacobian
    import scipy.sparse as sp


def _kernel(
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    k, w0, w1, w2 = fp[0], fp[1], fp[2], fp[3]
    for i in range(x.shape[0]):
        out[i, 0] += k * (w0 - v[i, 0])
        out[i, 1] += k * (w1 - v[i, 1])
        out[i, 2] += k * (w2 - v[i, 2])


#: particles from which the wind is summed column by column into a buffer (below: one expression)
COLUMNS_FROM = 256


class Wind(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    #: accumulate on row slices gives those rows of the whole evaluation (see Drag)
    row_blocks = True
    #: the steady part k (w - v) is the same push on a body standing still, step after step (the
    #: turbulent part is its own element, which keeps bodies awake), so a body may sleep under it
    lets_bodies_sleep = True
    watch_role = INJECTING
    has_damping = True

    def __init__(self, velocity: np.ndarray, k: float):
        self.w = np.asarray(velocity, dtype=np.float64)
        self.k = float(k)
        self.label = f"wind {self.w.tolist()} m/s, k = {self.k} N*s/m"
        # a linear drag toward w: the closed form of drag with a constant push k w
        self.closed_form = {"drag": self.k, "push": self.k * self.w}
        #: the most power the wind can put into one particle: max over v of k (w - v).v = k |w|^2 / 4
        self.max_power_per_particle = 0.25 * self.k * float(np.dot(self.w, self.w))

    _scratch: np.ndarray | None = None

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        # out += k (w - v), without temporaries: w - v column by column (a (3,) vector
        # broadcast against (N, 3) runs NumPy's inner loop three elements at a time),
        # then the same products and sums in place
        if len(v) < COLUMNS_FROM:  # a small scene: fewer NumPy calls matter more
            out += self.k * (self.w - v)
            return
        buf = self._scratch
        if buf is None or len(buf) < len(v) or buf.shape[1:] != v.shape[1:]:
            buf = self._scratch = np.empty(v.shape)
        buf = buf[: len(v)]  # a block of rows uses the front of the buffer
        for j in range(3):
            np.subtract(self.w[j], v[:, j], out=buf[:, j])
        buf *= self.k
        out += buf

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        c_rows += self.k * inv_mass

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[None, sp.csr_matrix]:
        """The steady part k (w - v) has dF/dv = -k I."""
        return None, scaled_identity(-self.k, len(v))

    numba_source = staticmethod(_kernel)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate([[self.k], self.w]), np.zeros(0, dtype=np.int64)


@register(m.Wind)
def build(entries: list[tuple[int, m.Wind]], ctx: BuildContext) -> list[ForceElement]:
    out: list[ForceElement] = []
    for index, f in entries:
        out.append(Wind(np.array(f.velocity), f.k))
        if f.turbulence > 0:
            # the stream is the wind's position among the scene's forces, so two winds differ
            out.append(Turbulence.from_scene(f, ctx.seed, ctx.system.particle_mass, stream=index))
    return out
