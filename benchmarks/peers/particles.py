"""The shared particle benchmark problem: n free particles with simple forces.

Per step (symplectic Euler, ``dt = 1e-3`` s), for each particle of mass m::

    a  = g + (-K_DRAG v + K_WIND (WIND - v)) / m    linear drag + steady wind
    v += dt a;  x += dt v
    if y < 0:  y = 0, and vy = -RESTITUTION vy when vy < 0   ground plane y = 0
    age += dt; if age > lifetime: respawn at the origin with a random velocity
               and a new lifetime ~ U(LIFETIME_RANGE)

Linear drag and wind as in Witkin, "Physically Based Modeling: Particle System
Dynamics", SIGGRAPH 2001 course notes, unary forces (viscous drag ``f = -k_d v``).
Respawns draw from a seeded generator; peers use their own generators, so
particle runs are statistically alike but not bit-for-bit comparable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PARTICLE_MASS = 1.0  # kg (not set by the brief; 1 kg keeps K_* per unit mass)
GRAVITY = (0.0, -9.81, 0.0)  # m/s^2
DT = 1e-3  # s
K_DRAG = 0.1  # N s/m, linear drag f = -K_DRAG v
K_WIND = 0.2  # N s/m, wind f = K_WIND (WIND - v)
WIND = (3.0, 0.0, 0.0)  # m/s
RESTITUTION = 0.5
LIFETIME_RANGE = (1.0, 3.0)  # s, uniform
# Spawn velocity, uniform per component: a fountain going up.
SPAWN_VXZ = (-1.0, 1.0)  # m/s, x and z
SPAWN_VY = (2.0, 5.0)  # m/s
# Initial-state construction (``flight``).
MAX_HOPS = 8  # after 8 hops at restitution 0.5 the hop speed is < 0.4 % of landing
NEWTON_ITERATIONS = 6


@dataclass(frozen=True)
class ParticleProblem:
    """Initial state of one particle run (float64), close to the steady state.

    Each particle is where its flight from the origin would have taken it by
    its age (``flight``; ages and lifetimes as in ``make_particles``), so the
    mix of airborne, grounded and respawning particles, and with it the cost
    of a step, does not drift during a benchmark.
    """

    x0: np.ndarray  # (n, 3) m
    v0: np.ndarray  # (n, 3) m/s
    age0: np.ndarray  # (n,) s
    lifetime0: np.ndarray  # (n,) s
    seed: int
    dt: float = DT

    @property
    def num_particles(self) -> int:
        return self.x0.shape[0]


def spawn_velocities(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` spawn velocities, shape (count, 3)."""
    v = rng.uniform(SPAWN_VXZ[0], SPAWN_VXZ[1], size=(count, 3))
    v[:, 1] = rng.uniform(SPAWN_VY[0], SPAWN_VY[1], size=count)
    return v


def _drag_constants() -> tuple[float, np.ndarray]:
    """``c`` and ``v_inf`` of ``dv/dt = F - c v`` (airborne motion, see ``flight``)."""
    c = (K_DRAG + K_WIND) / PARTICLE_MASS
    force = np.asarray(GRAVITY) + K_WIND * np.asarray(WIND) / PARTICLE_MASS
    return c, force / c


def _landing_time(vy: np.ndarray, c: float, vy_inf: float) -> np.ndarray:
    """Time for a hop launched up from y = 0 at ``vy`` > 0 to return to y = 0.

    Newton on ``y(t)`` from the drag-free guess ``2 vy / g``, to the right of
    the root of a concave function, so it converges monotonically.
    """
    t = 2.0 * vy / -GRAVITY[1]
    for _ in range(NEWTON_ITERATIONS):
        decay = np.exp(-c * t)
        y = vy_inf * t + (vy - vy_inf) * (1.0 - decay) / c
        t = t - y / (vy_inf + (vy - vy_inf) * decay)
    return t


def flight(v0: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity at time ``t`` after leaving the origin with ``v0``.

    Exact solution of ``dv/dt = F - c v`` (``c = (K_DRAG + K_WIND) / m``,
    ``F = g + K_WIND WIND / m``): ``v = v_inf + (v0 - v_inf) e^(-ct)``,
    ``x = v_inf t + (v0 - v_inf) (1 - e^(-ct)) / c`` with ``v_inf = F / c``.
    The frictionless ground leaves x and z alone; vertically each landing
    starts a new hop at ``RESTITUTION`` times the landing speed, and after
    ``MAX_HOPS`` hops a particle rests on the ground. Continuous time, so the
    stepped simulation differs by O(dt): a start close to the steady state.
    """
    c, v_inf = _drag_constants()
    decay = np.exp(-c * t)[:, None]
    v = v_inf + (v0 - v_inf) * decay
    x = v_inf * t[:, None] + (v0 - v_inf) * (1.0 - decay) / c
    # Vertical: walk the hops; ``left`` is the time still to go when ``hop`` starts.
    vy_inf, hop, left = v_inf[1], v0[:, 1].copy(), t.copy()
    y, vy = np.zeros_like(t), np.zeros_like(t)
    placed = np.zeros(t.shape, dtype=bool)
    for _ in range(MAX_HOPS):
        duration = _landing_time(hop, c, vy_inf)
        now = ~placed & (left < duration)
        decay = np.exp(-c * left)
        y = np.where(now, vy_inf * left + (hop - vy_inf) * (1.0 - decay) / c, y)
        vy = np.where(now, vy_inf + (hop - vy_inf) * decay, vy)
        placed |= now
        left = left - duration
        hop = -RESTITUTION * (vy_inf + (hop - vy_inf) * np.exp(-c * duration))
    x[:, 1], v[:, 1] = y, vy  # y = vy = 0 where the hops are over
    return x, v


def make_particles(n: int, seed: int = 0) -> ParticleProblem:
    """n particles spawned at the origin, each already in flight for its age.

    In the steady state the current lifetime of a particle slot is
    length-biased (density proportional to the lifetime L on LIFETIME_RANGE),
    and its age uniform in [0, L).
    """
    rng = np.random.default_rng(seed)
    lo, hi = LIFETIME_RANGE
    lifetime = np.sqrt(lo * lo + (hi * hi - lo * lo) * rng.uniform(size=n))
    age = rng.uniform(0.0, 1.0, size=n) * lifetime
    x, v = flight(spawn_velocities(rng, n), age)
    return ParticleProblem(x0=x, v0=v, age0=age, lifetime0=lifetime, seed=seed)
