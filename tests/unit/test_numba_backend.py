"""The numba backend steps the same physics as the NumPy backend, to 1e-12 relative here
(tests/unit/test_backend_parity.py holds the 1e-9 parity over every example scene).

Runs whenever numba is importable. The first run on a machine compiles the
kernels (tens of seconds); numba caches them on disk, so later runs load them.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim.backends import BACKEND_AUTO
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.integrators import FIXED_STEP
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text

pytest.importorskip("numba")

RTOL = 1e-12


def _run(text: str, backend: str, integrator: str | None = None, threads: int | None = None):
    scene = load_scene_text(text).scene
    if integrator is not None:
        scene = scene.model_copy(update={"integrator": integrator})
    compiled = compile_scene(scene, "t", backend=backend, threads=threads)
    sink = MemorySink()
    return compiled, run(compiled, [sink]), sink


def _assert_same_run(
    text: str, integrator: str | None = None, threads: int | None = None, moved: float = 1e-3
):
    ref_c, ref, ref_sink = _run(text, "numpy", integrator)
    fast_c, fast, fast_sink = _run(text, "numba", integrator, threads)
    assert fast_c.backend == "numba" and fast.meta["backend"] == "numba"
    assert ref_c.backend == "numpy"
    assert (fast.status, fast.steps_taken, fast.frames) == (ref.status, ref.steps_taken, ref.frames)
    assert fast.force_evals == ref.force_evals
    np.testing.assert_array_equal(fast_sink.times(), ref_sink.times())
    for a, b in (
        (fast_sink.positions(), ref_sink.positions()),
        (fast_sink.velocities(), ref_sink.velocities()),
    ):
        assert np.isfinite(a).all()
        scale = float(np.abs(b).max())
        assert float(np.abs(a - b).max()) <= RTOL * scale
    assert (
        float(np.abs(ref_sink.positions()[-1] - ref_sink.positions()[0]).max()) > moved
    )  # something happened
    return fast, ref


CLOTH = """
duration: 0.06
dt: 0.001
record: {every: 7}
forces: [{type: gravity}, {type: drag, k: 0.01}]
structures:
  - type: cloth
    id: c
    size: [1, 1]
    resolution: [9, 7]
    mass: 0.01
    velocity: [0, 0, 0.1]
    structural: {ks: 500, kd: 0.5}
    shear: {ks: 200, kd: 0.2}
    bend: {ks: 50, kd: 0.05}
    pin: ["c[0,0]", "c[8,0]"]
planes: [{point: [0, -0.02, 0], normal: [0, 1, 0], restitution: 0.4, friction: 0.3}]
"""

PARTICLES = """
duration: 0.5
dt: 0.003
record: {fps: 30}
forces:
  - {type: gravity}
  - {type: drag, k: 0.1}
  - {type: quadratic_drag, area: 0.01}
  - {type: wind, velocity: [3, 0, 1], k: 0.2}
  - {type: attractor, position: [0, 2, 0], gm: 0.5, softening: 0.1}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5, friction: 0.2}
  - {point: [0.3, 0, 0], normal: [-1, 0, 0], restitution: 0.9}
particles:
  - {id: a, mass: 1, position: [0, 0.3, 0], velocity: [1, 2, 0]}
  - {id: b, mass: 0.5, position: [0.1, 0.05, 0.2], velocity: [2, -3, 0]}
  - {id: c, mass: 2, position: [-0.2, 1, 0], velocity: [0, 0, 0]}
  - {id: d, position: [0, 1, 1], velocity: [0.5, 0, 0], pinned: true}
"""

SPRINGS = """
duration: 0.4
dt: 0.0007
forces: [{type: gravity, g: [0, -9.81, 0]}]
planes: [{point: [0, -1, 0], normal: [0, 1, 0], response: penalty, stiffness: 2000, damping: 5}]
particles:
  - {id: anchor, position: [0, 0, 0], pinned: true}
  - {id: a, mass: 0.2, position: [0.3, -0.2, 0]}
  - {id: b, mass: 0.3, position: [0.6, -0.5, 0.1]}
springs:
  - {between: [anchor, a], ks: 80, kd: 0.8}
  - {between: [a, b], ks: 60, kd: 0.4, rest: 0.2}
  - {between: [anchor, b], ks: 5}
"""


@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_cloth_with_plane_equals_numpy(integrator):
    _assert_same_run(CLOTH, integrator)


@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_particles_with_drag_wind_gravity_planes_equal_numpy(integrator):
    _assert_same_run(PARTICLES, integrator, moved=0.1)


@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_damped_springs_and_penalty_plane_equal_numpy(integrator):
    _assert_same_run(SPRINGS, integrator, moved=0.1)


def test_particles_without_planes_verlet_particle_major():
    text = PARTICLES.split("planes:")[0] + PARTICLES.split("restitution: 0.9}")[1]
    _assert_same_run(text, "verlet", moved=0.1)


def test_two_threads_equal_one():
    _, _, s1 = _run(CLOTH, "numba", threads=1)
    _, _, s2 = _run(CLOTH, "numba", threads=2)
    np.testing.assert_array_equal(s1.positions(), s2.positions())


def test_short_last_step_and_no_sinks():
    text = CLOTH.replace("duration: 0.06", "duration: 0.0605")  # dt does not divide it
    _assert_same_run(text)
    ref = run(compile_scene(load_scene_text(text).scene, "t", backend="numpy"))
    fast = run(compile_scene(load_scene_text(text).scene, "t", backend="numba"))
    assert fast.steps_taken == ref.steps_taken == 61
    scale = np.abs(ref.final_state.particle_position).max()
    assert (
        np.abs(fast.final_state.particle_position - ref.final_state.particle_position).max() <= RTOL * scale
    )


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the NumPy run overflows on purpose
@pytest.mark.parametrize(
    "text",
    [CLOTH.replace("ks: 500", "ks: 5e7"), PARTICLES.replace("gm: 0.5", "gm: 1e300")],
    ids=["stiff-cloth", "huge-attractor"],
)
def test_blow_up_is_reported_at_the_same_step(text):
    fast, ref = _run(text, "numba")[1], _run(text, "numpy")[1]
    assert ref.status == "unstable"
    assert fast.status == "unstable"
    assert fast.steps_taken == ref.steps_taken
    assert fast.failure.particle == ref.failure.particle


def test_auto_picks_numba_and_says_so():
    compiled = compile_scene(load_scene_text(SPRINGS).scene, "t", backend=BACKEND_AUTO)
    assert compiled.backend == "numba"
    assert any(s.startswith("backend: numba") and "auto: numba is installed" in s for s in compiled.stages)


def test_implicit_euler_runs_on_numba_kernels_step_by_step():
    fast, ref = _assert_same_run(SPRINGS, "implicit_euler")
    assert fast.meta["backend"] == "numba"


def test_turbulence_runs_on_numba_and_agrees():
    text = PARTICLES.replace(
        "{type: wind, velocity: [3, 0, 1], k: 0.2}",
        "{type: wind, velocity: [3, 0, 1], k: 0.2, turbulence: 1}",
    )
    _assert_same_run(text, "rk4", moved=0.1)


def test_cli_run_and_explain_with_numba(tmp_path, cli):
    scene = tmp_path / "s.yaml"
    scene.write_text(SPRINGS)
    explained = cli("explain", scene, "--backend", "auto")
    assert explained.returncode == 0, explained.stderr
    assert "backend: numba" in explained.stdout
    out = cli("run", scene, "--backend", "numba", "-o", tmp_path / "o.csv", "-q")
    assert out.returncode == 0, out.stderr
    ref = cli("run", scene, "-o", tmp_path / "r.csv", "-q")
    assert ref.returncode == 0
    a = np.loadtxt(tmp_path / "o.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3, 4, 5, 6, 7))
    b = np.loadtxt(tmp_path / "r.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3, 4, 5, 6, 7))
    assert a.shape == b.shape
    assert np.abs(a - b).max() <= RTOL * np.abs(b).max()


def test_an_emitter_scene_runs_fused_one_step_per_call_with_the_numpy_frames():
    """Births are called from Python between one-step fused calls (each step of the
    emitter one compiled call); the frames are the NumPy backend's."""
    from animsim.backends import backend_line
    from animsim.steppers import Fused, make_stepper

    text = """
duration: 0.3
dt: 0.005
seed: 2
forces: [{type: gravity}, {type: drag, k: 0.001}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.2}]
emitters:
  - name: jet
    rate: 2000
    shape: {type: disc, center: [0, 0.02, 0], normal: [0, 1, 0], radius: 0.05}
    velocity: {mean: [0, 1.5, 0], spread: 0.3}
    lifetime: {mean: 0.2, spread: 0.05}
    mass: 0.001
    max_particles: 300
"""
    loaded = load_scene_text(text)
    fast = compile_scene(loaded.scene, loaded.name, backend="numba")
    assert isinstance(make_stepper(fast), Fused)
    assert "one step per call, births between calls" in backend_line(fast, "numba", "")
    frames = {}
    for backend, compiled in (("numba", fast), ("numpy", compile_scene(loaded.scene, loaded.name))):
        sink = MemorySink()
        result = run(compiled, [sink])
        assert result.status == "ok"
        frames[backend] = (sink.frames, result.meta["emitters"], result.force_evals)
    assert fast.emitters._step is not None  # the emitter's step took the compiled call
    assert frames["numba"][1] == frames["numpy"][1]  # the same births, drops and deaths
    assert frames["numba"][2] == frames["numpy"][2]  # and the same force evaluations counted
    assert len(frames["numba"][0]) == len(frames["numpy"][0])
    for a, b in zip(frames["numba"][0], frames["numpy"][0], strict=True):
        assert a.new_ids == b.new_ids
        np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-9)


STARTUP_PROBE = """
import json, sys
from animsim.cli import main
try:
    main(["run", sys.argv[1], "-o", sys.argv[2], "-q", "--backend", "numba"])
except SystemExit as exc:
    assert not exc.code, exc.code
import numba
from animsim import elements
from animsim.backends import fused_kernels
kernels = [*elements._JITTED.values()]
kernels += [d for d in vars(fused_kernels).values() if isinstance(d, numba.core.dispatcher.Dispatcher)]
used = [d for d in kernels if d.overloads]
print(json.dumps({
    "modules": sorted(m for m in sys.modules if m.startswith(("numba.np.linalg", "scipy.linalg"))),
    "loaded": sorted(f"{d.py_func.__module__}.{d.py_func.__qualname__}" for d in used),
    "hits": sum(sum(d.stats.cache_hits.values()) for d in used),
    "misses": sum(sum(d.stats.cache_misses.values()) for d in used),
}))
"""


def test_a_second_process_loads_its_kernels_from_the_disk_cache_without_numbas_compiler(tmp_path):
    """Start-up of a one-particle numba run: the kernels it needs (its one force, the empty
    stage, the chunk) come from numba's disk cache, and nothing more is set up. Loading
    through numba's own path first initialises its whole compiler (every implementation,
    SciPy's linalg among them: a quarter of the command's start); a kernel that compiles
    again in every process would show as a cache miss."""
    import json
    import subprocess
    import sys

    from tests.conftest import ROOT

    scene = tmp_path / "tiny.yaml"
    scene.write_text(
        "duration: 0.1\ndt: 0.001\nrecord: {every: 10}\n"
        "particles: [{id: p, mass: 1, position: [0, 0, 0]}]\nforces: [{type: gravity}]\n"
    )

    def probe() -> dict:
        out = subprocess.run(
            [sys.executable, "-c", STARTUP_PROBE, str(scene), str(tmp_path / "o.csv")],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=600,
            check=True,
        )
        return json.loads(out.stdout.strip().splitlines()[-1])

    probe()  # the first run on a machine compiles and writes the cache
    got = probe()
    assert got["misses"] == 0, got
    assert got["hits"] == len(got["loaded"]) >= 3, got
    # of the elements' kernels, only those of the scene's one force: its force, and its
    # released energy for the watchdog's checks inside the compiled steps
    assert sorted(k for k in got["loaded"] if not k.startswith("animsim.backends.")) == [
        "animsim.forces.gravity._kernel",
        "animsim.forces.gravity._released_energy",
    ], got
    assert got["modules"] == [], got


@pytest.mark.parametrize("g", [(0.0, -9.81, 0.0), (1.5, 0.0, -2.0), (0.0, 0.0, 0.0)])
def test_gravity_kernel_equals_accumulate_to_the_bit_signed_zeros_included(g):
    """An earlier force may leave -0.0 in a column gravity does not pull along; NumPy's
    accumulate skips that column, and so must the compiled kernel (0.0 * m added to -0.0
    would give +0.0)."""
    from animsim.forces.gravity import Gravity

    rng = np.random.default_rng(7)
    mass = rng.uniform(0.5, 2.0, 9)
    mass[3] = 0.0  # a pinned row or a dead slot
    x = rng.normal(size=(9, 3))
    start = rng.normal(size=(9, 3))
    start[::2] = -0.0
    term = Gravity(np.array(g), mass)
    ref = start.copy()
    term.accumulate(x, x, 0.0, ref)
    out = start.copy()
    fp, ip = term.numba_params()
    term.numba_kernel(x, x, 0.0, out, mass, fp, ip)
    assert out.tobytes() == ref.tobytes()


#: a spring beside the emitter: a force that reads other rows, so the newborns take the
#: Python path's full evaluation on numba instead of the compiled birth step
PENDULUM = """
particles:
  - {id: a, pinned: true, position: [0, 1, 0]}
  - {id: b, mass: 0.5, position: [0.3, 0.8, 0]}
springs: [{between: [a, b], ks: 50, kd: 0.1}]
"""


@pytest.mark.parametrize("extra", ["", PENDULUM], ids=["own-rows", "full-evaluation"])
def test_newborns_that_cross_the_plane_in_their_birth_step_match_numpy_to_the_bit(extra):
    """Born just above the ground and moving down: their birth step's rest moves them
    (the compiled birth step on numba, or the Python path's full evaluation beside a
    spring) and the plane meets them there; every frame equals the NumPy backend's, bit
    for bit, and none is behind the plane."""
    text = (
        extra
        + """
duration: 0.2
dt: 0.01
seed: 3
forces: [{type: gravity}, {type: drag, k: 0.01}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.6, friction: 0.3}]
emitters:
  - name: down
    rate: 3000
    shape: {type: disc, center: [0, 0.002, 0], normal: [0, 1, 0], radius: 0.1}
    velocity: {mean: [0.5, -3, 0], spread: 0.5}
    lifetime: {mean: 0.15, spread: 0.02}
    mass: 0.001
    max_particles: 500
"""
    )
    runs = {}
    for backend in ("numpy", "numba"):
        compiled = compile_scene(load_scene_text(text).scene, "t", backend=backend)
        sink = MemorySink()
        assert run(compiled, [sink]).status == "ok"
        runs[backend] = sink.frames
    assert (compiled.emitters._step is None) == bool(extra)  # which path the newborns took
    assert len(runs["numba"]) == len(runs["numpy"]) > 5
    for a, b in zip(runs["numba"], runs["numpy"], strict=True):
        assert a.position.tobytes() == b.position.tobytes()
        assert a.velocity.tobytes() == b.velocity.tobytes()
        assert len(a.position) == 0 or a.position[:, 1].min() >= 0.0
    assert len(runs["numba"][-1].position) > 100 + (2 if extra else 0)
