"""Force families against closed forms: wind, quadratic drag, penalty planes,
moving anchors, attractor energy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import simulate_text


def test_wind_relaxes_velocity_to_the_wind():
    # m v' = k (w - v): v(t) = w + (v0 - w) e^(-k t / m)
    m, k, w = 2.0, 0.8, np.array([3.0, 0.0, -1.0])
    text = f"""
duration: 2.0
dt: 0.001
integrator: rk4
particles: [{{id: p, mass: {m}, position: [0, 0, 0], velocity: [0, 1, 0]}}]
forces: [{{type: wind, velocity: {w.tolist()}, k: {k}}}]
"""
    _, _, sink = simulate_text(text)
    for f in sink.frames[::100]:
        exact = w + (np.array([0.0, 1.0, 0.0]) - w) * math.exp(-k * f.time / m)
        np.testing.assert_allclose(f.velocity[0], exact, atol=1e-10)


def test_quadratic_drag_1d_closed_form():
    # m v' = -c v|v| with v > 0: v(t) = v0 / (1 + c v0 t / m)
    m, rho, cd, area, v0 = 1.0, 1.2, 0.5, 0.1, 20.0
    c = 0.5 * rho * cd * area
    text = f"""
duration: 3.0
dt: 0.001
integrator: rk4
particles: [{{id: p, mass: {m}, position: [0, 0, 0], velocity: [{v0}, 0, 0]}}]
forces: [{{type: quadratic_drag, rho: {rho}, cd: {cd}, area: {area}}}]
"""
    _, _, sink = simulate_text(text)
    for f in sink.frames[::300]:
        v = v0 / (1 + c * v0 * f.time / m)
        x = m / c * math.log(1 + c * v0 * f.time / m)
        assert f.velocity[0, 0] == pytest.approx(v, rel=1e-9)
        assert f.position[0, 0] == pytest.approx(x, rel=1e-9)


def test_penalty_floor_holds_a_particle_at_mg_over_k():
    m, k, c = 0.5, 1e4, 20.0
    text = f"""
duration: 3.0
dt: 0.0005
integrator: verlet
particles: [{{id: p, mass: {m}, position: [0, 0.05, 0]}}]
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], response: penalty, stiffness: {k}, damping: {c}}}]
"""
    compiled, result, sink = simulate_text(text)
    assert "penalty" in " ".join(compiled.stages)
    assert sink.frames[-1].position[0, 1] == pytest.approx(-m * 9.81 / k, rel=1e-3)


def test_moving_anchor_moves_at_its_velocity_and_drags_its_bob():
    # The anchor moves down the spring's axis at 1 m/s; the stretch u obeys
    # u'' = -w^2 u with u(0) = 0, u'(0) = 1 (relative velocity), so
    # y_bob = -1 - t + sin(w t)/w.
    omega = 10.0
    text = f"""
duration: 1.0
dt: 0.001
integrator: rk4
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0], velocity: [0, -1, 0]}}
  - {{id: bob, mass: 1, position: [0, -1, 0]}}
springs: [{{between: [anchor, bob], ks: {omega**2}}}]
"""
    compiled, _, sink = simulate_text(text)
    assert not compiled.conservative  # a driven anchor puts energy in
    for f in sink.frames:
        np.testing.assert_allclose(f.position[0], [0, -f.time, 0], atol=1e-12)
        np.testing.assert_allclose(f.velocity[0], [0, -1, 0])
        y = -1 - f.time + math.sin(omega * f.time) / omega
        assert f.position[1, 1] == pytest.approx(y, abs=1e-9)


def test_attractor_conserves_energy_on_an_ellipse():
    text = """
duration: 10.0
dt: 0.001
integrator: rk4
particles: [{id: p, mass: 2, position: [1, 0, 0], velocity: [0, 1.2, 0]}]
forces: [{type: attractor, gm: 1.0}]
"""
    compiled, result, sink = simulate_text(text)
    e = [compiled.dynamics.energy(f.position, f.velocity) for f in sink.frames]
    assert e[0] == pytest.approx(2 * (0.5 * 1.44 - 1.0))
    assert max(abs(x - e[0]) for x in e) < 1e-9
    assert compiled.conservative
