"""Time a 100 000-particle fountain on the NumPy path: steps per second.

The emitter fills its pool of 100 000 slots (50 000 births/s, lifetimes of
2 s +- 0.1 s), particles fly up, fall back and bounce on a ground plane with
friction. The warm-up (the pool filling) is not timed: only the steady state,
with about 100 000 alive particles, births and deaths every step, is.
Nothing is written (no sinks), so this is the stepping cost alone.

Two configurations are timed: the fountain as described, and the same
without its ground plane, which separates the cost of plane collisions (about
half the drops rest on the ground, and each is collided every step) from that
of the emitter, forces and integrator. Each is the best of ``--repeat`` runs,
because a shared machine's load only ever makes a run slower.

Run from the project root: ``python benchmarks/fountain.py [--steps N] [--backend numba] [--cpu]``
(``NUMBA_NUM_THREADS=1`` for one thread).
Target (issue 3): >= 200 steps/s.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from animsim.compile import compile_scene, with_overrides
from animsim.engine import run
from animsim.scene.loader import load_scene_text

PARTICLES = 100_000
RATE = 50_000  # births/s; with 2 s lifetimes the pool is full in steady state
DT = 0.005
WARMUP = 2.5  # s of simulated time before timing starts (the pool is full by then)

SCENE = f"""
name: fountain-benchmark
duration: 10.0
dt: {DT}
seed: 1
record: {{every: 1000000}}
forces:
  - {{type: gravity, g: [0, -9.81, 0]}}
PLANES_HERE
emitters:
  - name: fountain
    rate: {RATE}
    shape: {{type: disc, center: [0, 0.05, 0], normal: [0, 1, 0], radius: 0.05}}
    velocity: {{mean: [0, 6, 0], spread: 0.6}}
    lifetime: {{mean: 2.0, spread: 0.1}}
    mass: 0.001
    max_particles: {PARTICLES}
"""


GROUND = """planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.4, friction: 0.2}
"""


def steps_per_second(
    steps: int, ground: bool, backend: str = "numpy", cpu: bool = False, threads: int | None = None
) -> tuple[float, dict]:
    """Steady-state steps/s of the fountain on ``backend`` (wall clock, or this process's CPU
    time with ``cpu``) with numba's thread count ``threads`` (None: numba's default), and
    the run's emitter summary."""
    warm_steps = round(WARMUP / DT)
    loaded = load_scene_text(SCENE.replace("PLANES_HERE", GROUND if ground else ""))
    scene = with_overrides(loaded.scene, duration=(warm_steps + steps) * DT)
    compiled = compile_scene(scene, loaded.name, backend=backend, threads=threads)
    clock = time.process_time if cpu else time.perf_counter
    marks: dict[int, float] = {}

    def progress(step: int, _total: int) -> None:
        # the loop reports once per stretch of steps (a watchdog stride): the clock starts
        # at the first report at or after the warm-up
        if step >= warm_steps and not marks:
            marks[step] = clock()

    result = run(compiled, [], progress=progress)
    end = clock()
    ((start, t0),) = marks.items()
    return (warm_steps + steps - start) / (end - t0), result.meta["emitters"]


def stepper_steps_per_second(steps: int, ground: bool, threads: int | None = None) -> float:
    """Steady-state steps/s of the numba stepper alone on the fountain (wall clock): the
    physics and the births of each step, with none of the run's watchdog around them (no
    checks, no energy books, no copies kept for a replay, no recording or progress). Not a
    way to run a scene: a ceiling on what any change outside the stepper could give a run."""
    from animsim.backends import numba_threads
    from animsim.steppers import start

    warm_steps = round(WARMUP / DT)
    loaded = load_scene_text(SCENE.replace("PLANES_HERE", GROUND if ground else ""))
    scene = with_overrides(loaded.scene, duration=(warm_steps + steps) * DT)
    compiled = compile_scene(scene, loaded.name, backend="numba", threads=threads)
    with numba_threads(compiled):
        state, stepper, _ = start(compiled, None)
        k, failure, failed = stepper.advance(state, 0, warm_steps)
        t0 = time.perf_counter()
        end, failure, failed = stepper.advance(state, k, warm_steps + steps)
        seconds = time.perf_counter() - t0
    if failure is not None or failed or end != warm_steps + steps:
        raise RuntimeError(f"the fountain's stepper stopped at step {end}: {failure}")
    return steps / seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=400, help="timed steps after the warm-up")
    ap.add_argument("--repeat", type=int, default=3, help="runs per configuration; the best counts")
    ap.add_argument("--backend", default="numpy", choices=("numpy", "numba"))
    ap.add_argument(
        "--cpu", action="store_true", help="CPU time of this process instead of wall time (a shared machine)"
    )
    args = ap.parse_args()
    for ground, label in ((True, "with ground plane"), (False, "without ground plane")):
        runs = [steps_per_second(args.steps, ground, args.backend, args.cpu) for _ in range(args.repeat)]
        best, summary = max(runs, key=lambda r: r[0])
        alive = summary["per_emitter"]["fountain"]["alive"]
        print(
            f"fountain {label}: {best:.0f} steps/s (best of {args.repeat}; all: "
            f"{', '.join(f'{r[0]:.0f}' for r in runs)}), {alive} alive of {PARTICLES} slots, "
            f"symplectic_euler, dt {DT}, {args.steps} steps timed after {round(WARMUP / DT)} warm-up steps, "
            f"{args.backend}, {'CPU' if args.cpu else 'wall'} time"
        )


if __name__ == "__main__":
    main()
