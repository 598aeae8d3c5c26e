"""Time 1 000 free rigid bodies with gravity and a floor: steps per second, NumPy and numba.

A 40 x 25 grid (0.5 m apart) of boxes, spheres and capsules (a third each),
tilted and spinning, dropped from heights of 0.15 m to 1.05 m onto a floor
with friction (free bodies: they land apart and do not touch each other), run with
symplectic Euler at dt = 1 ms. The first 0.5 s (a warm-up, and numba's compile)
is not timed; the timed stretch has bodies falling, landing and resting, the
body contacts busy every step. Nothing is written (no sinks). Reported per
backend: steps per second of wall time and of this process's CPU time
(``time.process_time``; run numba with ``NUMBA_NUM_THREADS=1`` so that one
core is measured), the best of ``--repeat`` runs, because a shared machine's
load only ever makes a run slower.

With ``--piled``: 1 000 boxes (0.1 m cubes) piled on the floor instead, a 10 x 10 x 10
lattice of 100 columns of ten boxes, the columns 2 cm apart, set down at rest on each other
(the body contacts hold every box up: about 4,000 contact points, each step). The same warm-up
(the first step finds the stack's impulses from nothing, then they start warm) and the same
timing; the columns stand still through it.

With ``--sleep``: each variant runs twice, as above and with ``sleep: {speed: 0.005, after: 0.5}``
(bodies at rest sleep, :mod:`animsim.bodies.sleep`), and both rates are printed. The piled
columns stand still from the start, so they fall asleep at 0.5 s, where timing starts; the
dropped bodies land by 0.5 s and rest, so they fall asleep during the timed stretch (time a
later one with ``--warmup``).

With ``--rolling M``: every dropped body gets ``rolling_friction: M`` (m; default 0, none, the
scene measured before rolling resistance existed). Only the spheres and the capsules feel it (a
box's corners get none): a ball or a capsule on its side rolling on the floor then slows at
(5/7) M g / r and stops, so with ``--sleep`` it can fall asleep; without it, it rolls on and
stays awake. The piled boxes are left as they are.

Run from the project root:
``python benchmarks/bodies.py [--steps N] [--repeat R] [--piled] [--sleep] [--warmup S] [--rolling M]``.
Goal: >= 1 000 steps/s on numba, >= 100 on NumPy (dropped); >= 1 000 on numba (piled).
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

DT = 0.001
WARMUP = 0.5  # s of simulated time before timing starts
GRID = (40, 25)  # bodies along x and z
SHAPES = (
    "{type: box, size: [0.12, 0.08, 0.1]}",
    "{type: sphere, radius: 0.06}",
    "{type: capsule, radius: 0.04, length: 0.08}",
)


#: the piled variant: boxes of this edge, this far apart sideways, PILE along x, y and z
CUBE, GAP, PILE = 0.1, 0.02, (10, 10, 10)


#: the ``sleep`` key of ``--sleep`` (the defaults)
SLEEP = "sleep: {speed: 0.005, after: 0.5}"


def _header() -> list[str]:
    return [
        "name: bodies-benchmark",
        "duration: 10.0",
        f"dt: {DT}",
        "integrator: symplectic_euler",
        "record: {every: 1000000}",
        "forces: [{type: gravity}]",
        "planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.5}]",
        "bodies:",
    ]


def piled_text() -> str:
    """The piled variant: 1 000 boxes in columns of ten, each box resting on the one below."""
    lines = _header()
    step = CUBE + GAP
    k = 0
    for i in range(PILE[0]):
        for m in range(PILE[2]):
            for j in range(PILE[1]):
                lines.append(
                    f"  - {{id: b{k}, shape: {{type: box, size: [{CUBE}, {CUBE}, {CUBE}]}}, density: 800,"
                    f" friction: 0.5, restitution: 0,"
                    f" position: [{step * i:.2f}, {CUBE * (j + 0.5)!r}, {step * m:.2f}]}}"
                )
                k += 1
    return "\n".join(lines) + "\n"


def scene_text(rolling: float = 0.0) -> str:
    lines = _header()
    key = f", rolling_friction: {rolling!r}" if rolling else ""
    k = 0
    for i in range(GRID[0]):
        for m in range(GRID[1]):
            x, y, z = 0.5 * i, 0.15 + 0.1 * ((3 * i + 7 * m) % 10), 0.5 * m
            lines.append(
                f"  - {{id: b{k}, shape: {SHAPES[k % 3]}, density: 800, position: [{x:.2f}, {y:.2f}, {z:.2f}],"
                f" orientation: {{axis: [{1 + i % 3}, 1, {m % 2}], angle: {7 * k % 90}}},"
                f" angular_velocity: [{0.2 * ((k % 5) - 2):.1f}, {0.5 * ((k % 3) - 1):.1f}, {0.2 * ((k % 7) - 3):.1f}]{key}}}"
            )
            k += 1
    return "\n".join(lines) + "\n"


def steps_per_second(
    backend: str,
    steps: int,
    piled: bool = False,
    sleep: bool = False,
    warmup: float = WARMUP,
    rolling: float = 0.0,
) -> tuple[float, float]:
    """(steps per wall-clock second, steps per CPU second) over the timed stretch."""
    warm_steps = round(warmup / DT)
    text = piled_text() if piled else scene_text(rolling)
    if sleep:
        text = text.replace("bodies:\n", SLEEP + "\nbodies:\n", 1)
    loaded = load_scene_text(text, "bodies.yaml")
    scene = with_overrides(loaded.scene, duration=(warm_steps + steps) * DT)
    compiled = compile_scene(scene, loaded.name, backend=backend)
    marks: dict[int, tuple[float, float]] = {}

    def progress(step: int, _total: int) -> None:
        if step >= warm_steps and not marks:
            marks[step] = (time.perf_counter(), time.process_time())

    result = run(compiled, [], progress=progress)
    end, end_cpu = time.perf_counter(), time.process_time()
    assert result.status == "ok", result.failure
    ((start_step, (start, start_cpu)),) = marks.items()
    taken = warm_steps + steps - start_step
    return taken / (end - start), taken / (end_cpu - start_cpu)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=500, help="timed steps per run")
    ap.add_argument("--repeat", type=int, default=1, help="runs per backend (best counts)")
    ap.add_argument("--backend", action="append", choices=("numpy", "numba"), help="default: both")
    ap.add_argument("--piled", action="store_true", help="1 000 boxes piled in columns, not dropped apart")
    ap.add_argument("--sleep", action="store_true", help="run each variant also with bodies at rest asleep")
    ap.add_argument("--warmup", type=float, default=WARMUP, help="simulated seconds before timing starts")
    ap.add_argument("--rolling", type=float, default=0.0, help="rolling_friction of the dropped bodies, m")
    args = ap.parse_args()
    what = "piled boxes" if args.piled else "bodies"
    if args.rolling and not args.piled:
        what += f", rolling_friction {args.rolling:g}"
    for backend in args.backend or ("numba", "numpy"):
        for sleep in (False, True) if args.sleep else (False,):
            rates = [
                steps_per_second(backend, args.steps, args.piled, sleep, args.warmup, args.rolling)
                for _ in range(args.repeat)
            ]
            wall, cpu = max(r[0] for r in rates), max(r[1] for r in rates)
            goal = 1000 if backend == "numba" else 100
            label = f"{what}, sleep on" if sleep else what
            print(
                f"{backend:6s} 1000 {label}: {wall:8.1f} steps/s wall, {cpu:8.1f} steps/s CPU (goal {goal})"
            )


if __name__ == "__main__":
    main()
