"""xpbd against implicit Euler on the stiff cloth: speed, and sag against a force-based reference.

Two 32 x 32 cloths (every structural, shear and bend spring ks = 1e5 N/m, 10 g particles,
pinned at two corners of one edge, 1 s under gravity), each stepped at one step per 30 fps
frame by ``xpbd`` (its default substeps, on NumPy and on numba) and by ``implicit_euler``
(NumPy, with its own sparse factors):

- swinging: the cloth of ``benchmarks/stiff_cloth.py``, falling from horizontal, kd = 1 N s/m
  (about 1.6 % of a spring's critical damping): at 1 s it is halfway through the swing of a
  stiff plate about its pinned edge;
- hanging: the same cloth hanging in its own plane from its two top corners, kd = 100 N s/m,
  so that it has settled by 1 s (its sag is within 1 % of its final one from 0.5 s on).

The sag is the drop of the particles' mean height after ``DURATION`` s, and its error is
against the reference: symplectic Euler with springs as forces at 0.5 x its largest stable
step (the stability analysis' bound), on numba. The goal is within 2 %. After the rows at one
step per frame, xpbd's substeps are doubled and implicit Euler's step halved until the sag
is within 2 %: the cost of each at that accuracy.

Speed is simulated seconds per CPU second (the machine is shared, so CPU, not wall): of
the stepping (between the first and the last frame, the figure the goals are judged on), and
of the whole run (the scene's compilation included); best of the repeats. The last row times
a 128 x 128 swinging cloth on numba at 60 steps a second with 10 substeps (goal: real time).

``--results`` replaces this benchmark's section of benchmarks/RESULTS.md. Run from the project
root: ``python benchmarks/xpbd_cloth.py [--n 32] [--results]`` (about 10 minutes).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from animsim.methods.xpbd import DEFAULT_SUBSTEPS  # noqa: E402
from animsim.record import MemorySink  # noqa: E402
from benchmarks.stiff_cloth import DT_CAP, KS, scene  # noqa: E402

DURATION = 1.0
#: the reference's step, as a share of symplectic Euler's largest stable step on the cloth
REFERENCE_SHARE = 0.5
SECTION = "## xpbd against implicit Euler on the stiff cloth"
#: the sag error the issue asks for, and the bounds of the search for a setting that meets it
GOAL = 0.02
MAX_SUBSTEPS = 2560
MIN_DT = 1e-4
#: the hanging cloth's spring damping: enough that it has settled by DURATION
HANGING_KD = 100.0
#: the large cloth of the real-time goal, its steps per second and substeps
BIG, BIG_RATE, BIG_SUBSTEPS = 128, 60, 10


def hanging(n: int, integrator: str, dt: float, duration: float) -> str:
    """The cloth hanging in the xy plane from its two top corners (gravity in its plane)."""
    fam = "".join(f"    {k}: {{ks: {KS}, kd: {HANGING_KD}}}\n" for k in ("structural", "shear", "bend"))
    return f"""
duration: {duration!r}
dt: {dt!r}
integrator: {integrator}
record: {{every: 1000000000}}
forces: [{{type: gravity, g: [0, -9.81, 0]}}]
structures:
  - type: cloth
    id: c
    plane: xy
    size: [1, 1]
    resolution: [{n}, {n}]
    mass: 0.01
{fam}    pin: ["c[0,{n - 1}]", "c[{n - 1},{n - 1}]"]
"""


SCENES = {"swinging": scene, "hanging": hanging}


class _TimedSink(MemorySink):
    """Keeps the frames and the CPU clock at each: the first frame is written before the
    first step and the last after the last, so their difference is the stepping's CPU time."""

    def __init__(self) -> None:
        super().__init__()
        self.clock: list[float] = []

    def write(self, frame) -> None:  # type: ignore[no-untyped-def]
        self.clock.append(time.process_time())
        super().write(frame)


@dataclass
class Run:
    stepping: float  # simulated s per CPU s of the stepping
    whole: float  # simulated s per CPU s of the whole run, compilation included
    sag: float  # m
    meta: dict = field(default_factory=dict)


def _compiled(kind: str, n: int, integrator: str, dt: float, backend: str, duration: float = DURATION):
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    text = SCENES[kind](n, integrator, dt, duration)  # records the first and the last step
    return compile_scene(load_scene_text(text).scene, "stiff", backend=backend)


def _run(kind: str, n: int, integrator: str, dt: float, backend: str, duration: float = DURATION) -> Run:
    from animsim.engine import run

    start = time.process_time()
    compiled = _compiled(kind, n, integrator, dt, backend, duration)
    sink = _TimedSink()
    result = run(compiled, [sink])
    whole = time.process_time() - start
    if result.status != "ok":
        raise RuntimeError(f"{integrator} at dt {dt:g} did not survive {duration} s: {result.status}")
    y = sink.positions()[:, :, 1].mean(axis=1)
    meta = dict(result.meta)
    meta["steps"] = result.steps_taken
    meta["wall"] = duration / result.wall_time
    integ = compiled.integrator
    if hasattr(integ, "factorizations"):
        meta["solver"] = f"{integ.factorizations} factorisations ({integ.factor_kind or 'no'})"
    if hasattr(integ, "substeps"):
        meta["solver"] = f"{integ.substeps} substeps, {len(integ.groups.slices)} colour groups"
    stepping = sink.clock[-1] - sink.clock[0]
    return Run(duration / stepping, duration / whole, float(y[0] - y[-1]), meta)


def reference_dt(kind: str, n: int) -> float:
    from animsim.measures import stability

    compiled = _compiled(kind, n, "symplectic_euler", 1e-4, "numpy")
    limit = stability.analyse(compiled).limits["symplectic_euler"]
    steps = int(np.ceil(DURATION / (REFERENCE_SHARE * limit)))
    return DURATION / steps


def _best(kind: str, n: int, integrator: str, dt: float, backend: str, repeat: int) -> Run:
    """The best rates over ``repeat`` runs after a warm one (numba's cache, imports)."""
    got = _run(kind, n, integrator, dt, backend)
    runs = [_run(kind, n, integrator, dt, backend) for _ in range(repeat)]
    got.stepping = max(r.stepping for r in runs)
    got.whole = max(r.whole for r in runs)
    return got


def _xpbd(substeps: int) -> str:
    return f"{{method: xpbd, substeps: {substeps}}}"


Row = tuple[str, float, Run, float]  # label, dt, the run, sag error


def measure(kind: str, n: int, repeat: int) -> tuple[float, float, list[Row]]:
    """Rows of one cloth: each method at one step per frame, then at the cheapest setting
    whose sag is within GOAL of the reference (xpbd: substeps doubled from the default at
    one step per frame; implicit Euler: dt halved)."""
    ref_dt = reference_dt(kind, n)
    _run(kind, n, "symplectic_euler", ref_dt, "numba")  # warm: numba's cache
    ref = _run(kind, n, "symplectic_euler", ref_dt, "numba")
    # the reference itself, for its cost: the force-based answer at a stable step
    rows: list[Row] = [("symplectic_euler (the reference), numba", ref_dt, ref, 0.0)]

    def add(label: str, integrator: str, dt: float, backend: str, search: bool = False) -> float:
        # the search's runs are long: one each (the caches are warm by then)
        got = (
            _run(kind, n, integrator, dt, backend)
            if search
            else _best(kind, n, integrator, dt, backend, repeat)
        )
        err = abs(got.sag - ref.sag) / ref.sag
        rows.append((label, dt, got, err))
        print(
            f"{kind} {label}: dt {dt:.4g}, {got.stepping:.3g} sim s per CPU s, sag error {100 * err:.2f} %",
            flush=True,
        )
        return err

    add("implicit_euler, numpy", "implicit_euler", DT_CAP, "numpy")
    add("xpbd, numpy", "xpbd", DT_CAP, "numpy")
    add("xpbd, numba", "xpbd", DT_CAP, "numba")
    substeps, err = 10, abs(rows[-1][2].sag - ref.sag) / ref.sag
    while err >= GOAL and substeps < MAX_SUBSTEPS:
        substeps *= 2
        err = add(f"xpbd {substeps} substeps, numba", _xpbd(substeps), DT_CAP, "numba", search=True)
    dt, err = DT_CAP, rows[1][3]
    while err >= GOAL and dt > MIN_DT:
        dt /= 2
        err = add("implicit_euler, numpy", "implicit_euler", dt, "numpy", search=True)
    return ref_dt, ref.sag, rows


def big(repeat: int) -> Run:
    """xpbd on the 128 x 128 swinging cloth, numba, BIG_RATE steps a second of BIG_SUBSTEPS."""
    return _best("swinging", BIG, _xpbd(BIG_SUBSTEPS), 1.0 / BIG_RATE, "numba", repeat)


def _table(kind: str, ref_dt: float, ref_sag: float, rows: list[Row]) -> list[str]:
    implicit = rows[1][2]
    lines = [
        f"{kind.capitalize()} cloth: the reference's dt is {ref_dt:.3g} s, its sag {1e3 * ref_sag:.4g} mm.",
        "",
        "| method | dt | simulated s per CPU s, stepping | vs implicit_euler | whole run | vs implicit_euler "
        "| sag error | solver |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    for label, dt, run, err in rows:
        lines.append(
            f"| {label} | {dt:.4g} s | {run.stepping:.3g} | {run.stepping / implicit.stepping:.2f}x "
            f"| {run.whole:.3g} | {run.whole / implicit.whole:.2f}x | {_pct(err)} | {run.meta.get('solver', '')} |"
        )
    return [*lines, ""]


def _pct(err: float) -> str:
    return f"{100 * err:.3g} %" if err < 10 else f"{100 * err:.0f} %"


def _within(rows: list[Row], method: str) -> str:
    """The cheapest row of ``method`` whose sag is within GOAL, or the last tried, as words."""
    tried = [(dt, run, err) for label, dt, run, err in rows if label.startswith(method)]
    for dt, run, err in tried:
        if err < GOAL:
            setting = run.meta.get("solver", "").split(",")[0] if method == "xpbd" else f"dt {dt:.3g} s"
            return f"{method} at {setting} ({run.stepping:.3g} simulated s per CPU s)"
    dt, run, err = tried[-1]
    setting = run.meta.get("solver", "").split(",")[0] if method == "xpbd" else f"dt {dt:.3g} s"
    return f"{method} not even at {setting} ({_pct(err)} off)"


def _verdicts(tables: dict[str, list[Row]], large: Run) -> list[str]:
    """Each goal, met or not, from the numbers above (the swinging cloth is the issue's)."""
    rows = tables["swinging"]
    implicit, numpy_, numba_ = rows[1][2], rows[2][2], rows[3][2]

    def met(ok: bool) -> str:
        return "met" if ok else "not met"

    speed = numba_.stepping / implicit.stepping
    alone = numpy_.stepping / implicit.stepping
    lines = [
        f"- xpbd on numba at least 10x implicit Euler, one step per frame: {speed:.2f}x stepping "
        f"({numba_.whole / implicit.whole:.2f}x whole run): {met(speed >= 10)}",
        f"- xpbd on NumPy at least 2x implicit Euler: {alone:.2f}x stepping "
        f"({numpy_.whole / implicit.whole:.2f}x whole run): {met(alone >= 2)}",
    ]
    for kind, got in tables.items():
        lines.append(
            f"- sag within 2 % at one step per frame, {kind} cloth: xpbd {_pct(got[3][3])} off "
            f"({met(got[3][3] < GOAL)}), implicit Euler {_pct(got[1][3])} off; within 2 %: "
            f"{_within(got, 'xpbd')}, {_within(got, 'implicit_euler')}"
        )
    lines.append(
        f"- {BIG} x {BIG} on numba, {BIG_RATE} steps a second of {BIG_SUBSTEPS} substeps, at least "
        f"real time: {large.stepping:.2f} simulated s per CPU s of stepping ({met(large.stepping >= 1)}); "
        f"{large.meta['wall']:.2f} per wall s on the shared machine"
    )
    return lines


def _chain_factor(substeps: int, kd: float) -> float:
    """How many times its true stretch a long hanging chain of the cloth's particles (10 g,
    springs ks = KS, damping kd) keeps at rest under xpbd at one step per frame: one
    Gauss-Seidel pass a substep leaves each constraint (1 + gamma) w h^2 times the tension of
    the neighbour the pass projects after it (gamma = kd / (ks h), w = 1 / m), besides its own
    stretch; a lone spring (no such neighbour) rests exactly at m g / ks."""
    h = DT_CAP / substeps
    return 1.0 + (1.0 + kd / (KS * h)) * KS * (1 / 0.01) * h * h


def section(n: int, tables: dict[str, tuple[float, float, list[Row]]], large: Run) -> str:
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    lines = [
        f"{SECTION} {n} x {n} (ks = 100000 N/m on every spring, one step per 30 fps frame)",
        "",
        f"Made by `python benchmarks/xpbd_cloth.py --results` (its docstring says what is measured) at "
        f"commit {commit}, {platform.machine()}, Python {platform.python_version()}, on {os.cpu_count()} "
        f"cores shared with other jobs (load average {load} at the end), so CPU seconds, not wall "
        "seconds: simulated seconds per CPU second of the stepping and of the whole run "
        "(compilation included), best of the repeats.",
        "",
    ]
    for kind, (ref_dt, ref_sag, rows) in tables.items():
        lines += _table(kind, ref_dt, ref_sag, rows)
    lines += _verdicts({k: v[2] for k, v in tables.items()}, large)
    lines += [
        "",
        "What the sag goal means on these cloths:",
        "",
        "- swinging: pinned at two corners of one edge, with ks = 1e5 on its bend springs, the cloth "
        "swings down and back as a stiff plate, nearly undamped; its sag at 1 s is a point on that "
        "swing, not a resting sag. At one step per frame implicit Euler's numerical damping nearly "
        "stops the swing, and xpbd's cloth is far softer than its springs, so it hangs and folds",
        "- hanging: the same cloth hanging still, damped so that the reference has settled by 1 s, is the usual "
        "judge of a cloth's sag. Implicit Euler is exact for a static sag at any step. So is xpbd "
        "for a lone spring (at rest its stretch is m g / ks at any substep: the prediction's h^2 g "
        "and the correction cancel), so the cloth's excess is not a softer spring but the single "
        "Gauss-Seidel pass a substep: at rest each constraint also keeps (1 + gamma) w h^2 times "
        "the tension of each neighbour that shares a particle w = 1 / m with it and that the pass "
        "projects after it (gamma = kd / (ks h); times the cosine between them). Along a hanging "
        "chain of these particles that is about "
        f"{_chain_factor(DEFAULT_SUBSTEPS, HANGING_KD):.0f} times the true stretch at "
        f"{DEFAULT_SUBSTEPS} substeps. Its undamped part, ks w h^2, falls as h^2, but its damping "
        "part, kd w h, only as h, and it is the larger from "
        f"{DT_CAP * KS / HANGING_KD:.0f} substeps on: hence each doubling of the substeps about "
        "halves the error. At 10 substeps xpbd's cloth has not settled by 1 s either: its sag "
        "there is a point on a slow bounce",
        "- neither cloth has been tuned for a goal: both are reported as measured",
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
    ap.add_argument("--results", action="store_true", help="write the section of benchmarks/RESULTS.md")
    args = ap.parse_args()
    tables = {kind: measure(kind, args.n, args.repeat) for kind in SCENES}
    large = big(args.repeat)
    text = section(args.n, tables, large)
    print(text)
    if args.results:
        write_results(text)


if __name__ == "__main__":
    main()
