"""Bodies at rest sleep (scene key ``sleep``), on both backends, against facts known beforehand:

* a box dropped flat onto a floor with no bounce lands at t = sqrt(2 h / g); it falls asleep
  ``after`` seconds later (not before), and from then on its pose is bit-constant and its
  velocities exactly zero, while the same box with sleeping off keeps being stepped;
* a sleeping stack hit by a ball, a sleeping box hit by a particle and one pushed by a keyframed
  collider wake, and end where the same scene without sleeping ends;
* a body held by a spring, a pinned body and every body under an attractor never sleep;
* without the key nothing changes, and with it nothing changes until a body falls asleep;
* NumPy and numba agree to 1e-12;
* ten boxes stacked, asleep, stand for a minute on NumPy (in 11 s; awake, about 14 minutes).
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from animsim import api
from animsim.compile import compile_scene
from animsim.errors import SceneError

BACKENDS = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])
G = 9.81
SLEEP = "sleep: {speed: 0.005, after: 0.3}\n"
FLOOR = """forces: [{type: gravity}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.5}]
"""


def _run(text: str, backend: str) -> api.Trajectory:
    traj = api.simulate(api.loads(text, name="sleep"), backend=backend)
    assert traj.status == "ok", traj.failure
    return traj


def _asleep(traj: api.Trajectory, body: int) -> np.ndarray:
    """(frames,) bool: body ``body``'s velocities are exactly zero in the frame (asleep)."""
    w = traj.body_angular_velocities[:, body]
    v = traj.velocities[:, traj.velocities.shape[1] - traj.body_angular_velocities.shape[1] + body]
    return (v == 0.0).all(axis=1) & (w == 0.0).all(axis=1)


def _drop(height: float, duration: float, sleep: str = SLEEP) -> str:
    return f"""duration: {duration}
dt: 0.001
{FLOOR}{sleep}bodies:
  - {{id: box, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, mass: 1, restitution: 0, friction: 0.5,
     position: [0, {0.1 + height!r}, 0]}}
"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_dropped_box_falls_asleep_after_resting_and_then_stays_bit_still(backend):
    height = 0.2
    every = "record: {every: 1}\n"
    traj = _run(every + _drop(height, 1.0), backend)
    landed = math.sqrt(2 * height / G)  # free fall, and no bounce (restitution 0)
    asleep = _asleep(traj, 0)
    asleep[0] = False  # released at rest: its velocities start at zero
    first = int(np.argmax(asleep))
    assert asleep[first:].all() and not asleep[:first].any()
    # asleep `after` (0.3 s) after landing: not before, and within a few steps of it
    # (the step it lands in counts as a step at rest: -dt)
    assert landed + 0.3 - 0.001 <= traj.times[first] <= landed + 0.3 + 0.01, (landed, traj.times[first])
    x, q = traj.body_positions[first:, 0], traj.body_orientations[first:, 0]
    assert (x == x[0]).all() and (q == q[0]).all()  # bit-constant
    assert x[0, 1] == pytest.approx(0.1, abs=1e-3)  # on the floor, where it landed
    # the fact is sleeping's: without it the resting box is still stepped (velocities not zero)
    awake = _run(every + _drop(height, 1.0, sleep=""), backend)
    assert not _asleep(awake, 0)[first:].any()


def _stack_and_ball(sleep: str, duration: float) -> str:
    rows = "\n".join(
        f"  - {{id: c{i}, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, mass: 1, restitution: 0,"
        f" friction: 0.6, position: [0, {0.1 + 0.2 * i!r}, 0]}}"
        for i in range(2)
    )
    # the ball falls 1.2 m onto the stack's top face at 0.4 m: it lands at t = sqrt(2.4 / g) = 0.49 s
    return f"""duration: {duration}
dt: 0.002
{FLOOR}{sleep}bodies:
{rows}
  - {{id: ball, shape: {{type: sphere, radius: 0.05}}, mass: 0.5, restitution: 0.5, friction: 0.3,
     position: [0.03, 1.65, 0.02]}}
"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_ball_dropped_on_a_sleeping_stack_wakes_it_and_ends_as_without_sleeping(backend):
    hit = math.sqrt(2 * 1.2 / G)
    before = _run(_stack_and_ball(SLEEP, 0.46), backend)
    assert all(_asleep(before, b)[-1] for b in range(2)), "the stack sleeps before the ball lands"
    slept = _run(_stack_and_ball(SLEEP, hit + 0.2), backend)
    # woken by the hit: the stack answers the ball within 0.2 s (less than `after`)
    late = slept.times > hit + 0.01
    assert not _asleep(slept, 1)[late].all()
    assert not _asleep(slept, 0)[late].all()
    awake = _run(_stack_and_ball("", hit + 0.2), backend)
    # the stack asleep stood still where the stepped one stands within 1e-8 m: the two runs
    # meet the ball alike, and end within a tenth of a millimetre
    np.testing.assert_allclose(slept.body_positions[-1], awake.body_positions[-1], atol=1e-4)
    assert slept.body_positions[-1, 2, 1] == pytest.approx(0.45, abs=1e-3)  # the ball lies on top


def _box_and(extra: str, sleep: str, duration: float) -> str:
    return f"""duration: {duration}
dt: 0.001
{FLOOR}{sleep}{extra}
bodies:
  - {{id: box, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, mass: 1, restitution: 0, friction: 0.3,
     position: [0, 0.1, 0]}}
"""


# a particle thrown at the box's side: 3.88 m away at 5 m/s along x, it reaches the box at
# t = 0.776 s at the top of its arc (vy = g t / 2), at the height it left from, the box's centre
PARTICLE = (
    """particles: [{id: p, mass: 0.5, position: [-4.0, 0.1, 0], velocity: [5, 3.80628, 0], radius: 0.02}]"""
)

# a box collider that stands still until 0.8 s, then moves along x at 0.5 m/s, meets the box at
# 1.2 s and pushes it 0.2 m; it clears the floor by 2 cm and reaches above the box (a body meets
# a collider with its corners: the box's upper ones go in)
COLLIDER = """colliders:
  - {type: box, center: [-0.4, 0.17, 0], size: [0.2, 0.3, 0.4], restitution: 0, friction: 0,
     motion: {keyframes: [[0, [-0.4, 0.17, 0]], [0.8, [-0.4, 0.17, 0]], [1.6, [0.0, 0.17, 0]]]}}"""


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("what", ["particle", "collider"])
def test_a_sleeping_box_is_woken_by_a_particle_and_by_a_moving_collider(backend, what):
    extra = PARTICLE if what == "particle" else COLLIDER
    before = _run(_box_and(extra, SLEEP, 0.7), backend)
    assert _asleep(before, 0)[-1], "asleep before it is touched"
    slept = _run(_box_and(extra, SLEEP, 1.6), backend)
    awake = _run(_box_and(extra, "", 1.6), backend)
    moved = slept.body_positions[-1, 0, 0] - slept.body_positions[0, 0, 0]
    assert moved > 0.01, moved  # pushed along +x: it woke and answered
    assert not _asleep(slept, 0)[slept.times > 0.85].all()
    np.testing.assert_allclose(slept.body_positions[-1], awake.body_positions[-1], atol=1e-4)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_body_held_by_a_spring_and_a_pinned_body_never_sleep(backend):
    text = f"""duration: 1.5
dt: 0.001
{FLOOR}{SLEEP}particles: [{{id: hook, pinned: true, position: [1, 0.3, 0]}}]
springs:
  - {{between: [hook, {{body: held, at: [0, 0.1, 0]}}], ks: 50, kd: 20, rest: 0.0}}
bodies:
  - {{id: free, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, mass: 1, restitution: 0, position: [0, 0.1, 0]}}
  - {{id: held, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, mass: 1, restitution: 0, position: [1, 0.1, 0]}}
  - {{id: post, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, mass: 1, pinned: true, position: [2, 0.1, 0]}}
"""
    traj = _run(text, backend)
    free, held = _asleep(traj, 0), _asleep(traj, 1)
    assert free[-1]
    # the held box hangs still on its damped spring (its speed far below 0.005 m/s) and is awake
    assert np.abs(traj.velocities[-100:, 2]).max() < 0.005
    assert not held[1:].any()
    # a pinned body keeps its given velocity (0 here, so its velocities say nothing): the rule
    assert list(_sleep_of(api.loads(text)).may_sleep) == [True, False, False]
    explained = "\n".join(api.explain(api.loads(text, name="sleep"), backend=backend))
    assert "2 of 3 never sleep" in explained, explained


def _sleep_of(scene):
    # the body contacts' (the particle-body contacts share it)
    return next(s.sleep for s in compile_scene(scene).post_step if getattr(s, "sleep", None) is not None)


def test_a_force_that_changes_in_space_keeps_every_body_awake_gravity_does_not():
    # the rule is each force element's own (ForceElement.lets_bodies_sleep)
    def may_sleep(forces: str) -> np.ndarray:
        scene = api.loads(_drop(0.0, 0.1).replace("forces: [{type: gravity}]", forces))
        return _sleep_of(scene).may_sleep

    assert may_sleep("forces: [{type: gravity}, {type: drag, k: 0.1}]").all()
    assert not may_sleep("forces: [{type: gravity}, {type: attractor, position: [0, 5, 0], gm: 1}]").any()


@pytest.mark.parametrize("backend", BACKENDS)
def test_sleeping_changes_nothing_until_a_body_falls_asleep_and_is_off_by_default(backend):
    text = _stack_and_ball("", 0.6)
    plain = api.loads(text)
    assert plain.sleep is None
    assert "sleeping" not in "\n".join(api.explain(plain, backend=backend))
    off = _run(text, backend)
    never = _run(_stack_and_ball("sleep: {after: 10}\n", 0.6), backend)  # on, but nobody rests 10 s
    for field in ("positions", "velocities", "body_orientations", "body_angular_velocities"):
        assert np.array_equal(getattr(off, field), getattr(never, field)), field


@pytest.mark.skipif(len(BACKENDS) < 2, reason="numba not installed")
def test_numpy_and_numba_agree_through_sleeping_and_waking():
    text = _stack_and_ball(SLEEP, 1.0)
    a, b = _run(text, "numpy"), _run(text, "numba")
    for field in ("positions", "velocities", "body_orientations", "body_angular_velocities"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=1e-12, atol=1e-12)
    assert (_asleep(a, 0) == _asleep(b, 0)).all() and _asleep(a, 0).any()


def test_ten_boxes_stacked_fall_asleep_and_stand_for_a_minute_on_numpy():
    # the exact solution is every box at rest where it was put (tests/numerics/test_stacks.py)
    rows = "\n".join(
        f"  - {{id: c{i}, shape: {{type: box, size: [0.4, 0.4, 0.4]}}, density: 500, friction: 0.6,"
        f" restitution: 0, position: [0, {0.2 + 0.4 * i!r}, 0]}}"
        for i in range(10)
    )
    text = f"""duration: 60.0
dt: 0.016666666666666666
record: {{fps: 2}}
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.6}}]
sleep: {{}}
bodies:
{rows}
"""
    traj = _run(text, "numpy")
    x = traj.body_positions
    assert np.linalg.norm(x - x[0], axis=2).max() < 1e-6  # measured 3e-10 m
    assert all(_asleep(traj, b)[-1] for b in range(10))


def test_sleep_without_bodies_is_an_error_at_its_key():
    text = "duration: 0.1\nsleep: {}\nparticles: [{id: p, mass: 1, position: [0, 0, 0]}]\n"
    with pytest.raises(SceneError, match=r"sleep.*no bodies") as err:
        api.loads(text)
    assert ":2:" in str(err.value)  # line 2, where the key is


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_replay_from_a_kept_state_makes_the_steps_the_run_made(backend):
    """The watchdog traces a failure by replaying from a state kept before it (at step 0 here);
    the bodies' memory (warm starts, who sleeps and since when) is restored with that state, so
    the replayed step equals the step the run made, bit for bit: the box landed at about step
    202, the state is kept at step 256, the run fails at step 288, and the box would fall asleep
    at about step 302 (in a replay that kept step 288's clocks, at about step 270)."""
    from animsim.engine import STATUS_UNSTABLE, Failure, Guard, run
    from animsim.scene.loader import load_scene_text
    from animsim.steppers.base import CHECK_STRIDE

    fail_at = 18 * CHECK_STRIDE
    seen: dict[int, list[np.ndarray]] = {}

    class FailsLate(Guard):
        def check(self, state):
            if state.step == fail_at:
                seen.setdefault(state.step, []).append(
                    np.concatenate(
                        [state.particle_position, state.particle_velocity, state.body_angular_velocity]
                    )
                )
                return Failure(step=state.step, time=state.time, particle="box", reason="test")
            return None

    text = _drop(0.2, 1.0, sleep="sleep: {speed: 0.005, after: 0.1}\n")
    loaded = load_scene_text(text, "replay.yaml")
    compiled = compile_scene(loaded.scene, loaded.name, backend=backend)
    result = run(compiled, [], guard=FailsLate(compiled))
    assert result.status == STATUS_UNSTABLE and result.failure.step == fail_at
    first, replayed = seen[fail_at]  # checked once by the run, once by the replay
    np.testing.assert_array_equal(replayed, first)


def test_sleep_with_adaptive_steps_is_refused_at_its_key():
    text = _drop(0.2, 0.5).replace(
        "dt: 0.001", "dt: 0.001\nintegrator: {method: rk4, adaptive: {tolerance: 1e-6}}"
    )
    with pytest.raises(SceneError) as err:
        api.loads(text, name="sleep")
    assert "sleep" in str(err.value) and "adaptive" in str(err.value)
