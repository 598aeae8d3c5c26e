"""Rolling resistance of rigid bodies (``rolling_friction``) against closed forms.

A solid sphere (I = 2/5 m r^2) rolling without slipping on a floor, with a resisting torque
mu_r N at the contact: m a = F (friction at the contact), I alpha = -r F - mu_r N and
a = r alpha give a = -(5/7) mu_r g / r, so it stops after v0^2 / (2 a). On a slope of angle
theta it is held while r m g sin(theta) <= mu_r m g cos(theta), tan(theta) <= mu_r / r, and
above that rolls down at a = (5/7) g (sin(theta) - (mu_r / r) cos(theta)). Every expectation is
computed here from these formulas, never read back from the code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import animsim
from tests.numerics.test_bodies import BACKENDS, G, _run

R = 0.1


def _floor(friction: float = 0.5) -> str:
    return f"planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: {friction}}}]"


def _ball(extra: str, mu_r: float | None) -> str:
    key = "" if mu_r is None else f", rolling_friction: {mu_r}"
    return f"{{id: ball, shape: {{type: sphere, radius: {R}}}, mass: 1, {extra}{key}}}"


def _rolling_ball(
    mu_r: float | None, v0: float, duration: float, extra: str = "", **kw: object
) -> animsim.Trajectory:
    """A ball set rolling without slipping along x at v0 on a floor."""
    return _run(
        f"""
duration: {duration}
dt: 0.001
record: {{every: 10}}
forces: [{{type: gravity}}]
{_floor()}
{extra}
bodies:
  - {_ball(f"position: [0, {R}, 0], velocity: [{v0}, 0, 0], angular_velocity: [0, 0, {-v0 / R}]", mu_r)}
""",
        **kw,
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_rolling_ball_decelerates_at_five_sevenths_mu_r_g_over_r_and_stops(backend: str) -> None:
    mu_r, v0 = 0.005, 1.0
    a = 5 / 7 * mu_r * G / R
    stop_time, stop_distance = v0 / a, v0**2 / (2 * a)  # 2.85 s, 1.43 m
    traj = _rolling_ball(mu_r, v0, 3.5, backend=backend)
    x = traj.body_positions[:, 0, 0]
    assert abs(x[-1] - stop_distance) < 0.01 * stop_distance, (x[-1], stop_distance)
    # on the way: v = v0 - a t, still rolling without slipping (omega_z = -v / r)
    rolling = traj.times < stop_time - 0.05
    v = traj.velocities[:, 0, 0]
    np.testing.assert_allclose(v[rolling], v0 - a * traj.times[rolling], atol=1e-6)
    np.testing.assert_allclose(traj.body_angular_velocities[rolling, 0, 2] * R, -v[rolling], atol=1e-6)
    # and then at rest, not turning either way
    assert abs(v[-1]) < 1e-6 and np.abs(traj.body_angular_velocities[-1, 0]).max() < 1e-5


@pytest.mark.parametrize("backend", BACKENDS)
def test_without_the_key_a_ball_rolls_on_at_its_speed(backend: str) -> None:
    traj = _rolling_ball(None, 1.0, 1.0, backend=backend)
    np.testing.assert_allclose(traj.velocities[:, 0, 0], 1.0, atol=1e-9)


def _on_slope(degrees: float, mu_r: float, backend: str) -> animsim.Trajectory:
    """A ball set down at rest on a slope falling toward +x, touching it."""
    th = math.radians(degrees)
    n = (-math.sin(th), math.cos(th), 0.0)
    return _run(
        f"""
duration: 2.0
dt: 0.001
record: {{every: 10}}
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [{n[0]!r}, {n[1]!r}, 0], restitution: 0, friction: 0.5}}]
bodies:
  - {_ball(f"position: [{R * n[0]!r}, {R * n[1]!r}, 0]", mu_r)}
""",
        backend=backend,
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_ball_on_a_slope_stays_below_atan_mu_r_over_r_and_rolls_above(backend: str) -> None:
    mu_r = 0.01  # mu_r / r = 0.1: the ball is held up to atan(0.1) = 5.71 degrees
    held = _on_slope(4.0, mu_r, backend)
    moved = np.linalg.norm(held.body_positions[:, 0] - held.body_positions[0, 0], axis=1)
    assert moved.max() < 1e-6, moved.max()
    # without rolling resistance the same ball rolls away (5/7 g sin(4 deg) = 0.48 m/s^2)
    free = _on_slope(4.0, 0.0, backend)
    assert np.linalg.norm(free.body_positions[-1, 0] - free.body_positions[0, 0]) > 0.5
    th = math.radians(8.0)
    a = 5 / 7 * G * (math.sin(th) - mu_r / R * math.cos(th))
    steep = _on_slope(8.0, mu_r, backend)
    down = np.linalg.norm(steep.body_positions[-1, 0] - steep.body_positions[0, 0])
    want = 0.5 * a * steep.times[-1] ** 2  # 0.56 m
    assert abs(down - want) < 0.01 * want, (down, want)


@pytest.mark.parametrize("backend", BACKENDS)
def test_pair_of_bodies_combines_rolling_resistance_as_friction(backend: str) -> None:
    """A ball rolling on a pinned slab body: the pair's mu_r is sqrt(0.008 * 0.002) = 0.004,
    the geometric mean, as the friction of two bodies."""
    v0, mu_pair = 1.0, math.sqrt(0.008 * 0.002)
    traj = _run(
        f"""
duration: 1.0
dt: 0.001
record: {{every: 10}}
forces: [{{type: gravity}}]
bodies:
  - {_ball(f"position: [0, {R}, 0], velocity: [{v0}, 0, 0], angular_velocity: [0, 0, {-v0 / R}]", 0.008)}
  - {{id: slab, shape: {{type: box, size: [6, 0.2, 1]}}, mass: 100, pinned: true, position: [2, -0.1, 0],
      rolling_friction: 0.002}}
""",
        backend=backend,
    )
    a = 5 / 7 * mu_pair * G / R
    # the speed falls at a from the first step on (which sets the ball down on the slab)
    later = traj.times >= 0.01
    slope = np.polyfit(traj.times[later], traj.velocities[later, 0, 0], 1)[0]
    assert abs(slope + a) < 1e-3 * a, (slope, -a)


def _sliding_box(mu_r: float | None, backend: str) -> animsim.Trajectory:
    key = "" if mu_r is None else f", rolling_friction: {mu_r}"
    return _run(
        f"""
duration: 1.0
dt: 0.001
record: {{every: 10}}
forces: [{{type: gravity}}]
{_floor(0.3)}
bodies:
  - {{id: b, shape: {{type: box, size: [0.2, 0.1, 0.2]}}, mass: 2, position: [0, 0.05, 0], velocity: [2, 0, 0.5]{key}}}
""",
        backend=backend,
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_sliding_box_that_does_not_roll_is_unaffected(backend: str) -> None:
    """A box sliding flat on the floor does not turn: the rolling resistance has nothing to
    stop, and the slide is the one without the key (which stops in v0^2 / (2 mu g))."""
    plain = _sliding_box(None, backend)
    rolled = _sliding_box(0.01, backend)
    np.testing.assert_allclose(rolled.body_positions, plain.body_positions, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rolled.body_orientations, plain.body_orientations, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rolled.velocities, plain.velocities, rtol=0, atol=1e-12)
    speed = math.hypot(2, 0.5)
    end = np.linalg.norm(plain.body_positions[-1, 0, [0, 2]])
    assert abs(end - speed**2 / (2 * 0.3 * G)) < 0.02 * end


def test_a_ball_that_stopped_rolling_falls_asleep() -> None:
    """With ``sleep``, a ball stopped by its rolling resistance sleeps (velocities exactly 0
    from then on); the same ball without it never stops, so never sleeps."""
    sleep = "sleep: {speed: 0.005, after: 0.5}"
    stopped = _rolling_ball(0.02, 0.5, 1.5, extra=sleep)  # stops after 0.36 s
    assert (stopped.velocities[-20:, 0] == 0.0).all()
    assert (stopped.body_angular_velocities[-20:, 0] == 0.0).all()
    rolling = _rolling_ball(None, 0.5, 1.5, extra=sleep)
    assert rolling.velocities[-1, 0, 0] == pytest.approx(0.5, abs=1e-9)


#: spheres rolling into each other and a ball resting on a box (the stack's level pass); a
#: capsule rolling on its side into two balls (boxes and capsules are not allowed together)
PARITY_BODIES = {
    "spheres and a box": """
  - {id: a, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0, 0.1, 0], velocity: [2, 0, 0.3],
      angular_velocity: [3, 0, -20], rolling_friction: 0.004}
  - {id: b, shape: {type: sphere, radius: 0.08}, mass: 0.5, position: [0.6, 0.08, 0.05],
      rolling_friction: 0.002, friction: 0.3}
  - {id: d, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0.3, 0.31, 0], rolling_friction: 0.003}
  - {id: e, shape: {type: box, size: [0.3, 0.2, 0.3]}, mass: 2, position: [-1, 0.1, 0], rolling_friction: 0.005}
  - {id: f, shape: {type: sphere, radius: 0.05}, mass: 0.2, position: [-1.02, 0.25, 0.01], rolling_friction: 0.001}
""",
    "a capsule": """
  - {id: a, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0, 0.1, 0], velocity: [2, 0, 0.3],
      angular_velocity: [3, 0, -20], rolling_friction: 0.004}
  - {id: b, shape: {type: sphere, radius: 0.08}, mass: 0.5, position: [0.6, 0.08, 0.05],
      rolling_friction: 0.002, friction: 0.3}
  - {id: c, shape: {type: capsule, radius: 0.05, length: 0.2}, mass: 0.7, position: [1.0, 0.05, 0],
      orientation: {axis: [1, 0, 0], angle: 90}, velocity: [-1, 0, 0], angular_velocity: [0, 0, 20],
      rolling_friction: 0.01}
""",
}


@pytest.mark.parametrize("bodies", list(PARITY_BODIES.values()), ids=list(PARITY_BODIES))
def test_numba_and_numpy_agree_with_rolling_resistance(bodies: str) -> None:
    pytest.importorskip("numba")
    text = f"""
duration: 1.0
dt: 0.002
record: {{every: 5}}
forces: [{{type: gravity}}]
sleep: {{after: 0.2}}
{_floor()}
bodies:{bodies}"""
    scene = animsim.loads(text, name="t")
    a = animsim.simulate(scene, backend="numba")
    b = animsim.simulate(scene, backend="numpy")
    assert a.status == b.status == "ok"
    np.testing.assert_allclose(a.positions, b.positions, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.body_orientations, b.body_orientations, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.body_angular_velocities, b.body_angular_velocities, rtol=1e-12, atol=1e-12)
    # the rolling resistance took part: without it the bodies end elsewhere
    free = animsim.loads(text.replace("rolling_friction", "restitution"), name="t")
    assert np.abs(animsim.simulate(free, backend="numba").positions[-1] - a.positions[-1]).max() > 1e-3
