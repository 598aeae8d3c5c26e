"""The numba backend's blocked chunks: pointwise scenes stepped a block of particles at a time.

When every force and every collision acts on each particle alone, the fused stepper runs
all of a call's steps on one block of rows before the next (animsim.backends.fused_kernels,
``blocked_chunk``). It must give the bits of the one-pass-per-step chunk (``fused_chunk``)
and of the NumPy backend, count the same force evaluations and the same steps a collision
changed, and stop after the same first non-finite step, however the blocks fall. The
blocks are made a few rows long here so that every scene has many block boundaries.

The blocks of a call may run on several threads (``blocked_chunk_parallel``, the same code
with numba's parallel loop): every comparison runs three steppers side by side, the
one-pass-per-step chunk, the blocked chunk on one thread and its parallel build (with
numba's thread count 1 and 2), and asks for the same bits from all three.
"""

from __future__ import annotations

import numpy as np
import pytest

import animsim.backends
from animsim import thread_choice
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.integrators import FIXED_STEP
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text

pytest.importorskip("numba")

import numba

from animsim.backends import fused as fused_module  # after the skip: it imports numba
from animsim.backends import fused_kernels, kernel_calls

#: rows per block in these tests: 43 particles make 6 full blocks and one of 1 row
SMALL_BLOCK = 7


def _particles(count: int, seed: int) -> str:
    """Particles above, on and (pinned) over a ground plane: some fall and bounce, some rest
    on it (zero normal speed, pressed by gravity), some slide, some are pinned."""
    rng = np.random.default_rng(seed)
    lines = []
    for i in range(count):
        kind = i % 4
        x, z = (float(c) for c in rng.uniform(-1, 1, 2))
        if kind == 0:  # falling onto the plane within a few steps: bounces
            y, vel = rng.uniform(0.001, 0.05), [rng.uniform(-1, 1), rng.uniform(-3, -1), 0.0]
        elif kind == 1:  # resting on the plane, sliding
            y, vel = 0.0, [rng.uniform(-1, 1), 0.0, rng.uniform(-1, 1)]
        elif kind == 2:  # in the air
            y, vel = rng.uniform(0.2, 1.5), list(rng.uniform(-2, 2, 3))
        else:  # every eighth particle pinned (a moving anchor), the others thrown
            y, vel = rng.uniform(0.0, 0.5), list(rng.uniform(-1, 1, 3))
        pinned = ", pinned: true" if i % 8 == 3 else ""
        mass = float(rng.uniform(0.2, 2.0))
        y, vel = float(y), [float(c) for c in vel]
        lines.append(
            f"  - {{id: p{i}, mass: {mass!r}, position: [{x!r}, {y!r}, {z!r}], "
            f"velocity: [{vel[0]!r}, {vel[1]!r}, {vel[2]!r}]{pinned}}}"
        )
    return "\n".join(lines)


SCENE = f"""
duration: 0.3
dt: 0.002
seed: 4
record: {{every: 9}}
forces:
  - {{type: gravity}}
  - {{type: drag, k: 0.05}}
  - {{type: quadratic_drag, area: 0.01}}
  - {{type: wind, velocity: [3, 0, 1], k: 0.2, turbulence: 0.3}}
  - {{type: attractor, position: [0, 2, 0], gm: 0.5, softening: 0.1}}
  - {{type: vortex, center: [0, 0, 0], axis: [0, 1, 0], k: 0.3}}
planes:
  - {{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5, friction: 0.2}}
  - {{point: [0.8, 0, 0], normal: [-1, 0.2, 0], restitution: 0.9}}
  - {{point: [0, -0.05, 0], normal: [0, 1, 0], response: penalty, stiffness: 3000, damping: 2}}
particles:
{_particles(43, 1)}
"""


def _compiled(text: str, integrator: str | None = None):
    scene = load_scene_text(text).scene
    if integrator is not None:
        scene = scene.model_copy(update={"integrator": integrator})
    return compile_scene(scene, "t", backend="numba")


#: the kernels compared: one pass over every row per step, the blocked chunk, its parallel build
PLAIN, SERIAL, PARALLEL = "plain", "serial", "parallel"
#: numba's thread counts the parallel build is run with (2 needs two threads allowed)
THREADS = [
    1,
    pytest.param(2, marks=pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")),
]


@pytest.fixture
def threads(request):
    """numba's thread count for the test (its parameter), put back after it."""
    before = numba.get_num_threads()
    numba.set_num_threads(request.param)
    yield request.param
    numba.set_num_threads(before)


def _stepper(compiled, kind: str, monkeypatch):
    with monkeypatch.context() as m:
        if kind == PLAIN:
            m.setattr(animsim.backends, "fused_in_blocks", lambda compiled: False)
        stepper = fused_module.FusedStepper(compiled)
    assert stepper.blocked == (kind != PLAIN)
    # the build is chosen in _call, whatever numba's thread count and the scene's blocks
    stepper.parallel_blocks = False
    state = compiled.fresh_state()
    return stepper, state


def _call(kind: str, stepper, state, times, dts):
    """One call of ``stepper``, with the parallel build of the blocked chunk if ``kind`` says so."""
    if kind != PARALLEL:
        return stepper.advance(state, times, dts)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(fused_module, "blocked_chunk", fused_kernels.blocked_chunk_parallel)
        return stepper.advance(state, times, dts)


def _advance_all(compiled, monkeypatch, chunk: int) -> tuple[list[tuple], object]:
    """Step the scene with the three kernels, ``chunk`` steps per call; the per-call results
    (equal for all three) and the parallel build's stepper."""
    compiled.dynamics.bind(compiled.fresh_state())  # equal masses; every state keeps its own
    runs = {kind: _stepper(compiled, kind, monkeypatch) for kind in (PLAIN, SERIAL, PARALLEL)}
    plain, s_plain = runs[PLAIN]
    clock = compiled.clock
    times = np.array([clock.time(i) for i in range(clock.steps + 1)])
    dts = np.array([clock.step_size(i) for i in range(clock.steps)])
    calls = []
    k = 0
    while k < clock.steps:
        end = min(clock.steps, k + chunk)
        want = _call(PLAIN, plain, s_plain, times[k:end], dts[k:end])
        for kind in (SERIAL, PARALLEL):
            stepper, state = runs[kind]
            got = _call(kind, stepper, state, times[k:end], dts[k:end])
            assert got == want, (kind, k)
            assert (stepper.changed_steps, stepper.a0_valid) == (plain.changed_steps, plain.a0_valid), (
                kind,
                k,
            )
            assert state.revision == s_plain.revision, (kind, k)
            for a, b in (
                (state.particle_position, s_plain.particle_position),
                (state.particle_velocity, s_plain.particle_velocity),
            ):
                assert a.tobytes() == b.tobytes(), (kind, k)  # the same bits, NaNs included
            if stepper.method == fused_kernels.VERLET and stepper.a0_valid:
                assert stepper.work[0].tobytes() == plain.work[2].tobytes(), (kind, k)  # its cached force
        calls.append(want)
        if want[2]:  # not finite: the loop stops here
            break
        k += want[0]
    assert list(runs[PARALLEL][0]._chunks) == [fused_kernels.blocked_chunk_parallel]
    return calls, runs[PARALLEL][0], runs[PARALLEL][1]


@pytest.mark.parametrize("threads", THREADS, indirect=True)
@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_blocks_give_the_bits_counts_and_changed_steps_of_one_pass_per_step(integrator, threads, monkeypatch):
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    compiled = _compiled(SCENE, integrator)
    calls, blocked, _ = _advance_all(compiled, monkeypatch, chunk=40)
    assert sum(c[0] for c in calls) == compiled.clock.steps
    assert blocked.changed_steps > 0  # the planes did something
    assert not any(c[2] for c in calls)


@pytest.mark.parametrize("threads", THREADS, indirect=True)
def test_a_block_longer_than_the_scene_and_the_default_block(threads, monkeypatch):
    """The default block (one short block) and a block of exactly the scene's rows."""
    compiled = _compiled(SCENE)
    _advance_all(compiled, monkeypatch, chunk=150)
    monkeypatch.setattr(animsim.backends, "BLOCK", 43)
    _advance_all(compiled, monkeypatch, chunk=150)


def _in_the_air(count: int, seed: int) -> list[str]:
    """Particles far above every plane: none reaches one within SCENE's 0.3 s."""
    rng = np.random.default_rng(seed)
    lines = []
    for i in range(count):
        x, z = (float(c) for c in rng.uniform(-0.5, 0.5, 2))
        y = float(rng.uniform(3.0, 4.0))
        vel = [float(c) for c in rng.uniform(-0.5, 0.5, 3)]
        mass = float(rng.uniform(0.2, 2.0))
        lines.append(
            f"  - {{id: p{i}, mass: {mass!r}, position: [{x!r}, {y!r}, {z!r}], "
            f"velocity: [{vel[0]!r}, {vel[1]!r}, {vel[2]!r}]}}"
        )
    return lines


#: rows of SOME_BLOCKS that meet the ground: row 16 (block 2 of 7 rows) bounces from the
#: start, lower each time, and comes to rest on it late; row 38 (block 5) falls 3 mm and
#: comes to rest early
BOUNCING, FALLING = 16, 38


def _some_blocks(bouncing: bool = True, falling: bool = True) -> str:
    lines = _in_the_air(43, 5)
    if bouncing:
        lines[BOUNCING] = (
            "  - {id: bouncing, mass: 0.7, position: [0.1, 0.01, 0.2], velocity: [0.3, -1.0, 0.2]}"
        )
    if falling:
        lines[FALLING] = "  - {id: falling, mass: 1.3, position: [-0.2, 0.003, 0.1], velocity: [0, 0, 0]}"
    return SCENE.split("particles:\n")[0] + "particles:\n" + "\n".join(lines) + "\n"


@pytest.mark.parametrize("threads", THREADS, indirect=True)
@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet", "rk4"])
def test_steps_a_collision_changed_are_counted_over_every_block(integrator, threads, monkeypatch):
    """Only two blocks meet a plane, at steps that differ and steps they share: a step
    counts once when either block's particle was changed (the union over the blocks, not
    their sum nor one block's count), and Verlet's next force is evaluated again."""
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    compiled = _compiled(_some_blocks(), integrator)
    calls, blocked, state = _advance_all(compiled, monkeypatch, chunk=40)
    assert sum(c[0] for c in calls) == compiled.clock.steps
    # not every step (the bouncing particle is in the air between its first bounces), and
    # not only the steps of one of the two blocks: see test_the_two_blocks_collide_apart
    assert 0 < blocked.changed_steps < compiled.clock.steps
    assert state.particle_position[BOUNCING, 1] < 0.05 and state.particle_position[FALLING, 1] < 0.05


def test_the_two_blocks_collide_apart(monkeypatch):
    """What the test above relies on: each of the two particles alone (the other in the
    air) makes fewer steps changed than both, and together fewer than the sum (they
    share steps)."""
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    counts = {}
    for which, text in (
        ("both", _some_blocks()),
        ("bouncing", _some_blocks(falling=False)),
        ("falling", _some_blocks(bouncing=False)),
        ("neither", _some_blocks(bouncing=False, falling=False)),
    ):
        _, blocked, _ = _advance_all(_compiled(text), monkeypatch, chunk=40)
        counts[which] = blocked.changed_steps
    assert counts["neither"] == 0, counts
    assert 0 < counts["bouncing"] < counts["both"] and 0 < counts["falling"] < counts["both"], counts
    assert counts["both"] < counts["bouncing"] + counts["falling"], counts


def _crowd(count: int, seed: int):
    """SCENE's forces and planes on ``count`` particles (a strand without springs) thrown
    from random places above, on and below the ground's level."""
    head = SCENE.split("particles:\n")[0]
    text = head + (
        f"structures: [{{type: strand, id: s, start: [0, 0, 0], end: [1, 0, 0], count: {count}, mass: 0.5}}]\n"
    )
    compiled = _compiled(text)
    rng = np.random.default_rng(seed)
    compiled.initial.particle_position[:] = rng.uniform([-1, -0.02, -1], [1, 0.3, 1], (count, 3))
    compiled.initial.particle_velocity[:] = rng.uniform(-2, 2, (count, 3))
    return compiled


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
@pytest.mark.parametrize("threads", [2], indirect=True)
def test_many_blocks_on_two_threads_at_once(threads, monkeypatch):
    """Blocks long enough (64 rows, 40 steps a call) that both threads step one at the same
    time: work arrays shared between blocks would give other bits here (a race, so not
    every time; it did on each of a few tries)."""
    monkeypatch.setattr(animsim.backends, "BLOCK", 64)
    compiled = _crowd(64 * 40, 3)
    calls, blocked, _ = _advance_all(compiled, monkeypatch, chunk=40)
    assert sum(c[0] for c in calls) == compiled.clock.steps and blocked.changed_steps > 0


def _two_unstable(first: int, integrator: str, light: str = "2e-6") -> tuple[object, int]:
    """SCENE with strong drag and two light particles, rows 9 (second block) and 42 (alone in
    the last block): the one of mass ``light`` in row ``first`` overflows first, the other
    (1e-3) later; the scene, and the row of the other one."""
    other = 42 if first == 9 else 9
    text = SCENE.replace("{type: drag, k: 0.05}", "{type: drag, k: 2.0}")
    lines = text.rstrip("\n").split("\n")[:-1]  # without p42
    rows = {first: ("light", light), other: ("later", "1e-3")}
    start = next(k for k, line in enumerate(lines) if "id: p0," in line)
    lines.append("")
    for row, (name, mass) in rows.items():
        lines[start + row] = (
            f"  - {{id: {name}, mass: {mass}, position: [0.1, 1.0, 0.1], velocity: [0, 1, 0]}}"
        )
    return _compiled("\n".join(lines) + "\n", integrator), other


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("threads", THREADS, indirect=True)
@pytest.mark.parametrize("first", [42, 9])
@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_the_first_step_not_finite_is_the_same_wherever_it_falls(integrator, first, threads, monkeypatch):
    """Strong drag makes two light particles unstable: the lighter one (row ``first``: the
    last block, or the second) overflows first, in the middle of a call, while the other
    rows stay finite; the other one would overflow a few steps later in the same call
    (checked below). So the blocks that ran past the first step not finite (all the others,
    on several threads; on one, those before it) are put back and run again up to it, the
    other failing block too, and the chunk stops at the earlier of the two failures
    whichever block is first."""
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    compiled, other = _two_unstable(first, integrator)
    calls, _, state = _advance_all(compiled, monkeypatch, chunk=40)
    assert calls[-1][2]  # it blew up, at the same step on all three
    steps = sum(c[0] for c in calls)
    assert 0 < steps < compiled.clock.steps and steps % 40 != 0, steps  # inside a call
    finite = np.isfinite(np.hstack([state.particle_position, state.particle_velocity])).all(axis=1)
    assert not finite[first] and finite[np.arange(43) != first].all()
    later, _ = _two_unstable(first, integrator, light="1.0")  # only the other one fails
    later_calls, _, later_state = _advance_all(later, monkeypatch, chunk=40)
    later_steps = sum(c[0] for c in later_calls)
    assert later_calls[-1][2]
    assert not np.isfinite(
        np.hstack([later_state.particle_position, later_state.particle_velocity])[other]
    ).all()
    assert steps < later_steps < steps - steps % 40 + 40, (steps, later_steps)
    state = compiled.fresh_state()
    assert np.isfinite(state.particle_position).all()


@pytest.mark.parametrize("threads", THREADS, indirect=True)
@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_blocked_runs_equal_numpy_frames(integrator, threads, monkeypatch):
    """Whole runs: the stepper picks the parallel build itself when numba has two threads."""
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    monkeypatch.setattr(animsim.backends, "PARALLEL_MIN_BLOCKS", 2)
    frames = {}
    for backend in ("numba", "numpy"):
        scene = load_scene_text(SCENE).scene.model_copy(update={"integrator": integrator})
        compiled = compile_scene(scene, "t", backend=backend)
        sink = MemorySink()
        result = run(compiled, [sink])
        frames[backend] = (result.status, result.steps_taken, result.force_evals, sink)
    (fast_status, fast_steps, fast_evals, fast), (status, steps, evals, ref) = (
        frames["numba"],
        frames["numpy"],
    )
    assert (fast_status, fast_steps, fast_evals) == (status, steps, evals)
    np.testing.assert_array_equal(fast.positions(), ref.positions())
    np.testing.assert_array_equal(fast.velocities(), ref.velocities())


def test_blocks_are_chosen_for_pointwise_scenes_only():
    from animsim.backends import backend_line, fused_in_blocks
    from animsim.steppers import Fused, make_stepper

    pointwise = _compiled(SCENE)
    assert fused_in_blocks(pointwise) and isinstance(make_stepper(pointwise), Fused)
    assert fused_module.FusedStepper(pointwise).blocked
    assert "in blocks of particles" in backend_line(pointwise, "numba", "")
    springs = _compiled(
        SCENE + "springs:\n  - {between: [p0, p1], ks: 50}\n"
    )  # a spring reads two particles' rows
    assert isinstance(make_stepper(springs), Fused)
    assert not fused_in_blocks(springs) and not fused_module.FusedStepper(springs).blocked
    assert "in blocks" not in backend_line(springs, "numba", "")
    sphere = _compiled(SCENE + "colliders: [{type: sphere, center: [0, -1, 0], radius: 0.5}]\n")
    assert isinstance(make_stepper(sphere), Fused)  # static colliders fuse, not in blocks
    assert not fused_in_blocks(sphere) and not fused_module.FusedStepper(sphere).blocked


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
@pytest.mark.parametrize("threads", [2], indirect=True)
def test_the_parallel_build_runs_for_enough_blocks_and_threads(threads, monkeypatch):
    """From PARALLEL_MIN_BLOCKS blocks on, and only while numba has several threads."""
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    clock_times = np.array([0.0, 0.002, 0.004])
    dts = np.full(2, 0.002)
    for blocks, count, wanted in (
        (animsim.backends.PARALLEL_MIN_BLOCKS, 2, fused_kernels.blocked_chunk_parallel),
        (animsim.backends.PARALLEL_MIN_BLOCKS, 1, fused_kernels.blocked_chunk),
        (animsim.backends.PARALLEL_MIN_BLOCKS - 1, 2, fused_kernels.blocked_chunk),
    ):
        compiled = _crowd(SMALL_BLOCK * blocks, 1)
        compiled.dynamics.bind(compiled.fresh_state())
        stepper = fused_module.FusedStepper(compiled)
        numba.set_num_threads(count)
        stepper.advance(compiled.fresh_state(), clock_times, dts)
        assert list(stepper._chunks) == [wanted], (blocks, count)


def test_threads_is_numba_thread_count_during_a_run_only():
    """compile_scene(threads=) holds numba's threads during the run, then gives them back."""
    from animsim.errors import UsageError

    before = numba.get_num_threads()
    seen = []
    compiled = compile_scene(load_scene_text(SCENE).scene, "t", backend="numba", threads=1)
    run(compiled, [], observers=[lambda state: seen.append(numba.get_num_threads())])
    assert seen and set(seen) == {1} and numba.get_num_threads() == before
    for bad in (0, -1, 1.5, True):
        with pytest.raises(UsageError, match="threads"):
            compile_scene(load_scene_text(SCENE).scene, "t", backend="numba", threads=bad)
    too_many = compile_scene(
        load_scene_text(SCENE).scene, "t", backend="numba", threads=numba.config.NUMBA_NUM_THREADS + 1
    )
    with pytest.raises(UsageError, match="NUMBA_NUM_THREADS"):
        run(too_many, [])
    assert numba.get_num_threads() == before
    numpy = compile_scene(load_scene_text(SCENE).scene, "t", backend="numpy", threads=1)
    run(numpy, [], observers=[lambda state: seen.append(numba.get_num_threads())])
    assert seen[-1] == before  # NumPy runs leave numba alone


SMALL_RUN = """
import numba.np.ufunc.parallel as pool
from animsim.backends import fused_kernels
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.scene.loader import load_scene_text

text = "duration: 0.1\\ndt: 0.001\\nforces: [{type: gravity}]\\n"
text += "planes: [{point: [0, 0, 0], normal: [0, 1, 0]}]\\nparticles: [{id: p, mass: 1, position: [0, 1, 0]}]\\n"
compiled = compile_scene(load_scene_text(text).scene, "t", backend="numba")
assert "in blocks" in compiled.stages[-1], compiled.stages
assert run(compiled, []).status == "ok"
print(bool(fused_kernels.blocked_chunk.overloads), bool(fused_kernels.blocked_chunk_parallel.overloads), pool._is_initialized)
"""


def test_a_small_scene_neither_loads_the_parallel_build_nor_starts_threads():
    """A one-particle run (one block) starts no faster with the parallel build around: the
    build is not loaded and numba's thread pool not started."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    out = subprocess.run(
        [sys.executable, "-c", SMALL_RUN], capture_output=True, text=True, cwd=root, check=True
    )
    assert out.stdout.split() == ["True", "False", "False"], out


def test_explain_says_whether_the_blocks_share_the_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    from animsim.backends import backend_line

    compiled = _compiled(SCENE)
    n = compiled.system.particle_count
    monkeypatch.setattr(animsim.backends, "PARALLEL_MIN_BLOCKS", -(-n // animsim.backends.BLOCK) + 1)
    assert "in blocks of particles (no particle acts on another) on one thread" in backend_line(
        compiled, "numba", ""
    )
    monkeypatch.setattr(animsim.backends, "PARALLEL_MIN_BLOCKS", 1)
    compiled.threads = 2
    assert "shared among 2 threads" in backend_line(compiled, "numba", "")
    compiled.threads = 1
    assert "shared among 1 thread)" in backend_line(compiled, "numba", "")


def test_the_chooser_keeps_the_faster_build_and_follows_a_change_of_load(monkeypatch):
    """Both builds are timed first; the one with the lower time per step is kept; every
    RETRY_EVERY calls (these calls are long enough for RETRY_SECONDS) the other is tried
    again, and kept once it is faster."""
    monkeypatch.setattr(thread_choice, "RETRY_SECONDS", 0.0)
    chooser = thread_choice.BuildChooser()
    trial = thread_choice.TRIAL_CALLS
    picks = []
    for _ in range(2 * trial):  # the trials alternate, threads first
        parallel = chooser.pick()
        picks.append(parallel)
        chooser.record(parallel, 8e-3 if parallel else 1e-3, 4)  # busy cores: threads wait
    assert picks == [True, False] * trial
    assert chooser.parallel is False
    tried = []
    for _ in range(3 * (thread_choice.RETRY_EVERY + 1)):
        parallel = chooser.pick()
        tried.append(parallel)
        chooser.record(parallel, 8e-3 if parallel else 1e-3, 4)
    # one call after every RETRY_EVERY tries the threads again (and they stay slower)
    assert sum(tried) == 3 and chooser.parallel is False
    booked = list(chooser.recent[True]), chooser.calls
    chooser.record(True, 0.0, 0)  # a call that took no step is not a timing
    assert (chooser.recent[True], chooser.calls) == booked
    # the other jobs end: the threads are now twice as fast; after enough retries they win
    for _ in range(trial * thread_choice.RETRY_EVERY + 1):
        parallel = chooser.pick()
        chooser.record(parallel, 0.5e-3 if parallel else 1e-3, 4)
    assert chooser.parallel is True and chooser.pick() is True


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
@pytest.mark.parametrize("threads", [2], indirect=True)
def test_both_builds_load_before_the_run_and_switching_keeps_the_bits(threads, monkeypatch):
    """warm_up loads both builds (none compiles inside the timed run), and a run whose calls
    switch between them steps the same bits as one that never shares the blocks."""
    monkeypatch.setattr(animsim.backends, "BLOCK", SMALL_BLOCK)
    compiled = _crowd(SMALL_BLOCK * animsim.backends.PARALLEL_MIN_BLOCKS, 5)
    ref_state = compiled.fresh_state()
    compiled.dynamics.bind(ref_state)
    times = np.arange(41) * 0.002
    dts = np.full(40, 0.002)
    serial = fused_module.FusedStepper(compiled)
    for k in range(0, 40, 4):
        serial._advance(ref_state, times[k : k + 5], dts[k : k + 4], False)
    state = compiled.fresh_state()
    compiled.dynamics.bind(state)
    stepper = fused_module.FusedStepper(compiled)
    stepper.warm_up(state)
    assert set(stepper._chunks) == {fused_kernels.blocked_chunk, fused_kernels.blocked_chunk_parallel}
    used = []
    for k in range(0, 40, 4):
        used.append(stepper.chooser.pick())
        stepper.advance(state, times[k : k + 5], dts[k : k + 4])
    assert True in used and False in used
    assert np.array_equal(state.particle_position.view(np.int64), ref_state.particle_position.view(np.int64))
    assert np.array_equal(state.particle_velocity.view(np.int64), ref_state.particle_velocity.view(np.int64))


def test_the_chooser_switches_only_for_a_clear_margin(monkeypatch):
    """Timings of single calls scatter: after the trials a build close to the kept one's
    speed (within SWITCH_MARGIN) does not take over; a clearly faster one does."""
    monkeypatch.setattr(thread_choice, "RETRY_SECONDS", 0.0)
    chooser = thread_choice.BuildChooser()
    for _ in range(2 * thread_choice.TRIAL_CALLS):
        parallel = chooser.pick()
        chooser.record(parallel, 1.1e-3 if parallel else 1e-3, 1)
    assert chooser.parallel is False  # the trials: the faster, however close
    near = 1e-3 / (0.9 * thread_choice.SWITCH_MARGIN)  # faster, but not by the margin
    for _ in range(4 * thread_choice.RETRY_EVERY):
        parallel = chooser.pick()
        chooser.record(parallel, near if parallel else 1e-3, 1)
    assert chooser.parallel is False
    clear = 1e-3 / (1.1 * thread_choice.SWITCH_MARGIN)
    for _ in range(4 * thread_choice.RETRY_EVERY):
        parallel = chooser.pick()
        chooser.record(parallel, clear if parallel else 1e-3, 1)
    assert chooser.parallel is True


def test_the_chooser_tries_the_other_build_once_both_calls_and_time_have_passed():
    """Short calls (a step of a fountain) would pay for a trial every RETRY_EVERY calls: a
    trial also waits for RETRY_SECONDS on the kept build; long calls keep the call count."""

    def one_thread_calls(chooser, calls: int, threaded: float) -> list[int]:
        """The calls (of ``calls``) that ran on one thread, each taking twice ``threaded``."""
        picks = []
        for _ in range(calls):
            parallel = chooser.pick()
            picks.append(parallel)
            chooser.record(parallel, threaded if parallel else 2 * threaded, 1)
        return [i for i, p in enumerate(picks) if not p]

    every = thread_choice.RETRY_EVERY
    short = thread_choice.RETRY_SECONDS / (4 * every)  # 4 x RETRY_EVERY calls a trial
    chooser = thread_choice.BuildChooser()
    one_thread_calls(chooser, 2 * thread_choice.TRIAL_CALLS, short)
    assert chooser.parallel is True
    tried = one_thread_calls(chooser, 13 * every, short)
    assert len(tried) == 3
    assert np.diff(tried).tolist() == [4 * every + 1] * 2
    long = 2 * thread_choice.RETRY_SECONDS  # each call alone is long enough: RETRY_EVERY counts
    chooser = thread_choice.BuildChooser()
    one_thread_calls(chooser, 2 * thread_choice.TRIAL_CALLS, long)
    assert one_thread_calls(chooser, 4 * every, long) == [every + (every + 1) * j for j in range(3)]


#: more particles than two pieces of the quick check, under gravity, an attractor (both
#: releasing), drag, and a penalty floor (elastic): every watched element pointwise
PIECES = """
duration: 0.04
dt: 0.002
seed: 2
forces:
  - {type: gravity}
  - {type: drag, k: 0.05}
  - {type: attractor, position: [0, 2, 0], gm: 0.5, softening: 0.1}
planes:
  - {point: [0, -0.05, 0], normal: [0, 1, 0], response: penalty, stiffness: 3000, damping: 2}
"""


def _pieces_scene():
    count = 2 * fused_kernels.CHECK_PIECE + 1234
    text = PIECES + (
        f"structures: [{{type: strand, id: s, start: [0, 0, 0], end: [1, 0, 0], count: {count}, mass: 0.5}}]\n"
    )
    compiled = _compiled(text)
    rng = np.random.default_rng(8)
    compiled.initial.particle_position[:] = rng.uniform([-1, -0.1, -1], [1, 0.3, 1], (count, 3))
    compiled.initial.particle_velocity[:] = rng.uniform(-2, 2, (count, 3))
    return compiled


def test_the_quick_check_in_pieces_sums_and_decides_as_the_one_pass_check():
    """The quick check shared among threads: each piece of rows summed alone, the pieces
    added in order. Its sums equal NumPy's to rounding, it counts the movable rows, it finds
    a number that is not finite at either end of any piece, and it passes and fails where
    the one-thread check does."""
    from animsim.measures.watchdog import EnergyWatch

    compiled = _pieces_scene()
    state = compiled.fresh_state()
    compiled.dynamics.bind(state)
    watch = EnergyWatch(compiled, compiled.clock.dt)
    watch.bind(state)
    watch.reset(compiled.initial)
    state.particle_position[:] += 0.01  # some energy released since the books opened
    elastic, releasing = watch.elastic, watch.releasing
    assert [type(t).__name__ for t in releasing] == ["Gravity", "Attractor"] and len(elastic) == 1
    tables = (*kernel_calls.energy_table(elastic), *kernel_calls.energy_table(releasing))
    u_refs = kernel_calls.array_tuple(list(watch.u_ref), np.float64)
    n = len(state.particle_mass)
    pieces = -(-n // fused_kernels.CHECK_PIECE)
    assert pieces == 3
    room = fused_module.check_room(pieces, tables)
    assert room[2].shape == (pieces, 4)  # kinetic, the spring, gravity, the attractor
    x, v, m = state.particle_position, state.particle_velocity, state.particle_mass.copy()

    def both(limit: float, x: np.ndarray, m: np.ndarray = m) -> tuple[bool, bool, float, float]:
        books = np.array([1.0, 0.0, 0.0, 0.0, 0.0, limit])
        one = fused_kernels.quick_check_state(
            x, v, 0.1, m, *tables, u_refs, watch.x_ref, np.zeros(0), books, True
        )
        split = books.copy()
        split[3] = 0.0
        shared = fused_kernels.quick_check_pieces(
            x, v, 0.1, m, *tables, u_refs, watch.x_ref, np.zeros(0), split, True, *room
        )
        return bool(one), bool(shared), books[3], split[3]

    assert both(1e30, x) == (True, True, n, n)
    sums = room[2].copy()
    dead = m.copy()
    dead[::5] = 0.0  # rows the count leaves out (a pool's dead slots)
    assert both(1e30, x, dead)[2:] == (np.count_nonzero(dead),) * 2
    kinetic = float(np.dot(m, np.einsum("ij,ij->i", v, v)))
    np.testing.assert_allclose(sums[:, 0].sum(), kinetic, rtol=1e-12)
    np.testing.assert_allclose(sums[:, 1].sum(), elastic[0].potential(x), rtol=1e-12)
    for k, (t, u) in enumerate(zip(releasing, watch.u_ref, strict=True)):
        np.testing.assert_allclose(sums[:, 2 + k].sum(), t.released(x, watch.x_ref, u), rtol=1e-10)
    assert both(0.0, x)[:2] == (False, False)
    # the pieces' sums combined: H / B as NumPy sums it, with books h0 = 1 and nothing else
    h = 0.5 * kinetic + elastic[0].potential(x)
    released = sum(t.released(x, watch.x_ref, u) for t, u in zip(releasing, watch.u_ref, strict=True))
    ratio = h / (1.0 + max(released, 0.0))
    assert both(ratio * (1 + 1e-9), x)[:2] == (True, True)
    assert both(ratio * (1 - 1e-9), x)[:2] == (False, False)
    piece = fused_kernels.CHECK_PIECE
    for row in (0, piece - 1, piece, 2 * piece - 1, 2 * piece, n - 1):
        bad = x.copy()
        bad[row, row % 3] = np.inf if row % 2 else np.nan
        assert both(1e30, bad)[:2] == (False, False), row


def test_the_quick_check_in_pieces_has_a_column_for_the_kernel_standing_in_for_no_elements():
    """A scene with nothing elastic and nothing releasing energy (a free emitter): the
    compiled check still calls one kernel for each empty list (one that adds nothing),
    so its room has a column for each. Sized from the lists instead, the check wrote past
    its room's end (a heap corruption that aborted a hypothesis run)."""
    empty = (*kernel_calls.energy_table([]), *kernel_calls.energy_table([]))
    assert len(empty[0]) == len(empty[3]) == 1
    pieces = 3
    ok, movable, sums = fused_module.check_room(pieces, empty)
    assert sums.shape == (pieces, 3)
    n = pieces * fused_kernels.CHECK_PIECE - 7
    rng = np.random.default_rng(3)
    x, v, m = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.uniform(0.5, 1.0, n)
    books = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 1e30])
    passed = fused_kernels.quick_check_pieces(
        x, v, 0.0, m, *empty, (np.zeros(0),), x.copy(), np.zeros(0), books, True, ok, movable, sums
    )
    assert passed and books[3] == n
    np.testing.assert_allclose(sums[:, 0].sum(), np.dot(m, np.einsum("ij,ij->i", v, v)), rtol=1e-12)
    assert not sums[:, 1:].any()  # the stand-in kernels add nothing


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
@pytest.mark.parametrize("threads", [2], indirect=True)
def test_a_run_checked_in_pieces_on_two_threads_is_the_run_on_one(threads, monkeypatch):
    """A run whose quick checks share their pieces among two threads: the same bits and
    status as on one thread, where the one-pass check runs."""
    used = []
    pieces = fused_kernels.quick_check_pieces

    def counted(*args):
        used.append(True)
        return pieces(*args)

    results = []
    for count in (2, 1):
        numba.set_num_threads(count)
        compiled = _pieces_scene()
        with monkeypatch.context() as m:
            m.setattr(fused_module, "quick_check_pieces", counted)
            results.append(run(compiled, []))
        assert bool(used) == (count == 2)
        used.clear()
    two, one = results
    assert two.status == one.status == "ok"
    assert two.final_state.particle_position.tobytes() == one.final_state.particle_position.tobytes()
    assert two.final_state.particle_velocity.tobytes() == one.final_state.particle_velocity.tobytes()
