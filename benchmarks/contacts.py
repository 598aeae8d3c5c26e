"""Time particle contacts: about 100,000 grains in a box, steps per second per backend.

A lattice of 47 x 47 x 47 = 103,823 particles (a soft_box structure with no
springs) with particle_collisions, radius just over half the spacing (so each grain
touches its six lattice neighbours from the start: about 300,000 contacts), falls
under gravity into a box of five solid box colliders slightly wider than the
lattice; the grains touch their neighbours from the first step, so every step
finds and resolves a few hundred thousand contacts. One short untimed run first
(numba compiles its kernels on a machine's first run and caches them), then
the loop's own wall time over ``--steps`` steps, best of ``--repeat`` runs.

The first steps are the lattice falling as one: touching neighbours that
neither approach nor part, so the impulse passes end early and the list of
neighbours is hardly ever rebuilt. ``--after N`` times steps N to N + steps
instead (the difference of a run of N + steps and one of N steps): from step
about 35 the bottom layer lands and the pile is pressed together, which costs
every pass and rebuilds the neighbour list every few steps.

Run from the project root: ``python benchmarks/contacts.py [--steps N] [--after N] [--backend numba]``.
Goals: 20 steps/s with numba, 5 with NumPy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from animsim.compile import compile_scene, with_overrides
from animsim.engine import run
from animsim.scene.loader import load_scene_text

N_SIDE = 47
SPACING = 0.05
SIDE = SPACING * (N_SIDE - 1)  # 2.3 m
DT = 0.002

SCENE = f"""
name: contacts-benchmark
duration: 1.0
dt: {DT}
record: {{every: 1000000}}
structures:
  - type: soft_box
    id: grains
    center: [0, {SIDE / 2 + 0.05}, 0]
    size: [{SIDE}, {SIDE}, {SIDE}]
    resolution: [{N_SIDE}, {N_SIDE}, {N_SIDE}]
    mass: 0.001
particle_collisions: {{radius: {0.51 * SPACING}, restitution: 0.1, friction: 0.3}}
colliders:
  - {{type: box, center: [0, -0.1, 0], size: [2.6, 0.2, 2.6], restitution: 0, friction: 0.5}}
  - {{type: box, center: [-1.25, 1.5, 0], size: [0.1, 3.0, 2.6], restitution: 0}}
  - {{type: box, center: [1.25, 1.5, 0], size: [0.1, 3.0, 2.6], restitution: 0}}
  - {{type: box, center: [0, 1.5, -1.25], size: [2.6, 3.0, 0.1], restitution: 0}}
  - {{type: box, center: [0, 1.5, 1.25], size: [2.6, 3.0, 0.1], restitution: 0}}
forces:
  - {{type: gravity}}
"""


def _timed(scene, backend: str, steps: int) -> tuple[float, float, int]:
    """(loop wall seconds, process CPU seconds, particles) of a run of ``steps`` steps."""
    import time

    if steps == 0:
        return 0.0, 0.0, 0
    compiled = compile_scene(with_overrides(scene, duration=steps * DT), "bench", backend=backend)
    cpu0 = time.process_time()
    result = run(compiled)
    cpu = time.process_time() - cpu0
    assert result.steps_taken == steps, result.status
    return result.wall_time, cpu, compiled.system.particle_count


def steps_per_second(backend: str, steps: int, repeat: int, after: int = 0) -> tuple[float, float, int]:
    """(steps per wall-clock second, steps per CPU second of this process, particles), over
    steps ``after`` to ``after + steps``.

    On a machine shared with other jobs the wall clock counts their time too; the
    process's CPU time does not (with one thread, it is the quiet machine's wall time).
    """
    scene = load_scene_text(SCENE).scene
    warm = compile_scene(with_overrides(scene, duration=2 * DT), "bench", backend=backend)
    run(warm)  # compile or load the kernels: not timed
    best = best_cpu = 0.0
    particles = 0
    for _ in range(repeat):
        wall, cpu, particles = _timed(scene, backend, after + steps)
        wall0, cpu0, _ = _timed(scene, backend, after)
        best = max(best, steps / (wall - wall0))
        best_cpu = max(best_cpu, steps / (cpu - cpu0))
    return best, best_cpu, particles


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--after", type=int, default=0, help="untimed steps before the timed ones")
    parser.add_argument("--backend", choices=["numpy", "numba", "both"], default="both")
    args = parser.parse_args()
    for backend in ("numpy", "numba") if args.backend == "both" else (args.backend,):
        rate, cpu_rate, n = steps_per_second(backend, args.steps, args.repeat, args.after)
        goal = 20 if backend == "numba" else 5
        window = f", steps {args.after}-{args.after + args.steps}" if args.after else ""
        print(
            f"contacts {backend}: {n} particles{window}, {rate:.2f} steps/s wall, "
            f"{cpu_rate:.2f} steps per CPU second (goal {goal})"
        )


if __name__ == "__main__":
    main()
