"""Rigid bodies meet keyframed colliders where the keys put them, at their velocity: a paddle
moving at u sends a resting ball with restitution 1 off at 2u (an elastic bounce off an immovable
wall in motion), and a box sliding along the floor pushes a crate ahead of it without overlap."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from animsim import api
from animsim.bodies import quaternion as quat
from animsim.colliders import BOX, Shape

BACKENDS = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("speed", [2.0, 5.0])
def test_a_moving_paddle_sends_a_ball_off_at_twice_its_speed(backend, speed):
    text = f"""duration: 1.0
dt: 0.01
colliders:
  - {{type: box, center: [-1, 0, 0], size: [0.2, 1, 1], restitution: 1, friction: 0,
     motion: {{keyframes: [[0, [-1, 0, 0]], [1, [{speed - 1}, 0, 0]]]}}}}
bodies:
  - {{id: ball, shape: {{type: sphere, radius: 0.1}}, mass: 1, position: [0, 0, 0], restitution: 1, friction: 0}}
"""
    traj = api.simulate(api.loads(text), backend=backend)
    x = traj.body_positions[:, 0, 0]
    after = np.diff(x[-5:]) / np.diff(traj.times[-5:])
    np.testing.assert_allclose(after, 2 * speed, rtol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_box_sliding_along_the_floor_pushes_a_crate(backend):
    """The pusher clears the floor by 2 cm: a body's corner on the floor exactly at the plane of
    the pusher's bottom face is met by that face (see the rigid bodies guide's limits)."""
    text = """duration: 1.5
dt: 0.005
forces: [{type: gravity}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.3}]
colliders:
  - {type: box, center: [-1, 0.32, 0], size: [0.4, 0.6, 1.0], restitution: 0, friction: 0,
     motion: {keyframes: [[0, [-1, 0.32, 0]], [1.5, [1, 0.32, 0]]]}}
bodies:
  - {id: crate, shape: {type: box, size: [0.3, 0.3, 0.3]}, mass: 1, position: [0, 0.15, 0],
     restitution: 0, friction: 0.3}
"""
    traj = api.simulate(api.loads(text), backend=backend)
    centre = -1 + 2 * traj.times / 1.5  # the collider's centre along x
    pusher = Shape(BOX, np.array([0.0, 0.32, 0.0]), half=np.array([0.2, 0.3, 0.5]))
    x, q = traj.body_positions[:, 0], traj.body_orientations[:, 0]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * 0.15
    for k in range(len(traj.times)):
        world = x[k] + quat.rotate(np.repeat(q[k : k + 1], 8, axis=0), corners)
        depth, _ = pusher.signed_distance(world, np.array([centre[k], 0.0, 0.0]))
        # no corner inside the pusher by more than the step's approach (1.33 m/s x 5 ms)
        assert depth.min() >= -7e-3, (traj.times[k], depth.min())
    # pushed: it ends ahead of the pusher's front face, moving with it
    assert x[-1, 0] > centre[-1] + 0.2
    assert np.diff(x[-3:, 0]) / np.diff(traj.times[-3:]) == pytest.approx(2 / 1.5, rel=0.05)
