"""The shared cloth benchmark problem: an n x n mass-spring grid.

Every peer steps exactly this problem, so their results can be compared.

Springs use the damped spring force of Lander, "Devil in the Blue-Faceted
Dress: Real-time Cloth Animation", Game Developer, May 1999, Eq. 2: with
``L = x_a - x_b`` and ``Ldot = v_a - v_b``::

    f_a = -(ks (|L| - R) + kd (Ldot . L) / |L|) L / |L|,    f_b = -f_a

The integrator for all peers is symplectic (semi-implicit) Euler,
``v += dt * a; x += dt * v``; particles with inverse mass 0 are pinned and
never move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PARTICLE_MASS = 0.01  # kg
GRAVITY = (0.0, -9.81, 0.0)  # m/s^2
DT = 1e-3  # s

# (ks [N/m], kd [N s/m]) per spring family.
STRUCTURAL = (500.0, 0.5)
SHEAR = (200.0, 0.2)
BEND = (50.0, 0.05)


@dataclass(frozen=True)
class ClothProblem:
    """Initial state and constants of one cloth run (float64, C-contiguous).

    Particle ``(i, j)`` has index ``i + j * n`` and starts at
    ``(i * h, 0, j * h)`` with ``h = 1 / (n - 1)``.
    """

    n: int
    x0: np.ndarray  # (P, 3) positions, m
    v0: np.ndarray  # (P, 3) velocities, m/s
    inv_mass: np.ndarray  # (P,) 1/kg, 0 for pinned particles
    a: np.ndarray  # (S,) int64 first particle of each spring
    b: np.ndarray  # (S,) int64 second particle of each spring
    rest: np.ndarray  # (S,) rest length R, m
    ks: np.ndarray  # (S,) stiffness, N/m
    kd: np.ndarray  # (S,) damping, N s/m
    gravity: tuple[float, float, float] = GRAVITY
    dt: float = DT

    @property
    def num_particles(self) -> int:
        return self.x0.shape[0]

    @property
    def num_springs(self) -> int:
        return self.a.shape[0]


def _pairs(idx: np.ndarray, di: int, dj: int) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j) - (i + di, j + dj)`` for every pair inside the grid."""
    n = idx.shape[0]
    i0, i1 = max(0, -di), n - max(0, di)
    j0, j1 = max(0, -dj), n - max(0, dj)
    first = idx[i0:i1, j0:j1]
    second = idx[i0 + di : i1 + di, j0 + dj : j1 + dj]
    return first.ravel(), second.ravel()


def make_cloth(n: int) -> ClothProblem:
    """Build the n x n cloth in the xz plane, corners (0,0) and (n-1,0) pinned."""
    if n < 3:
        raise ValueError(f"cloth needs n >= 3 (bend springs skip one), got {n}")
    h = 1.0 / (n - 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    idx = i + j * n  # idx[i, j]
    x0 = np.zeros((n * n, 3))
    x0[idx.ravel(), 0] = i.ravel() * h
    x0[idx.ravel(), 2] = j.ravel() * h

    families = (
        (STRUCTURAL, [(1, 0), (0, 1)]),
        (SHEAR, [(1, 1), (-1, 1)]),  # (i,j)-(i+1,j+1) and (i+1,j)-(i,j+1)
        (BEND, [(2, 0), (0, 2)]),
    )
    a_parts, b_parts, ks_parts, kd_parts = [], [], [], []
    for (ks, kd), offsets in families:
        for di, dj in offsets:
            pa, pb = _pairs(idx, di, dj)
            a_parts.append(pa)
            b_parts.append(pb)
            ks_parts.append(np.full(pa.size, ks))
            kd_parts.append(np.full(pa.size, kd))
    a = np.concatenate(a_parts).astype(np.int64)
    b = np.concatenate(b_parts).astype(np.int64)
    rest = np.sqrt(((x0[a] - x0[b]) ** 2).sum(axis=1))

    inv_mass = np.full(n * n, 1.0 / PARTICLE_MASS)
    inv_mass[[idx[0, 0], idx[n - 1, 0]]] = 0.0
    return ClothProblem(
        n=n,
        x0=x0,
        v0=np.zeros_like(x0),
        inv_mass=inv_mass,
        a=a,
        b=b,
        rest=rest,
        ks=np.concatenate(ks_parts),
        kd=np.concatenate(kd_parts),
    )
