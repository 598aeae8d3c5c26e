"""Particles and rigid bodies collide both ways, on both backends: a head-on hit gives the
closed-form velocities of a one-dimensional impact with restitution e, an off-centre hit
keeps linear and angular momentum, and particles raining on a crate never end inside it."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from animsim import api
from animsim.bodies import quaternion as quat

BACKENDS = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("m1", "m2", "e"), [(1.0, 1.0, 1.0), (0.2, 3.0, 0.5), (5.0, 1.0, 0.0)])
def test_a_head_on_hit_gives_the_closed_form_velocities(backend, m1, m2, e):
    u1, u2 = 2.0, -0.5
    text = f"""duration: 0.6
dt: 0.001
particles: [{{id: p, mass: {m1}, position: [-0.5, 0, 0], velocity: [{u1}, 0, 0]}}]
bodies:
  - {{id: ball, shape: {{type: sphere, radius: 0.1}}, mass: {m2}, position: [0.2, 0, 0],
     velocity: [{u2}, 0, 0], restitution: {e}, friction: 0}}
"""
    traj = api.simulate(api.loads(text), backend=backend)
    # Newton's law of restitution with momentum kept (e.g. Goldstein, Classical Mechanics)
    v1 = (m1 * u1 + m2 * u2 - m2 * e * (u1 - u2)) / (m1 + m2)
    v2 = (m1 * u1 + m2 * u2 + m1 * e * (u1 - u2)) / (m1 + m2)
    np.testing.assert_allclose(traj.velocities[-1, 0], [v1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(traj.velocities[-1, 1], [v2, 0, 0], atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_off_centre_hit_keeps_momentum_and_angular_momentum(backend):
    text = """duration: 0.5
dt: 0.001
particles: [{id: p, mass: 0.3, position: [-0.6, 0.15, 0.05], velocity: [3, 0, 0]}]
bodies:
  - {id: crate, shape: {type: box, size: [0.4, 0.4, 0.4]}, mass: 1.0, position: [0, 0, 0],
     restitution: 0.7, friction: 0.4}
"""
    traj = api.simulate(api.loads(text), backend=backend)
    inertia = np.full(3, 1.0 / 12 * (0.4**2 + 0.4**2))
    for k in (0, -1):
        x, v = traj.positions[k], traj.velocities[k]
        p = 0.3 * v[0] + 1.0 * v[1]
        spin = quat.angular_momentum(traj.body_orientations[k], traj.body_angular_velocities[k], inertia)[0]
        l_total = 0.3 * np.cross(x[0], v[0]) + np.cross(x[1], 1.0 * v[1]) + spin
        if k == 0:
            p0, l0 = p, l_total
    np.testing.assert_allclose(p, p0, atol=1e-12)
    np.testing.assert_allclose(l_total, l0, atol=1e-12)
    assert np.abs(traj.body_angular_velocities[-1, 0]).max() > 0.1  # it was hit off centre: it spins


@pytest.mark.parametrize("backend", BACKENDS)
def test_rain_on_a_crate_stays_outside_it(backend):
    drops = ", ".join(
        f"{{id: d{i}_{j}, mass: 0.01, position: [{-0.15 + 0.1 * i}, {1.0 + 0.05 * (i + j)}, {-0.15 + 0.1 * j}]}}"
        for i in range(4)
        for j in range(4)
    )
    text = f"""duration: 1.2
dt: 0.002
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.5}}]
particles: [{drops}]
bodies:
  - {{id: crate, shape: {{type: box, size: [0.5, 0.5, 0.5]}}, mass: 2.0, position: [0, 0.25, 0],
     restitution: 0.2, friction: 0.5}}
"""
    traj = api.simulate(api.loads(text), backend=backend)
    for k in range(len(traj.times)):
        local = quat.rotate_inverse(
            np.repeat(traj.body_orientations[k], 16, axis=0),
            traj.positions[k, :16] - traj.body_positions[k, 0],
        )
        inside = np.all(np.abs(local) < 0.25 - 1e-9, axis=1)
        assert not inside.any(), traj.times[k]
    # the drops came to rest on its lid, and it still stands on the floor
    np.testing.assert_allclose(traj.positions[-1, :16, 1], 0.5, atol=1e-3)
    assert traj.body_positions[-1, 0, 1] == pytest.approx(0.25, abs=1e-3)
