"""animsim's benchmark suite: ``python -m benchmarks [--quick] [--only ...]``.

Every workload is measured side by side, in the same run, for animsim's
backends and for the peers of :mod:`benchmarks.peers` (plain NumPy with a
bincount scatter, Warp CPU). Contenders of one workload are sampled round
robin (A B C A B C ...), so a load spike from another process on this shared
machine hits them all alike instead of one contender's whole measurement.
The results go to ``benchmarks/RESULTS.md`` (machine, versions, medians and
the p10/p90 spread), followed by ``benchmarks/optimisation_log.md``.

Speed is measured here and never asserted in a test.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.peers import PeerUnavailable, load_peers
from benchmarks.peers import particles as P
from benchmarks.peers.cloth import BEND, GRAVITY, PARTICLE_MASS, SHEAR, STRUCTURAL

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT_OUTPUT = HERE / "RESULTS.md"
LOG = HERE / "optimisation_log.md"

#: steps between recorded frames for the compiled backend's calls (a 50 fps
#: animation at dt = 1 ms); the NumPy contenders and the peers step one at a time
STEPS_PER_FRAME = 20
CLOTH_SIZES = (32, 128, 256)
PARTICLE_COUNTS = (100_000, 1_000_000)
TINY_STEPS = 20_000
TINY_RECORD_EVERY = 100
IO_GRID = 64  # 64 x 64 = 4096 rows per frame
IO_FRAMES = 25
WORKLOADS = ("cloth", "particles", "fountain", "bodies", "piled", "contacts", "stiff", "tiny", "io", "render")


@dataclass
class Settings:
    samples: int = 5
    seconds: float = 0.2  # per sample
    cloth_sizes: tuple[int, ...] = CLOTH_SIZES
    particle_counts: tuple[int, ...] = PARTICLE_COUNTS


QUICK = Settings(samples=3, seconds=0.1, cloth_sizes=(32, 128), particle_counts=(100_000,))


@dataclass
class Contender:
    """One way to run a workload: ``call()`` advances ``steps_per_call`` steps."""

    label: str
    call: Callable[[], None]
    steps_per_call: int = 1
    note: str = ""
    rates: list[float] = field(default_factory=list)  # steps/s per sample
    #: calls before the timing starts (compiling, caches, and a numba stepper's build trials)
    warm_up_calls: int = 1


@dataclass
class Table:
    title: str
    unit: str  # how a rate is shown
    scale: float  # rate (steps/s) -> shown unit
    rows: list[tuple[str, str, str, str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: (workload, contender label) -> the median shown in the table, for the goals section
    figures: dict[tuple[str, str], float] = field(default_factory=dict)


def in_tree(module: str) -> bool:
    """True if ``module`` exists in this checkout's animsim.

    ``importlib.util.find_spec`` alone is not enough: an editable install of
    another checkout can supply submodules this tree lacks.
    """
    import animsim

    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return False
    return Path(spec.origin).resolve().is_relative_to(Path(animsim.__file__).resolve().parent)


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def machine() -> list[str]:
    model = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = "unknown"
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = f"{int(line.split()[1]) / 1024**2:.1f} GiB"
    except OSError:
        pass
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=False
        ).stdout.strip()
    except OSError:
        commit = "?"
    import animsim

    return [
        f"- CPU: {model}, {os.cpu_count()} cores; memory {mem}",
        f"- load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (a shared machine: other jobs ran beside this one)",
        f"- Python {platform.python_version()}, NumPy {np.__version__}, numba {_version('numba')}, "
        f"warp-lang {_version('warp-lang')}, animsim {animsim.__version__} (commit {commit})",
    ]


def sample(contenders: list[Contender], settings: Settings) -> None:
    """Warm up, calibrate and sample every contender, round robin."""
    counts = []
    for c in contenders:
        for _ in range(c.warm_up_calls):  # warm-up (compiles, fills caches)
            c.call()
        t0 = time.perf_counter()
        c.call()
        once = max(time.perf_counter() - t0, 1e-9)
        counts.append(max(1, round(settings.seconds / once)))
    for _ in range(settings.samples):
        for c, k in zip(contenders, counts, strict=True):
            t0 = time.perf_counter()
            for _ in range(k):
                c.call()
            c.rates.append(k * c.steps_per_call / (time.perf_counter() - t0))


def add_rows(table: Table, workload: str, contenders: list[Contender], baseline: str | None) -> None:
    base = next((c for c in contenders if c.label == baseline), None)
    base_median = float(np.median(base.rates)) if base and base.rates else None
    for c in contenders:
        r = np.asarray(c.rates) * table.scale
        med, p10, p90 = np.median(r), np.percentile(r, 10), np.percentile(r, 90)
        if table.unit == "us/step":  # lower is better: show the time, spread reversed
            med, p10, p90 = 1e6 / med, 1e6 / p90, 1e6 / p10
        ratio = f"{np.median(c.rates) / base_median:.2f}x" if base_median else ""
        label = c.label + (f" ({c.note})" if c.note else "")
        table.rows.append((workload, label, _fmt(med), f"{_fmt(p10)} - {_fmt(p90)}", ratio))
        table.figures[workload, c.label] = float(med)


def _fmt(x: float) -> str:
    return f"{x:,.0f}" if x >= 100 else f"{x:.3g}"


# --- animsim contenders --------------------------------------------------------------


def _compile(text: str, backend: str = "numpy"):
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    return compile_scene(load_scene_text(text).scene, "bench", backend=backend)


def cloth_scene(n: int, integrator: str = "symplectic_euler") -> str:
    """The peers' cloth (benchmarks/peers/cloth.py) as an animsim scene."""
    fam = {"structural": STRUCTURAL, "shear": SHEAR, "bend": BEND}
    lines = "".join(f"    {k}: {{ks: {ks}, kd: {kd}}}\n" for k, (ks, kd) in fam.items())
    return f"""
duration: 1000.0
dt: 0.001
integrator: {integrator}
record: {{every: {STEPS_PER_FRAME}}}
forces: [{{type: gravity, g: {list(GRAVITY)}}}]
structures:
  - type: cloth
    id: c
    plane: xz
    size: [1, 1]
    resolution: [{n}, {n}]
    mass: {PARTICLE_MASS}
{lines}    pin: ["c[0,0]", "c[{n - 1},0]"]
"""


def particles_scene(n: int) -> str:
    """The peers' particle forces and ground (benchmarks/peers/particles.py), fixed particles.

    Without ``animsim.emitters`` a strand with no springs is the cheapest way
    to get n particles; its state is then replaced by the peers' initial state.
    """
    return f"""
duration: 1000.0
dt: {P.DT}
record: {{every: {STEPS_PER_FRAME}}}
forces:
  - {{type: gravity, g: {list(P.GRAVITY)}}}
  - {{type: drag, k: {P.K_DRAG}}}
  - {{type: wind, velocity: {list(P.WIND)}, k: {P.K_WIND}}}
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: {P.RESTITUTION}}}]
structures:
  - {{type: strand, id: s, start: [0, 0, 0], end: [1, 0, 0], count: {n}, mass: {P.PARTICLE_MASS}}}
"""


def numpy_contender(compiled, label: str, note: str = "") -> Contender:
    """The loop's work for one watchdog stride on the NumPy backend: the engine's stepper
    advances ``check_stride`` steps (integrate, then the post-step stages), then one check,
    as ``engine.run`` does."""
    from animsim.engine import Guard
    from animsim.steppers import start

    state, stepper, _ = start(compiled)
    guard = Guard(compiled, dt=stepper.largest_dt)
    guard.start(state)
    stride, end = stepper.check_stride, stepper.end

    def call() -> None:
        k = state.step
        if k + stride > end:  # start the clock over (the state keeps moving)
            k = state.step = 0
        stepper.advance(state, k, k + stride)
        guard.check(state)

    return Contender(label, call, stride, note)


def numba_contender(compiled, label: str, threads: int = 1) -> Contender:
    """The engine's numba stepper (fused chunks where the scene allows, else step by step),
    advancing STEPS_PER_FRAME steps per call as the loop does between frames, with numba's
    thread count ``threads`` during each call (as ``compile_scene(threads=)`` holds it
    during a run) and the process's count put back after it."""
    import numba

    from animsim.backends import fused
    from animsim.steppers import start

    state, stepper, _ = start(compiled)
    end = stepper.end

    def call() -> None:
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            k = state.step
            if k + STEPS_PER_FRAME > end:  # start the clock over (the state keeps moving)
                k = state.step = 0
            stepper.advance(state, k, k + STEPS_PER_FRAME)
        finally:
            numba.set_num_threads(before)

    # The first calls of a blocked stepper alternate its one-thread and threaded builds to
    # time them (fused.BuildChooser); they are a run's first few calls, and left in the
    # samples they had made up two of the five single-call samples at 1e6 particles.
    trials = 2 * fused.TRIAL_CALLS
    return Contender(label, call, STEPS_PER_FRAME, f"{STEPS_PER_FRAME} steps per call", warm_up_calls=trials)


def numba_cores() -> int:
    """The threads numba may run here (every core, or NUMBA_NUM_THREADS)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)


def peer_contenders(workload: str, n: int, notes: list[str]) -> list[Contender]:
    out = []
    for peer in load_peers():
        try:
            st = peer.cloth_stepper(n) if workload == "cloth" else peer.particles_stepper(n)
        except PeerUnavailable as exc:
            notes.append(f"{peer.LABEL} skipped: {exc}")
            continue
        out.append(Contender(f"peer: {peer.LABEL}", st.step, 1))
    return out


def numba_ok(notes: list[str]) -> bool:
    if importlib.util.find_spec("numba") is None:
        notes.append('animsim numba backend skipped: numba is not installed (pip install -e ".[fast]")')
        return False
    return True


def bench_cloth(settings: Settings) -> Table:
    from animsim.integrators import REGISTRY

    table = Table("Cloth n x n (structural + shear + bend, symplectic Euler, dt = 1 ms)", "steps/s", 1.0)
    implicit = "implicit_euler" in REGISTRY
    if not implicit:
        table.notes.append(
            "implicit Euler skipped: `implicit_euler` is not registered in this build (issue 5)"
        )
    use_numba = numba_ok(table.notes)
    for n in settings.cloth_sizes:
        springs = 2 * n * (n - 1) + 2 * (n - 1) ** 2 + 2 * n * (n - 2)
        contenders = peer_contenders("cloth", n, table.notes)
        ref = _compile(cloth_scene(n), "reference")
        contenders.append(numpy_contender(ref, "animsim numpy, generic bincount (before)"))
        default = _compile(cloth_scene(n))
        contenders.append(numpy_contender(default, "animsim numpy, grid slices (default)"))
        if implicit:
            contenders.append(
                numpy_contender(_compile(cloth_scene(n, "implicit_euler")), "animsim numpy, implicit Euler")
            )
        if use_numba:
            contenders.append(numba_contender(_compile(cloth_scene(n), "numba"), "animsim numba, 1 thread"))
            table.notes.append(
                "animsim numba runs cloth on one thread whatever the thread count: its springs join "
                "neighbouring particles, so it is not stepped in independent blocks of particles "
                "(only the particle systems below are), and a thread contender would time the same code"
            )
        sample(contenders, settings)
        add_rows(
            table, f"cloth {n} ({springs:,} springs)", contenders, "peer: plain NumPy (bincount scatter)"
        )
        print(f"  cloth {n} done", flush=True)
    return table


def bench_particles(settings: Settings) -> Table:
    table = Table(
        "Particles with gravity, drag, wind and a ground plane (symplectic Euler, dt = 1 ms)",
        "M particle-steps/s",
        1.0,
    )
    table.notes.append(
        "animsim runs fixed particles (a strand without springs) started from the peers' initial state, "
        "with its impulse plane (time of impact, restitution); the peers also respawn particles by age. "
        "The emitter path (births, deaths, pools) is timed in its own table below (fountain)."
    )
    use_numba = numba_ok(table.notes)
    for n in settings.particle_counts:
        prob = P.make_particles(n, 0)
        contenders = peer_contenders("particles", n, table.notes)
        compiled = _compile(particles_scene(n))
        compiled.initial.particle_position[:] = prob.x0
        compiled.initial.particle_velocity[:] = prob.v0
        contenders.append(numpy_contender(compiled, "animsim numpy (default)"))
        if use_numba:
            cores = numba_cores()
            for threads in (1, cores) if cores > 1 else (1,):
                fast = _compile(particles_scene(n), "numba")  # its own state and stepper
                fast.initial.particle_position[:] = prob.x0
                fast.initial.particle_velocity[:] = prob.v0
                label = "animsim numba, 1 thread" if threads == 1 else f"animsim numba, {threads} threads"
                contenders.append(numba_contender(fast, label, threads=threads))
        sample(contenders, settings)
        for c in contenders:
            c.rates = [r * n / 1e6 for r in c.rates]
        add_rows(table, f"{n:.0e} particles", contenders, "peer: plain NumPy (bincount scatter)")
        print(f"  particles {n} done", flush=True)
    return table


class NullSink:
    """Takes frames and drops them: the loop's recording cost without I/O."""

    def begin(self, header) -> None: ...

    def write(self, frame) -> None: ...

    def close(self, meta) -> None: ...

    def abort(self) -> None: ...


def tiny_scene(integrator: str = "symplectic_euler", spring: bool = False) -> str:
    """One particle under gravity; with ``spring``, the two-particle spring pendulum."""
    text = f"""
duration: {TINY_STEPS * 1e-4}
dt: 0.0001
integrator: {integrator}
record: {{every: {TINY_RECORD_EVERY}}}
particles: [{{id: p, mass: 1, position: [0, 0, 0]}}]
forces: [{{type: gravity}}]
"""
    if spring:
        text = text.replace(
            "position: [0, 0, 0]}]",
            "position: [0, 0, 0], pinned: true}, {id: q, mass: 1, position: [1.2, 0, 0]}]",
        )
        text += "springs: [{between: [p, q], ks: 10, kd: 0.1, rest: 1}]\n"
    return text


TINY = tiny_scene()


def bench_tiny(settings: Settings) -> Table:
    from animsim.engine import run

    table = Table(
        f"Tiny scenes: whole `run()` of {TINY_STEPS:,} steps, a frame every {TINY_RECORD_EVERY} "
        "to a sink that drops it",
        "us/step",
        1.0,
    )
    backends = [("numpy", "numpy")]
    if numba_ok(table.notes):
        backends.append(("numba", "numba"))
    cases = [
        ("1 particle, gravity", "symplectic_euler", False),
        ("1 particle, gravity", "rk4", False),
        ("spring pendulum (2 particles, 1 spring)", "symplectic_euler", True),
        ("spring pendulum (2 particles, 1 spring)", "rk4", True),
    ]
    for what, integrator, spring in cases:
        contenders = []
        for backend, label in backends:
            compiled = _compile(tiny_scene(integrator, spring), backend)

            def call(compiled=compiled) -> None:
                run(compiled, [NullSink()])

            contenders.append(Contender(f"animsim {label}", call, TINY_STEPS))
        sample(contenders, Settings(samples=settings.samples, seconds=settings.seconds))
        add_rows(table, f"{what}, {integrator}", contenders, None)
    table.notes.append("per step = wall time of run() / steps, including energy at start and end")
    return table


def bench_io(settings: Settings) -> Table:
    from animsim.export.csv import CsvSink
    from animsim.export.npz import NpzSink
    from animsim.record import Frame

    table = Table(f"Trajectory writing: {IO_FRAMES} frames of {IO_GRID * IO_GRID:,} particles", "rows/s", 1.0)
    compiled = _compile(cloth_scene(IO_GRID))
    rng = np.random.default_rng(0)
    n = compiled.system.particle_count
    x = compiled.initial.particle_position + rng.normal(scale=0.01, size=(n, 3))
    v = rng.normal(size=(n, 3))
    index = np.arange(n, dtype=np.int64)
    tmp = Path(tempfile.mkdtemp(prefix="animsim-bench-"))
    contenders = []
    for label, make in (
        ("CsvSink", lambda p: CsvSink(p / "t.csv", write_meta=False)),
        ("NpzSink", lambda p: NpzSink(p / "t.npz")),
    ):

        def call(make=make) -> None:
            sink = make(tmp)
            sink.begin(compiled.header)
            for k in range(IO_FRAMES):
                sink.write(Frame(step=k, time=k * 1e-3, index=index, position=x, velocity=v))
            sink.close({"status": "ok"})

        contenders.append(Contender(label, call, IO_FRAMES * n))
    sample(contenders, Settings(samples=max(3, settings.samples // 2), seconds=settings.seconds))
    add_rows(table, f"{IO_FRAMES} x {n:,} rows", contenders, None)
    return table


def bench_render(settings: Settings) -> Table:
    """Issue 6: frames/s of the whole GIF path (raster, palette, LZW, write) for 500 particles."""
    from animsim.export.animation import AnimationSink
    from animsim.export.raster import bounds_from_positions
    from animsim.record import Frame, TrajectoryHeader
    from benchmarks import render_speed as R

    table = Table(
        f"Rendering: a {R.GOAL_FPS:.0f}-frames/s goal at 500 particles, 480x480, streamed to a GIF",
        "frames/s",
        1.0,
    )
    n, frames = 500, (60 if settings is QUICK else 120)
    positions, all_springs = R.cloth(n, 2000, frames)
    bounds = bounds_from_positions([*positions, np.zeros((1, 3))])
    index, zeros = np.arange(n), np.zeros((n, 3))
    for view in ("xy", "3d"):
        contenders = []
        for springs in (np.zeros((0, 2), dtype=np.int64), all_springs):
            header = TrajectoryHeader("bench", [str(i) for i in range(n)], springs, False)
            tmp = Path(tempfile.mkdtemp(prefix="animsim-render-"))

            def gif(header=header, view=view, tmp=tmp) -> None:
                sink = AnimationSink(
                    tmp / "b.gif", size=(480, 480), view=view, bounds=bounds, planes=[R.GROUND]
                )
                sink.begin(header)
                for k, p in enumerate(positions):
                    sink.write(Frame(k, k / 25, index, p, zeros))
                sink.close({})

            label = f"animsim GIF, {len(springs):,} springs"
            contenders.append(Contender(label, gif, frames))
        sample(contenders, settings)
        add_rows(table, f"{view} view, {n} particles", contenders, None)
    table.notes.append(f"a call renders and writes {frames} frames of a waving cloth over a ground plane")
    print("  render done", flush=True)
    return table


def startup() -> list[str]:
    """Seconds for a fresh process to import, compile a scene and run it, per backend."""
    lines = []
    tiny = Path(tempfile.mkdtemp(prefix="animsim-bench-")) / "tiny.yaml"
    tiny.write_text(TINY)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    backends = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])
    for backend in backends:
        t0 = time.perf_counter()
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "animsim",
                "run",
                str(tiny),
                "-o",
                str(tiny.with_suffix(".csv")),
                "-q",
                "--backend",
                backend,
            ],
            capture_output=True,
            text=True,
            env=env,
            check=False,
        )
        wall = time.perf_counter() - t0
        status = "ok" if out.returncode == 0 else f"exit {out.returncode}: {out.stderr.strip()[:200]}"
        lines.append(f"| `animsim run tiny.yaml --backend {backend}` | {wall:.2f} s | {status} |")
    return lines


#: the fountain's contender that times the numba stepper with no watchdog around it
_STEPPER_ALONE = "ceiling: the numba stepper alone"


def bench_fountain(settings: Settings) -> Table:
    """Issue 3's particle system: a 100k-particle fountain in steady state (benchmarks/fountain.py)."""
    from benchmarks import fountain as F

    table = Table(
        f"Particle system: {F.PARTICLES:,}-slot fountain in steady state (emitter, births, deaths; "
        f"symplectic Euler, dt = {F.DT * 1000:g} ms)",
        "steps/s",
        1.0,
    )
    steps = 100 if settings is QUICK else 300
    # (backend, numba's threads): the fountain's particles are stepped in blocks, which run
    # on several threads when numba has them
    ways: list[tuple[str, int | None]] = [("numpy", None)]
    if numba_ok(table.notes):
        cores = numba_cores()
        ways += [("numba", 1)] + ([("numba", cores)] if cores > 1 else [])
    # the numba stepper on numba's threads with none of the run's watchdog around it: what a
    # run could reach if its checks, energy books and replay copies were free
    alone = max((t for b, t in ways if b == "numba" and t), default=None)
    for ground, label in ((True, "with a ground plane (restitution, friction)"), (False, "no plane")):
        runs: dict[tuple[str, int | None], list[tuple[float, dict]]] = {way: [] for way in ways}
        bare: list[float] = []
        for _ in range(max(2, settings.samples // 2)):  # whole runs, round robin
            for backend, threads in ways:
                runs[backend, threads].append(F.steps_per_second(steps, ground, backend, threads=threads))
            if ground and alone:
                bare.append(F.stepper_steps_per_second(steps, ground, threads=alone))
        contenders = []
        for (backend, threads), done in runs.items():
            alive = done[-1][1]["per_emitter"]["fountain"]["alive"]
            how = "" if threads is None else (" 1 thread," if threads == 1 else f" {threads} threads,")
            c = Contender(f"animsim {backend},{how} {label}", lambda: None, 1, f"{alive:,} alive")
            c.rates = [r for r, _ in done]
            contenders.append(c)
        if bare:
            threads_label = "1 thread" if alone == 1 else f"{alone} threads"
            c = Contender(
                f"{_STEPPER_ALONE}, {threads_label}, {label}", lambda: None, 1, "a ceiling, not a run"
            )
            c.rates = bare
            contenders.append(c)
        add_rows(table, f"fountain {F.PARTICLES:.0e}", contenders, None)
    table.notes.append(
        f"each sample times {steps} steps after {round(F.WARMUP / F.DT)} warm-up steps that fill the pool; "
        "spread over whole runs, not sub-samples"
    )
    if alone:
        table.notes.append(
            f"{_STEPPER_ALONE}: the same scene's steps (physics, births, deaths) timed without the "
            "run around them: no watchdog checks, no energy books of the newborns, no copies kept for "
            "a replay, no progress; what a run could reach if all of that were free"
        )
    print("  fountain done", flush=True)
    return table


def bench_bodies(settings: Settings) -> Table:
    """Rigid bodies: 1,000 free bodies with gravity and a floor (benchmarks/bodies.py)."""
    from benchmarks import bodies as B

    count = B.GRID[0] * B.GRID[1]
    table = Table(
        f"Rigid bodies: {count:,} free boxes, spheres and capsules dropped onto a floor with friction "
        f"(symplectic Euler, dt = {B.DT * 1000:g} ms; goals: 1,000 steps/s on numba, 100 on NumPy)",
        "steps/s",
        1.0,
    )
    steps = 200 if settings is QUICK else 500
    backends = ["numpy"] + (["numba"] if numba_ok(table.notes) else [])
    contenders = []
    for backend in backends:
        runs = [B.steps_per_second(backend, steps) for _ in range(max(2, settings.samples // 2))]
        best_cpu = max(cpu for _, cpu in runs)
        c = Contender(f"animsim {backend}", lambda: None, 1, f"best {best_cpu:,.0f} steps per CPU second")
        c.rates = [wall for wall, _ in runs]
        contenders.append(c)
    add_rows(table, f"bodies {count}", contenders, None)
    table.notes.append(
        f"each sample times {steps} steps after a {B.WARMUP:g} s warm-up (bodies falling, landing and "
        "resting); rates are per wall-clock second, spread over whole runs, not sub-samples"
    )
    print("  bodies done", flush=True)
    return table


def bench_piled(settings: Settings) -> Table:
    """Rigid bodies piled: 1,000 boxes at rest on each other (benchmarks/bodies.py --piled)."""
    from benchmarks import bodies as B

    table = Table(
        "Rigid bodies: 1,000 boxes piled on a floor, 100 columns of ten at rest on each other "
        f"(symplectic Euler, dt = {B.DT * 1000:g} ms; goal: 1,000 steps/s on numba)",
        "steps/s",
        1.0,
    )
    if not numba_ok(table.notes):
        return table
    steps = 200 if settings is QUICK else 500
    runs = [B.steps_per_second("numba", steps, piled=True) for _ in range(2)]
    best_cpu = max(cpu for _, cpu in runs)
    c = Contender("animsim numba", lambda: None, 1, f"best {best_cpu:,.0f} steps per CPU second")
    c.rates = [wall for wall, _ in runs]
    add_rows(table, "piled 1000", [c], None)
    table.notes.append(
        f"each sample times {steps} steps after a {B.WARMUP:g} s warm-up (the first step finds the "
        "columns' impulses from nothing, the rest start warm); the columns stand still throughout. "
        "NumPy is not timed here (measured by hand: about 0.5 s of CPU a step)"
    )
    print("  piled done", flush=True)
    return table


def bench_contacts(settings: Settings) -> Table:
    """Particle contacts: about 100,000 grains poured into a box (benchmarks/contacts.py)."""
    from benchmarks import contacts as K

    table = Table(
        "Particle contacts: about 100,000 grains falling into a box of colliders "
        "(symplectic Euler; goals: 20 steps/s on numba, 5 on NumPy)",
        "steps/s",
        1.0,
    )
    steps = 10 if settings is QUICK else 20
    backends = ["numpy"] + (["numba"] if numba_ok(table.notes) else [])
    windows = ((0, "steps 0-20: the lattice falling"), (40, "steps 40-60: the pile landed"))
    for after, label in windows:
        contenders = []
        for backend in backends:
            runs = [K.steps_per_second(backend, steps, 1, after=after) for _ in range(2)]
            particles = runs[-1][2]
            best_cpu = max(cpu for _, cpu, _ in runs)
            c = Contender(
                f"animsim {backend}, {label}",
                lambda: None,
                1,
                f"{particles:,} grains; best {best_cpu:,.1f} steps per CPU second",
            )
            c.rates = [wall for wall, _, _ in runs]
            contenders.append(c)
        add_rows(table, "contacts 1e+05", contenders, None)
    table.notes.append(
        f"each sample times {steps} steps as the difference of two runs (to the window's end and "
        "to its start), so compiling and the steps before the window are not counted"
    )
    print("  contacts done", flush=True)
    return table


def bench_stiff(settings: Settings) -> Table:
    """Simulated seconds per wall second on a stiff cloth, each method at its largest surviving step."""
    from benchmarks import stiff_cloth as S

    n = 32
    table = Table(
        f"Stiff cloth {n} x {n} (ks = {S.KS:g} N/m on every spring): simulated seconds per wall second "
        "at the largest step each method survives (capped at one 30 fps frame)",
        "simulated s per wall s",
        1.0,
    )
    rows = S.measure(n, repeat=max(1, settings.samples // 2))
    base = rows[0][2]
    for integrator, dt, rate, meta in rows:
        extra = meta.get("solver", "")
        table.figures[f"stiff cloth {n}", integrator] = rate
        table.rows.append(
            (
                f"stiff cloth {n}",
                f"animsim numpy, {integrator} (dt {dt:.3g} s, {meta.get('steps_taken')} steps{extra})",
                _fmt(rate),
                "",
                f"{rate / base:.2f}x vs symplectic",
            )
        )
    table.notes.append(
        f"largest step: bisection in log dt on {S.PROBE} s probe runs that must end ok; symplectic Euler is "
        f"then timed at 0.9 x that step; each timed run covers {S.DURATION} s (best of the repeats)"
    )
    print("  stiff done", flush=True)
    return table


def _figure(tables: list[Table], title: str, workload: str, label: str) -> float | None:
    """The median this run measured for the first contender whose table title, workload and
    label start with these (None when the run did not time it)."""
    for t in tables:
        if not t.title.startswith(title):
            continue
        for (w, lab), value in t.figures.items():
            if w.startswith(workload) and lab.startswith(label):
                return value
    return None


#: where the log appended below says what was measured and tried for a goal not met
_FOUNTAIN_LOG = (
    '"The fountain on numba, eighth round: the run around the stepper", "The fountain on numba, '
    'seventh round: an emitter\'s step in one compiled call, the loop once a stride", "The '
    "fountain on numba, sixth round: the plane's rows, gravity's stores, the newborns in one "
    'call" and "The fountain on numba: births, deaths and checks around the physics"'
)
_IMPLICIT_LOG = '"Implicit Euler: a sparse Cholesky (CHOLMOD) for the stiff steps"'


def goals_section(tables: list[Table]) -> list[str]:
    """The speed goals animsim holds itself to, each with this run's figure: met, or how far
    from it and where the log says what was tried. Goals whose workloads this run did not
    time are left out."""
    rows: list[tuple[str, str, str, str]] = []

    def at_most(goal: str, value: float | None, limit: float, unit: str) -> None:
        if value is None:
            return
        met = value <= limit
        status = "met" if met else f"not met: {value / limit:.2f} times the goal"
        rows.append((goal, f"{_fmt(value)} {unit}", status, "-"))

    at_most(
        "tiny scene on NumPy, symplectic Euler: at most 3 us a step",
        _figure(tables, "Tiny scenes", "1 particle, gravity, symplectic_euler", "animsim numpy"),
        3.0,
        "us",
    )
    at_most(
        "tiny scene on NumPy, rk4: at most 15 us a step",
        _figure(tables, "Tiny scenes", "1 particle, gravity, rk4", "animsim numpy"),
        15.0,
        "us",
    )

    def ratio(goal: str, ours: float | None, peer: float | None, least: float, what: str, log: str) -> None:
        if ours is None or peer is None:
            return
        r = ours / peer
        status = "met" if r >= least else f"not met: {least / r:.2f}x short"
        rows.append(
            (goal, f"{r:.2f}x ({_fmt(ours)} against {_fmt(peer)} {what})", status, "-" if r >= least else log)
        )

    ratio(
        "numba cloth 128 x 128, one thread: at least 1.5x Warp on the CPU",
        _figure(tables, "Cloth", "cloth 128 ", "animsim numba, 1 thread"),
        _figure(tables, "Cloth", "cloth 128 ", "peer: Warp CPU"),
        1.5,
        "steps/s",
        "-",
    )
    ratio(
        "NumPy, 1e6 particles with a ground plane: at least 1.0x the plain NumPy peer",
        _figure(tables, "Particles with gravity", "1e+06 particles", "animsim numpy"),
        _figure(tables, "Particles with gravity", "1e+06 particles", "peer: plain NumPy"),
        1.0,
        "M particle-steps/s",
        "-",
    )
    fountain = [  # every numba thread count the run timed, with the plane
        (label.split(",")[1].strip(), value)
        for t in tables
        if t.title.startswith("Particle system")
        for (w, label), value in t.figures.items()
        if w.startswith("fountain") and label.startswith("animsim numba,") and "ground plane" in label
    ]
    if fountain:
        best = max(v for _, v in fountain)
        figure = ", ".join(f"{_fmt(v)} on {how}" for how, v in fountain) + " (steps/s)"
        met = best >= 1500
        status = "met" if met else f"not met: the best is {1500 / best:.2f}x short"
        ceiling = [
            (label.split(",")[1].strip(), value)
            for t in tables
            if t.title.startswith("Particle system")
            for (w, label), value in t.figures.items()
            if w.startswith("fountain") and label.startswith(_STEPPER_ALONE)
        ]
        if ceiling:
            how, value = ceiling[0]
            figure += f"; the stepper alone, no watchdog: {_fmt(value)} on {how}"
            if not met and value < 1500:
                status += f"; the stepper alone, with none of the run around it, is {1500 / value:.2f}x short"
        rows.append(
            (
                "numba, 100,000-slot fountain with its ground plane: at least 1,500 steps/s",
                figure,
                status,
                "-" if met else _FOUNTAIN_LOG,
            )
        )
    ratio(
        "implicit Euler on the stiff cloth: at least 10x symplectic Euler's simulated s per s",
        _figure(tables, "Stiff cloth", "stiff cloth", "implicit_euler"),
        _figure(tables, "Stiff cloth", "stiff cloth", "symplectic_euler"),
        10.0,
        "simulated s per s",
        _IMPLICIT_LOG,
    )
    if not rows:
        return []
    out = ["## Speed goals, from this run", "", "| goal | this run | status | what was tried |"]
    out.append("| --- | --- | --- | --- |")
    out += [f"| {' | '.join(r)} |" for r in rows]
    return [*out, ""]


def render_markdown(tables: list[Table], header: list[str], start_lines: list[str], elapsed: float) -> str:
    out = [
        "# animsim benchmarks",
        "",
        "Written by `python -m benchmarks` (see `benchmarks/suite.py`); do not edit by hand.",
        "Medians over samples taken round robin across the contenders of a workload, with the",
        "10th-90th percentile spread; `vs plain` is the median over the plain-NumPy peer's in the same run.",
        "",
        "## Machine",
        "",
        *header,
        f"- load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; suite took {elapsed:.0f} s",
        "",
        *goals_section(tables),
    ]
    for t in tables:
        out += [f"## {t.title}", ""]
        if t.rows:
            out += [
                f"| workload | contender | median {t.unit} | p10 - p90 | vs plain |",
                "| --- | --- | ---: | ---: | ---: |",
            ]
            out += [f"| {' | '.join(r)} |" for r in t.rows]
            out.append("")
        out += [f"- {note}" for note in dict.fromkeys(t.notes)]
        out.append("")
    if start_lines:
        out += ["## Start-up (fresh process, numba kernels from the on-disk cache)", ""]
        out += ["| command | wall time | status |", "| --- | ---: | --- |", *start_lines, ""]
    # written by benchmarks/cold_start.py and benchmarks/compare_defaults.py, kept here
    for kept in (HERE / "cold_start.md", HERE / "compare_defaults.md"):
        if kept.exists():
            out += [kept.read_text().rstrip(), ""]
    if LOG.exists():
        out += [LOG.read_text().rstrip(), ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer, shorter samples and only the smaller sizes")
    ap.add_argument(
        "--only",
        default=",".join(WORKLOADS),
        help=f"comma-separated workloads (default all: {','.join(WORKLOADS)})",
    )
    ap.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="where to write the Markdown results")
    args = ap.parse_args(argv)
    only = [w.strip() for w in args.only.split(",") if w.strip()]
    unknown = sorted(set(only) - set(WORKLOADS))
    if unknown:
        ap.error(f"unknown workload(s) {', '.join(unknown)} (valid: {', '.join(WORKLOADS)})")
    settings = QUICK if args.quick else Settings()
    t0 = time.perf_counter()
    header = machine()
    print("\n".join(header), flush=True)
    runners = {
        "cloth": bench_cloth,
        "particles": bench_particles,
        "tiny": bench_tiny,
        "io": bench_io,
        "render": bench_render,
        "fountain": bench_fountain,
        "bodies": bench_bodies,
        "piled": bench_piled,
        "contacts": bench_contacts,
        "stiff": bench_stiff,
    }
    tables = []
    for name in WORKLOADS:
        if name in only:
            print(f"{name} ...", flush=True)
            tables.append(runners[name](settings))
    start_lines = startup() if "tiny" in only else []
    text = render_markdown(tables, header, start_lines, time.perf_counter() - t0)
    args.output.write_text(text)
    print(text)
    print(f"wrote {args.output}")
    return 0
