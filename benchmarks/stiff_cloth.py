"""What implicit Euler buys on a stiff cloth: simulated seconds per wall second.

A stiff cloth (every spring ks = 1e5 N/m, 10 g particles, pinned at two
corners, falling under gravity) is run by each method at the largest step it
survives: found by bisection on dt (a run of ``PROBE`` simulated seconds must
end ``ok``), capped at one animation frame (1/30 s), since an A-stable method
survives any step and nobody animates with steps longer than a frame. Then a
run of ``DURATION`` s at that step is timed (the loop only, as ``run`` reports
it), and its simulated seconds per wall second are the figure (``--cpu``: per CPU
second of the whole run, compiling included, for a machine shared with other
jobs). Implicit Euler's line names the factorisation its stiff steps used
(CHOLMOD with the ``cholmod`` extra installed, else banded Cholesky or SuperLU).

Run from the project root: ``python benchmarks/stiff_cloth.py [--n 32] [--cpu]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: the longest step tried: one frame at 30 frames/s
DT_CAP = 1.0 / 30.0
#: simulated seconds of a bisection probe, and of the timed run
PROBE = 0.3
DURATION = 1.0
KS = 1e5
KD = 1.0


def scene(n: int, integrator: str, dt: float, duration: float) -> str:
    fam = "".join(f"    {k}: {{ks: {KS}, kd: {KD}}}\n" for k in ("structural", "shear", "bend"))
    return f"""
duration: {duration!r}
dt: {dt!r}
integrator: {integrator}
record: {{every: 1000000000}}
forces: [{{type: gravity, g: [0, -9.81, 0]}}]
structures:
  - type: cloth
    id: c
    plane: xz
    size: [1, 1]
    resolution: [{n}, {n}]
    mass: 0.01
{fam}    pin: ["c[0,0]", "c[{n - 1},0]"]
"""


def _run(n: int, integrator: str, dt: float, duration: float, backend: str = "numpy"):
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.scene.loader import load_scene_text

    compiled = compile_scene(
        load_scene_text(scene(n, integrator, dt, duration)).scene, "stiff", backend=backend
    )
    return compiled, run(compiled, [])


def largest_dt(n: int, integrator: str, lo: float = 1e-6, rounds: int = 10) -> float:
    """The largest step (to 1 part in 2^rounds of the bracket) whose probe run ends ok."""
    if _run(n, integrator, DT_CAP, PROBE)[1].status == "ok":
        return DT_CAP
    hi = DT_CAP
    for _ in range(rounds):
        mid = (lo * hi) ** 0.5  # bisection in log dt
        if _run(n, integrator, mid, PROBE)[1].status == "ok":
            lo = mid
        else:
            hi = mid
    return lo


def sim_rate(
    n: int, integrator: str, dt: float, backend: str = "numpy", repeat: int = 2, cpu: bool = False
) -> tuple[float, dict]:
    """Simulated seconds per wall second at dt (``cpu``: per CPU second of the whole run), best
    of ``repeat``, and the last run's metadata."""
    best, meta = 0.0, {}
    for _ in range(repeat):
        start = time.process_time()
        compiled, result = _run(n, integrator, dt, DURATION, backend)
        spent = time.process_time() - start if cpu else result.wall_time
        if result.status != "ok":
            raise RuntimeError(f"{integrator} at dt {dt:g} did not survive {DURATION} s: {result.status}")
        best = max(best, DURATION / spent)
        meta = dict(result.meta)
        integ = compiled.integrator
        if hasattr(integ, "factorizations"):
            kind = getattr(integ, "factor_kind", None) or "no"
            meta["solver"] = (
                f", {integ.factorizations} factorisations ({kind}), {integ.cg_iterations} CG iterations"
            )
    return best, meta


def measure(
    n: int, backend: str = "numpy", repeat: int = 2, cpu: bool = False
) -> list[tuple[str, float, float, dict]]:
    out = []
    for integrator in ("symplectic_euler", "implicit_euler"):
        dt = largest_dt(n, integrator)
        # a margin below the bisection's edge, so the timed run is not on the brink
        dt_run = dt if dt == DT_CAP else 0.9 * dt
        rate, meta = sim_rate(n, integrator, dt_run, backend, repeat, cpu)
        out.append((integrator, dt_run, rate, meta))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=32, help="cloth resolution n x n")
    ap.add_argument("--backend", default="numpy")
    ap.add_argument("--cpu", action="store_true", help="simulated s per CPU s of each run (a shared machine)")
    args = ap.parse_args()
    rows = measure(args.n, args.backend, cpu=args.cpu)
    clock = "CPU" if args.cpu else "wall"
    for integrator, dt, rate, meta in rows:
        print(
            f"{integrator}: dt {dt:.4g} s, {rate:.3g} simulated s per {clock} s, "
            f"{meta.get('steps_taken')} steps{meta.get('solver', '')}"
        )
    print(f"implicit / symplectic: {rows[1][2] / rows[0][2]:.2f}x")


if __name__ == "__main__":
    main()
