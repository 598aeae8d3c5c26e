"""Measure how still a pile of grains comes to rest: a seeded, jittered lattice of grains dropped
into a box of five solid box colliders under gravity, symplectic Euler, the colliders then the
particle contacts after each step (the engine's order). At the end: the largest and the median
speed, the largest overlap of two grains as a fraction of the radius, how far the grains moved
over the last 0.2 s and how many resting passes the steps of those 0.2 s ran.

Run from the project root: ``python benchmarks/pile_rest.py [--grains 10000] [--seconds 3]
[--backend numba]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from animsim.colliders import BOX, Colliders, Shape
from animsim.particle_contacts import ParticleContacts, find_pairs_numpy

G = np.array([0.0, -9.81, 0.0])


def box_walls(side: float, friction: float) -> list[Shape]:
    """A floor at y = 0 and four walls around a square of ``side`` centred on the y axis."""
    h = np.array
    return [
        Shape(BOX, h([0.0, -0.5, 0.0]), half=h([side, 0.5, side]), restitution=0.0, friction=friction),
        Shape(
            BOX, h([-side / 2 - 0.5, 2.0, 0.0]), half=h([0.5, 2.0, side]), restitution=0.0, friction=friction
        ),
        Shape(
            BOX, h([side / 2 + 0.5, 2.0, 0.0]), half=h([0.5, 2.0, side]), restitution=0.0, friction=friction
        ),
        Shape(
            BOX, h([0.0, 2.0, -side / 2 - 0.5]), half=h([side, 2.0, 0.5]), restitution=0.0, friction=friction
        ),
        Shape(
            BOX, h([0.0, 2.0, side / 2 + 0.5]), half=h([side, 2.0, 0.5]), restitution=0.0, friction=friction
        ),
    ]


def lattice(n: int, r: float, side: float, seed: int) -> np.ndarray:
    """``n`` grains on a cubic lattice 2.3 r apart that fits the box, jittered by 0.1 r."""
    per = max(int((side - 2.2 * r) / (2.3 * r)), 1)
    layers = -(-n // (per * per))
    g = np.stack(np.meshgrid(np.arange(per), np.arange(layers), np.arange(per), indexing="ij"), -1)
    g = g.reshape(-1, 3)[:n].astype(float)
    x = (g - [(per - 1) / 2, 0, (per - 1) / 2]) * 2.3 * r + [0.0, 2.0 * r, 0.0]
    return x + np.random.default_rng(seed).uniform(-0.1 * r, 0.1 * r, (n, 3))


def settle(
    n: int,
    r: float,
    seconds: float,
    backend: str,
    dt: float = 0.002,
    seed: int = 1,
    side: float | None = None,
    restitution: float = 0.1,
    friction: float = 0.4,
    wall_friction: float = 0.5,
) -> tuple[dict[str, float], np.ndarray, np.ndarray]:
    """Drop ``n`` grains of radius ``r`` into a box and run ``seconds``; returns the measures
    and the final positions and velocities."""
    side = side if side is not None else 2.3 * r * (np.sqrt(n / 12.0) + 1.0)
    x = lattice(n, r, side, seed)
    v = np.zeros((n, 3))
    radius = np.full(n, r)
    walls = Colliders(box_walls(side, wall_friction), np.ones(n), radius=radius, backend=backend)
    contacts = ParticleContacts(
        radius, restitution, friction, np.ones(n), np.ones(n, dtype=bool), np.zeros(0, np.int64), backend
    )
    contacts.colliders = walls
    steps = round(seconds / dt)
    keep_from = steps - round(0.2 / dt)
    x_then = x.copy()
    passes = []  # the resting passes each step of the last 0.2 s ran
    t_start = time.perf_counter()
    for step in range(steps):
        x_old, v_old = x.copy(), v.copy()
        v += G * dt
        x += v * dt
        st = SimpleNamespace(particle_position=x, particle_velocity=v, particle_alive=None)
        t0, t1 = step * dt, (step + 1) * dt
        walls.apply(st, x_old, v_old, t0, t1)
        contacts.apply(st, x_old, v_old, t0, t1)
        if step + 1 == keep_from:
            x_then = x.copy()
        if step + 1 > keep_from:
            passes.append(contacts.passes_last)
    wall = time.perf_counter() - t_start
    speed = np.linalg.norm(v, axis=1)
    pairs = find_pairs_numpy(x, radius, np.ones(n, dtype=bool), np.zeros(0, np.int64))
    dist = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)
    overlap = float((2 * r - dist).max()) if len(dist) else 0.0
    drift = np.linalg.norm(x - x_then, axis=1)
    measures = {
        "grains": n,
        "layers": float((x[:, 1].max() - x[:, 1].min()) / (2 * r)),
        "max_speed": float(speed.max()),
        "median_speed": float(np.median(speed)),
        "mean_speed": float(speed.mean()),
        "max_overlap_over_r": overlap / r,
        "median_drift_last_0.2s": float(np.median(drift)),
        "max_drift_last_0.2s": float(drift.max()),
        "max_passes_last_0.2s": float(max(passes, default=0)),
        "mean_passes_last_0.2s": float(np.mean(passes)) if passes else 0.0,
        "wall_s": wall,
    }
    return measures, x, v


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grains", type=int, default=10000)
    parser.add_argument("--radius", type=float, default=0.01)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--backend", choices=["numpy", "numba"], default="numba")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    out, _, _ = settle(args.grains, args.radius, args.seconds, args.backend, seed=args.seed)
    print(f"{args.backend}: " + ", ".join(f"{k} {v:.3g}" for k, v in out.items()))


if __name__ == "__main__":
    main()
