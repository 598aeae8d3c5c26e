"""A particle at 1,000 m/s skimming a 1 cm box collider at a small angle is reflected, on every
method and both backends: the contact search does not give up on a grazing path.

Sphere tracing closes only sin(angle) of the gap per march step along a path that skims a
surface; at 2 degrees its 48 steps ran out and the particle went through the box. The path's
distance to a convex shape is convex along it, so where the march gives up a golden-section
search finds the closest approach and bisection the first touch (animsim.colliders)."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from animsim import api

BACKENDS = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])
THICK = 0.01
SHAPES = {
    "box": f"{{type: box, center: [0, 0, 0], size: [4, {THICK}, 4], restitution: 1, friction: 0}}",
    # a long thin capsule lying along x: its top is THICK / 2 above its axis, like the box's face
    "capsule": f"{{type: capsule, a: [-2, 0, 0], b: [2, 0, 0], radius: {THICK / 2}, restitution: 1, friction: 0}}",
}


def shot(shape: str, degrees: float, backend: str, method: str = "symplectic_euler"):
    """Aimed down at ``degrees`` so that it would cross the top surface 1 m downrange."""
    a = math.radians(degrees)
    y0 = THICK / 2 + math.tan(a)
    text = f"""duration: 0.03
dt: 0.01
integrator: {method}
record: {{every: 1}}
colliders: [{SHAPES[shape]}]
particles: [{{id: p, mass: 1, position: [-1, {y0}, 0], velocity: [{1000 * math.cos(a)}, {-1000 * math.sin(a)}, 0]}}]
"""
    return api.simulate(api.loads(text), backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("degrees", [10.0, 2.0, 0.5])
def test_a_grazing_shot_is_reflected(shape, degrees, backend):
    traj = shot(shape, degrees, backend)
    y = traj.positions[:, 0, 1]
    assert y.min() >= THICK / 2 - 1e-9, y  # never below the top surface
    vy = traj.velocities[-1, 0, 1]
    assert vy == pytest.approx(1000 * math.sin(math.radians(degrees)), rel=1e-9)  # reflected, e = 1


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", ["euler", "midpoint", "rk4", "verlet", "implicit_euler"])
def test_every_method_reflects_the_2_degree_shot(method, backend):
    traj = shot("box", 2.0, backend, method)
    assert traj.positions[:, 0, 1].min() >= THICK / 2 - 1e-9
    assert traj.velocities[-1, 0, 1] > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_shot_that_passes_above_is_left_alone(backend):
    """1 mm above the face all along (the march gives up there too): the search must not
    invent a touch."""
    level = THICK / 2 + 1e-3
    text = f"""duration: 0.03
dt: 0.01
colliders: [{SHAPES["box"]}]
particles: [{{id: p, mass: 1, position: [-1.9, {level}, 0], velocity: [1000, 0, 0]}}]
"""
    traj = api.simulate(api.loads(text), backend=backend)
    np.testing.assert_array_equal(traj.positions[:, 0, 1], level)
    np.testing.assert_array_equal(traj.velocities[:, 0, 1], 0.0)


def test_check_states_the_speed_at_which_a_body_can_pass_through_a_collider(tmp_path):
    """Bodies' contacts are found at step ends: where that leaves a limit, check states it,
    and the limit it states is true (a ball just under it is stopped, one well over it is not)."""
    from tests.conftest import run_cli

    def scene(speed: float) -> str:
        return f"""duration: 0.05
dt: 0.01
colliders: [{{type: box, center: [0, 0, 0], size: [4, 0.01, 4], restitution: 1, friction: 0}}]
bodies:
  - {{id: ball, shape: {{type: sphere, radius: 0.05}}, mass: 1, position: [0, 0.2, 0], velocity: [0, {-speed}, 0]}}
"""

    path = tmp_path / "fast.yaml"
    path.write_text(scene(200.0))
    r = run_cli("check", path, "--backend", "numpy")
    assert r.returncode == 0, r.stderr
    # r + t/2 = 0.05 + 0.005 m per step of 0.01 s
    assert "a body faster than (r + t/2) / dt = 5.5 m/s can pass through a collider" in r.stdout
    assert "particles against colliders:" in r.stdout and "found at any speed and angle" in r.stdout
    for speed, stopped in ((5.0, True), (200.0, False)):
        traj = api.simulate(api.loads(scene(speed)), backend="numpy")
        assert (traj.body_positions[:, 0, 1].min() > 0) == stopped, speed
