"""Point gravity toward a fixed centre: f = -m gm r / |r|^3 (negative gm repels).

With ``softening`` eps the law is Plummer's, f = -m gm r / (|r|^2 + eps^2)^(3/2),
which stays finite at the centre; eps = 0 is the exact inverse-square law.
"""

from __future__ import annotations

import numpy as np

from animsim.elements import RELEASING, BuildContext, ForceElement, register
from animsim.scene import models as m
from animsim.system import State
from animsim.vec import dot3


def _kernel(
    x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> None:
    c0, c1, c2, gm, eps2 = fp[0], fp[1], fp[2], fp[3], fp[4]
    for i in range(x.shape[0]):
        r0 = x[i, 0] - c0
        r1 = x[i, 1] - c1
        r2 = x[i, 2] - c2
        d2 = r0 * r0 + r1 * r1 + r2 * r2 + eps2
        if d2 > 0:
            s = -gm * mass[i] / (d2 * np.sqrt(d2))
            out[i, 0] += s * r0
            out[i, 1] += s * r1
            out[i, 2] += s * r2


def _released_energy(  # numba: ENERGY_SIGNATURE
    x: np.ndarray, x_ref: np.ndarray, u_ref: np.ndarray, mass: np.ndarray, fp: np.ndarray, ip: np.ndarray
) -> float:
    """U(x_ref) - U(x) = sum (u_ref_i - U_i(x)), U_i = -gm m_i / sqrt(|x_i - c|^2 + eps^2) where
    that root is positive, else 0 (per_particle_potential's terms, summed in particle order)."""
    c0, c1, c2, gm, eps2 = fp[0], fp[1], fp[2], fp[3], fp[4]
    total = 0.0
    for i in range(x.shape[0]):
        r0 = x[i, 0] - c0
        r1 = x[i, 1] - c1
        r2 = x[i, 2] - c2
        d = np.sqrt(((r0 * r0 + r1 * r1) + r2 * r2) + eps2)
        u = -gm * mass[i] / d if d > 0 else 0.0
        total += u_ref[i] - u
    return total


class Attractor(ForceElement):
    #: row i of its force reads only row i (the numba backend may evaluate it on a few rows)
    pointwise = True
    watch_role = RELEASING
    energy_part = "gravitational"

    def __init__(self, position: np.ndarray, gm: float, softening: float, particle_mass: np.ndarray):
        self.center = np.asarray(position, dtype=np.float64)
        self.gm = float(gm)
        self.eps2 = float(softening) ** 2
        self.mass = particle_mass
        self.label = f"attractor at {self.center.tolist()} gm = {self.gm} m^3/s^2"
        self.closed_form = {"attractor": (self.center, self.gm, self.eps2)}

    def bind(self, state: State) -> None:
        self.mass = state.particle_mass

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        r = x - self.center
        d2 = dot3(r, r) + self.eps2
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(d2 > 0, -self.gm * self.mass / (d2 * np.sqrt(d2)), 0.0)
        out += s[:, None] * r

    def per_particle_potential(self, x: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray:
        """U per particle at ``x`` (the rows ``idx`` of the system, or all)."""
        mass = self.mass if idx is None else self.mass[idx]
        r = x - self.center
        d = np.sqrt(np.einsum("ij,ij->i", r, r) + self.eps2)
        # invalid too: a massless slot (a dead emitter slot) at the centre is 0/0, masked out here.
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return np.where(d > 0, -self.gm * mass / d, 0.0)

    def potential(self, x: np.ndarray) -> float:
        return float(self.per_particle_potential(x).sum())

    def released(self, x: np.ndarray, x_ref: np.ndarray, u_ref: np.ndarray) -> float:
        """U(x_ref) - U(x), with U(x_ref) per particle in ``u_ref``."""
        return float(np.sum(u_ref - self.per_particle_potential(x)))

    numba_source = staticmethod(_kernel)
    numba_energy_source = staticmethod(_released_energy)

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate([self.center, [self.gm, self.eps2]]), np.zeros(0, dtype=np.int64)


@register(m.Attractor)
def build(entries: list[tuple[int, m.Attractor]], ctx: BuildContext) -> list[ForceElement]:
    return [Attractor(np.array(f.position), f.gm, f.softening, ctx.system.particle_mass) for _, f in entries]
