"""CPU-time check of the "where users wait" goals, one workload at a time.

A shared machine's wall clock swings from minute to minute; this process's CPU
time (``time.process_time``, numba on one thread) is steadier, so before/after
comparisons of one change use it. The workloads are those of
:mod:`benchmarks.suite` (the tiny scenes' whole ``run()``, the particles' NumPy
contender beside the plain-NumPy peer) and :mod:`benchmarks.fountain`. Wall time
is printed beside every CPU figure. Run from the project root::

    NUMBA_NUM_THREADS=1 python -m benchmarks.cpu_goals tiny
    NUMBA_NUM_THREADS=1 python -m benchmarks.cpu_goals tiny numba
    python -m benchmarks.cpu_goals particles 100000 1000000
    python -m benchmarks.cpu_goals fountain numba

Speed is measured here and never asserted in a test.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def best(fn: Callable[[], None], repeat: int) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of the fastest of ``repeat`` calls."""
    cpu, wall = [], []
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return min(cpu), min(wall)


def tiny(backend: str = "numpy", repeat: int = 5) -> None:
    from animsim.engine import run
    from benchmarks.suite import TINY_STEPS, NullSink, _compile, tiny_scene

    for spring in (False, True):
        for integrator in ("symplectic_euler", "rk4"):
            compiled = _compile(tiny_scene(integrator, spring), backend)
            run(compiled, [NullSink()])
            cpu, wall = best(lambda c=compiled: run(c, [NullSink()]), repeat)
            what = "spring pendulum" if spring else "1 particle"
            print(
                f"tiny, {backend}, {what}, {integrator}: {cpu / TINY_STEPS * 1e6:.2f} us/step CPU "
                f"({wall / TINY_STEPS * 1e6:.2f} wall)"
            )


def particles(n: int, repeat: int = 3) -> None:
    from benchmarks.peers import particles as P
    from benchmarks.peers import plain_numpy
    from benchmarks.suite import _compile, numpy_contender, particles_scene

    prob = P.make_particles(n, 0)
    compiled = _compile(particles_scene(n))
    compiled.initial.particle_position[:] = prob.x0
    compiled.initial.particle_velocity[:] = prob.v0
    ours = numpy_contender(compiled, "animsim numpy")
    peer = plain_numpy.particles_stepper(n)
    calls = max(1, int(2e7 // n) // ours.steps_per_call)
    steps = calls * ours.steps_per_call
    ours.call()
    peer.step()

    def run_ours() -> None:
        for _ in range(calls):
            ours.call()

    def run_peer() -> None:
        for _ in range(steps):
            peer.step()

    c_ours, w_ours = best(run_ours, repeat)
    c_peer, w_peer = best(run_peer, repeat)
    rate = n * steps / 1e6
    print(
        f"particles {n:.0e}: animsim {rate / c_ours:.2f} M particle-steps/s CPU ({rate / w_ours:.2f} wall), "
        f"plain peer {rate / c_peer:.2f} ({rate / w_peer:.2f}); "
        f"ratio {c_peer / c_ours:.2f}x CPU ({w_peer / w_ours:.2f}x wall)"
    )


def fountain(backend: str, steps: int = 300, repeat: int = 2) -> None:
    from benchmarks import fountain as F

    for ground in (True, False):
        cpu = max(F.steps_per_second(steps, ground, backend, cpu=True)[0] for _ in range(repeat))
        wall = max(F.steps_per_second(steps, ground, backend)[0] for _ in range(repeat))
        print(
            f"fountain {F.PARTICLES:.0e}, {backend}, {'with' if ground else 'without'} ground plane: "
            f"{cpu:.0f} steps/s CPU ({wall:.0f} wall, separate runs)"
        )


def main(argv: list[str]) -> int:
    what = argv[0] if argv else "tiny"
    if what == "tiny":
        tiny(argv[1] if len(argv) > 1 else "numpy")
    elif what == "particles":
        for n in map(int, argv[1:] or ["100000", "1000000"]):
            particles(n)
    elif what == "fountain":
        fountain(argv[1] if len(argv) > 1 else "numba")
    else:
        print(f"unknown workload {what!r} (tiny, particles, fountain)", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
