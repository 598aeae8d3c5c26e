"""Peer "plain NumPy (bincount scatter)": the deliberately straightforward baseline.

Cloth: all spring forces at once (Lander 1999, Eq. 2, see ``cloth.py``), then
scattered onto particles with one ``np.bincount`` per component over the
concatenated index arrays ``[a, b]`` and forces ``[f_a, -f_a]``; symplectic
Euler. Particles: the workload of ``particles.py`` with boolean masks.
No fusion, no preallocated buffers, no tricks.
"""

from __future__ import annotations

import numpy as np

from . import PeerUnavailable, Stepper
from . import particles as P
from .cloth import ClothProblem, make_cloth
from .particles import make_particles

__all__ = ["cloth_stepper", "make_cloth", "make_particles", "particles_stepper"]

NAME = "plain_numpy"
LABEL = "plain NumPy (bincount scatter)"
AVAILABLE = True
REASON = ""


def _meta(workload: str, particles: int, **extra: object) -> dict[str, object]:
    return {
        "peer": NAME,
        "label": LABEL,
        "workload": workload,
        "dtype": "float64",
        "device": "cpu",
        "particles": particles,
        **extra,
    }


def cloth_stepper(n: int, problem: ClothProblem | None = None) -> Stepper:
    """Stepper for the n x n cloth (``problem`` overrides ``make_cloth(n)``)."""
    if not AVAILABLE:
        raise PeerUnavailable(REASON)
    prob = problem if problem is not None else make_cloth(n)
    x, v = prob.x0.copy(), prob.v0.copy()
    a, b, rest, ks, kd = prob.a, prob.b, prob.rest, prob.ks, prob.kd
    num = prob.num_particles
    scatter_idx = np.concatenate([a, b])
    inv_mass = prob.inv_mass[:, None]
    gravity = np.asarray(prob.gravity) * (prob.inv_mass > 0)[:, None]  # 0 if pinned
    dt = prob.dt

    def step() -> None:
        L = x[a] - x[b]
        Ldot = v[a] - v[b]
        length = np.sqrt((L * L).sum(axis=1))
        c = ks * (length - rest) + kd * (Ldot * L).sum(axis=1) / length
        f_a = L * (-c / length)[:, None]
        f_ab = np.concatenate([f_a, -f_a])
        force = np.stack(
            [np.bincount(scatter_idx, weights=f_ab[:, k], minlength=num) for k in range(3)],
            axis=1,
        )
        v[...] += dt * (force * inv_mass + gravity)
        x[...] += dt * v

    def state() -> dict[str, np.ndarray]:
        return {"x": x.copy(), "v": v.copy()}

    meta = _meta("cloth", num, n=prob.n, springs=prob.num_springs)
    return Stepper(step, state, meta)


def particles_stepper(n: int, seed: int = 0) -> Stepper:
    """Stepper for ``make_particles(n, seed)``; respawns draw from a seeded generator."""
    if not AVAILABLE:
        raise PeerUnavailable(REASON)
    prob = make_particles(n, seed)
    x, v = prob.x0.copy(), prob.v0.copy()
    age, life = prob.age0.copy(), prob.lifetime0.copy()
    rng = np.random.default_rng(seed + 1)  # respawn stream, apart from the initial one
    gravity, wind, dt = np.asarray(P.GRAVITY), np.asarray(P.WIND), prob.dt

    def step() -> None:
        acc = gravity + (-P.K_DRAG * v + P.K_WIND * (wind - v)) / P.PARTICLE_MASS
        v[...] += dt * acc
        x[...] += dt * v
        below = x[:, 1] < 0.0
        x[below, 1] = 0.0
        bounce = below & (v[:, 1] < 0.0)
        v[bounce, 1] *= -P.RESTITUTION
        age[...] += dt
        dead = np.flatnonzero(age > life)
        if dead.size:
            x[dead] = 0.0
            v[dead] = P.spawn_velocities(rng, dead.size)
            age[dead] = 0.0
            life[dead] = rng.uniform(*P.LIFETIME_RANGE, size=dead.size)

    def state() -> dict[str, np.ndarray]:
        return {
            "x": x.copy(),
            "v": v.copy(),
            "age": age.copy(),
            "lifetime": life.copy(),
        }

    return Stepper(step, state, _meta("particles", n))
