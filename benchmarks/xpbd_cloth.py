"""xpbd against implicit Euler on the stiff cloth: speed, and sag against a force-based reference.

The cloth of ``benchmarks/stiff_cloth.py`` (n x n, every spring ks = 1e5 N/m, kd = 1,
10 g particles, pinned at two corners, falling from horizontal under gravity) is stepped
at one step per 30 fps frame by ``xpbd`` (its default substeps, on NumPy and on numba) and
by ``implicit_euler`` (NumPy, with its own sparse factors). Each run's figure is simulated
seconds per second of the loop (``--cpu``: per CPU second of the whole run, for a machine
shared with other jobs), best of the repeats.

Accuracy: the sag after ``DURATION`` s (the drop of the particles' mean height) against
the reference, symplectic Euler with springs as forces at 0.5 x its largest stable step
(the stability analysis' bound), on numba. The goal is within 2 %.

``--results`` appends (or replaces) this benchmark's section of benchmarks/RESULTS.md.
Run from the project root: ``python benchmarks/xpbd_cloth.py [--n 32] [--cpu] [--results]``.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.stiff_cloth import DT_CAP, scene  # noqa: E402

DURATION = 1.0
#: the reference's step, as a share of symplectic Euler's largest stable step on the cloth
REFERENCE_SHARE = 0.5
SECTION = "## xpbd against implicit Euler on the stiff cloth"
#: the sag error the issue asks for, and the bounds of the search for a setting that meets it
GOAL = 0.02
MAX_SUBSTEPS = 2560
MIN_DT = 1e-4


def _compiled(n: int, integrator: str, dt: float, backend: str):
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    text = scene(n, integrator, dt, DURATION)  # records the first and the last step
    return compile_scene(load_scene_text(text).scene, "stiff", backend=backend)


def _run(n: int, integrator: str, dt: float, backend: str, cpu: bool) -> tuple[float, float, dict]:
    """(simulated s per wall or CPU s, sag in m, metadata) of one run."""
    from animsim.engine import run
    from animsim.record import MemorySink

    start = time.process_time()
    compiled = _compiled(n, integrator, dt, backend)
    sink = MemorySink()
    result = run(compiled, [sink])
    spent = time.process_time() - start if cpu else result.wall_time
    if result.status != "ok":
        raise RuntimeError(f"{integrator} at dt {dt:g} did not survive {DURATION} s: {result.status}")
    y = sink.positions()[:, :, 1].mean(axis=1)
    meta = dict(result.meta)
    meta["steps"] = result.steps_taken
    integ = compiled.integrator
    if hasattr(integ, "factorizations"):
        meta["solver"] = f"{integ.factorizations} factorisations ({integ.factor_kind or 'no'})"
    if hasattr(integ, "substeps"):
        meta["solver"] = f"{integ.substeps} substeps, {len(integ.groups.slices)} colour groups"
    return DURATION / spent, float(y[0] - y[-1]), meta


def reference_dt(n: int) -> float:
    from animsim.measures import stability

    limit = stability.analyse(_compiled(n, "symplectic_euler", 1e-4, "numpy")).limits["symplectic_euler"]
    steps = int(np.ceil(DURATION / (REFERENCE_SHARE * limit)))
    return DURATION / steps


def _best(
    n: int, integrator: str, dt: float, backend: str, repeat: int, cpu: bool
) -> tuple[float, float, dict]:
    """(best rate, sag, metadata) over ``repeat`` runs after a warm one (numba's cache, imports)."""
    _, sag, meta = _run(n, integrator, dt, backend, cpu)
    best = 0.0
    for _ in range(repeat):
        rate, sag, meta = _run(n, integrator, dt, backend, cpu)
        best = max(best, rate)
    return best, sag, meta


def _xpbd(substeps: int) -> str:
    return f"{{method: xpbd, substeps: {substeps}}}"


def measure(
    n: int, repeat: int, cpu: bool
) -> tuple[float, float, list[tuple[str, float, float, float, dict]]]:
    """Rows (label, dt, rate, sag error, metadata): each method at one step per frame, then
    at the cheapest setting whose sag is within GOAL of the reference (xpbd: substeps doubled
    from the default at one step per frame; implicit Euler: dt halved)."""
    ref_dt = reference_dt(n)
    _run(n, "symplectic_euler", ref_dt, "numba", cpu)  # warm: numba's cache
    ref_rate, ref_sag, ref_meta = _run(n, "symplectic_euler", ref_dt, "numba", cpu)
    # the reference itself, for its cost: the force-based answer at a stable step
    rows = [("symplectic_euler (the reference), numba", ref_dt, ref_rate, 0.0, ref_meta)]

    def add(label: str, integrator: str, dt: float, backend: str, search: bool = False) -> float:
        # the search's runs are long: one each (the caches are warm by then)
        rate, sag, meta = (
            _run(n, integrator, dt, backend, cpu)
            if search
            else _best(n, integrator, dt, backend, repeat, cpu)
        )
        err = abs(sag - ref_sag) / ref_sag
        rows.append((label, dt, rate, err, meta))
        print(f"{label}: dt {dt:.4g}, {rate:.3g} sim s per s, sag error {100 * err:.2f} %", flush=True)
        return err

    add("implicit_euler, numpy", "implicit_euler", DT_CAP, "numpy")
    add("xpbd, numpy", "xpbd", DT_CAP, "numpy")
    add("xpbd, numba", "xpbd", DT_CAP, "numba")
    substeps = 10
    while substeps < MAX_SUBSTEPS:
        substeps *= 2
        if add(f"xpbd {substeps} substeps, numba", _xpbd(substeps), DT_CAP, "numba", search=True) < GOAL:
            break
    dt = DT_CAP
    while dt > MIN_DT:
        dt /= 2
        if add("implicit_euler, numpy", "implicit_euler", dt, "numpy", search=True) < GOAL:
            break
    return ref_dt, ref_sag, rows


def section(n: int, cpu: bool, ref_dt: float, ref_sag: float, rows: list) -> str:
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    clock = "CPU" if cpu else "wall"
    implicit = next(rate for label, _, rate, _, _ in rows if label.startswith("implicit_euler"))
    lines = [
        f"{SECTION} {n} x {n} (ks = 100000 N/m on every spring, one step per 30 fps frame)",
        "",
        f"Simulated seconds per {clock} second over {DURATION:g} s (best of the repeats), and the sag "
        "after 1 s (drop of the mean height) against symplectic Euler with springs as forces at "
        f"dt {ref_dt:.3g} s on numba (sag {ref_sag:.4f} m). Commit {commit}, "
        f"{platform.machine()}, Python {platform.python_version()}.",
        "",
        f"| method | dt | simulated s per {clock} s | vs implicit_euler | sag error | solver |",
        "| --- | ---: | ---: | ---: | ---: | --- |",
    ]
    for label, dt, rate, err, meta in rows:
        lines.append(
            f"| {label} | {dt:.4g} s | {rate:.3g} | {rate / implicit:.2f}x | {100 * err:.2f} % | "
            f"{meta.get('solver', '')} |"
        )
    lines += [
        "",
        "- goals: sag within 2 % of the force-based reference; xpbd at least 10x implicit Euler "
        "(each on its fastest backend) and 2x on NumPy alone",
        "- the rows after the first four double xpbd's substeps (at one step per frame) and halve "
        "implicit Euler's dt until the sag is within 2 %: the cost of each at that accuracy (one run each)",
        "",
    ]
    return "\n".join(lines)


def write_results(text: str) -> None:
    path = ROOT / "benchmarks" / "RESULTS.md"
    old = path.read_text()
    start = old.find(SECTION)
    if start < 0:
        new = old.rstrip("\n") + "\n\n" + text
    else:
        end = old.find("\n## ", start + 1)
        new = old[:start] + text + ("" if end < 0 else "\n" + old[end + 1 :])
    path.write_text(new)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=32, help="cloth resolution n x n")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cpu", action="store_true", help="simulated s per CPU s of each run (a shared machine)")
    ap.add_argument("--results", action="store_true", help="write the section of benchmarks/RESULTS.md")
    args = ap.parse_args()
    ref_dt, ref_sag, rows = measure(args.n, args.repeat, args.cpu)
    text = section(args.n, args.cpu, ref_dt, ref_sag, rows)
    print(text)
    if args.results:
        write_results(text)


if __name__ == "__main__":
    main()
