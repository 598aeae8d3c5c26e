"""The numba backend's blocked chunks: pointwise scenes stepped a block of particles at a time.

When every force and every collision acts on each particle alone, the fused stepper runs
all of a call's steps on one block of rows before the next (animsim.backends.fused,
``blocked_chunk``). It must give the bits of the one-pass-per-step chunk (``fused_chunk``)
and of the NumPy backend, count the same force evaluations and the same steps a collision
changed, and stop after the same first non-finite step, however the blocks fall. The
blocks are made a few rows long here so that every scene has many block boundaries.
"""

from __future__ import annotations

import numpy as np
import pytest

import animsim.backends
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.integrators import FIXED_STEP
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text

pytest.importorskip("numba")

from animsim.backends import fused as fused_module  # after the skip: it imports numba

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


def _stepper(compiled, blocked: bool, monkeypatch):
    with monkeypatch.context() as m:
        if not blocked:
            m.setattr(animsim.backends, "fused_in_blocks", lambda compiled: False)
        stepper = fused_module.FusedStepper(compiled)
    assert stepper.blocked == blocked
    state = compiled.fresh_state()
    return stepper, state


def _advance_both(compiled, monkeypatch, chunk: int) -> list[tuple]:
    """Step the scene with both chunks, ``chunk`` steps per call; the per-call results."""
    compiled.dynamics.bind(compiled.fresh_state())  # equal masses; both states keep their own
    blocked, s_blocked = _stepper(compiled, True, monkeypatch)
    plain, s_plain = _stepper(compiled, False, monkeypatch)
    clock = compiled.clock
    times = np.array([clock.time(i) for i in range(clock.steps + 1)])
    dts = np.array([clock.step_size(i) for i in range(clock.steps)])
    calls = []
    k = 0
    while k < clock.steps:
        end = min(clock.steps, k + chunk)
        got = blocked.advance(s_blocked, times[k:end], dts[k:end])
        want = plain.advance(s_plain, times[k:end], dts[k:end])
        assert got == want, k
        assert (blocked.changed_steps, blocked.a0_valid) == (plain.changed_steps, plain.a0_valid)
        assert s_blocked.revision == s_plain.revision
        for a, b in (
            (s_blocked.particle_position, s_plain.particle_position),
            (s_blocked.particle_velocity, s_plain.particle_velocity),
        ):
            assert a.tobytes() == b.tobytes(), k  # the same bits, NaNs included
        calls.append(got)
        if got[2]:  # not finite: the loop stops here
            break
        k += got[0]
    return calls, blocked


@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_blocks_give_the_bits_counts_and_changed_steps_of_one_pass_per_step(integrator, monkeypatch):
    monkeypatch.setattr(fused_module, "BLOCK", SMALL_BLOCK)
    compiled = _compiled(SCENE, integrator)
    calls, blocked = _advance_both(compiled, monkeypatch, chunk=40)
    assert sum(c[0] for c in calls) == compiled.clock.steps
    assert blocked.changed_steps > 0  # the planes did something
    assert not any(c[2] for c in calls)


def test_a_block_longer_than_the_scene_and_the_default_block(monkeypatch):
    """The default block (one short block) and a block of exactly the scene's rows."""
    compiled = _compiled(SCENE)
    _advance_both(compiled, monkeypatch, chunk=150)
    monkeypatch.setattr(fused_module, "BLOCK", 43)
    _advance_both(compiled, monkeypatch, chunk=150)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_the_first_step_not_finite_is_the_same_wherever_it_falls(integrator, monkeypatch):
    """Strong drag on one very light particle, the scene's last row (alone in the last
    block), is unstable (k dt / m = 1,000): it overflows in the middle of a call while the
    other rows stay finite, so the earlier blocks have run past its step and are put back."""
    monkeypatch.setattr(fused_module, "BLOCK", SMALL_BLOCK)
    text = SCENE.replace("{type: drag, k: 0.05}", "{type: drag, k: 2.0}")
    last = text.rstrip("\n").rsplit("\n", 1)[0]
    text = last + "\n  - {id: light, mass: 2e-6, position: [0.1, 1.0, 0.1], velocity: [0, 1, 0]}\n"
    compiled = _compiled(text, integrator)
    calls, _ = _advance_both(compiled, monkeypatch, chunk=40)
    assert calls[-1][2]  # it blew up, at the same step on both
    steps = sum(c[0] for c in calls)
    assert 0 < steps < compiled.clock.steps and steps % 40 != 0, steps  # inside a call
    state = compiled.fresh_state()
    assert np.isfinite(state.particle_position).all()


@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_blocked_runs_equal_numpy_frames(integrator, monkeypatch):
    monkeypatch.setattr(fused_module, "BLOCK", SMALL_BLOCK)
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
