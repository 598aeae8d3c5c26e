"""The turbulent wind: a seeded, smooth, divergence-free random field f(x, t) (issue 3).

Because it is a fixed field (not fresh noise per step), integrators converge
on turbulent trajectories at their own order as dt halves.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from animsim.forces.turbulence import Turbulence
from animsim.scene import models as m
from tests.conftest import simulate_text


def field(sigma=0.7, scale=0.5, time=2.0, seed=3, stream=0, mass=None) -> Turbulence:
    wind = m.Wind(
        type="wind",
        velocity=[0.0, 0.0, 0.0],
        k=0.0,
        turbulence=sigma,
        turbulence_scale=scale,
        turbulence_time=time,
    )
    return Turbulence.from_scene(wind, seed, np.ones(1) if mass is None else mass, stream=stream)


def test_standard_deviation_is_turbulence_per_component():
    f = field(sigma=0.7, scale=0.5)
    rng = np.random.default_rng(1)
    x = rng.uniform(-200, 200, (40000, 3))  # far more than the 0.5 m correlation length
    samples = np.concatenate([f.field(x, t) for t in (0.0, 50.0, 100.0)])
    assert np.all(np.abs(samples.mean(axis=0)) < 0.05)
    total = samples.var(axis=0).sum()
    assert total == pytest.approx(3 * 0.7**2, rel=0.05)
    assert np.all(np.abs(samples.std(axis=0) - 0.7) < 0.7 * 0.35)  # per component, one realization


def test_divergence_free():
    f = field(scale=0.3)
    x = np.random.default_rng(2).uniform(-1, 1, (200, 3))
    h = 1e-5
    div = np.zeros(len(x))
    grad = 0.0
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        d = (f.field(x + e, 0.4) - f.field(x - e, 0.4)) / (2 * h)
        div += d[:, j]
        grad = max(grad, float(np.abs(d).max()))
    assert np.abs(div).max() < 1e-6 * grad


def test_length_and_time_scales():
    """Correlation exp(-r^2 / 2L^2) in space, exp(-tau^2 / 2T^2) in time."""
    L, T = 0.5, 2.0
    f = field(scale=L, time=T)
    rng = np.random.default_rng(3)
    x = rng.uniform(-100, 100, (20000, 3))
    f0 = f.field(x, 0.0)

    def corr(a: np.ndarray, b: np.ndarray) -> float:
        return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))

    near = corr(f0, f.field(x + np.array([0.1 * L, 0, 0]), 0.0))
    far = corr(f0, f.field(x + np.array([3 * L, 0, 0]), 0.0))
    soon = corr(f0, f.field(x, 0.1 * T))
    late = corr(f0, f.field(x, 3 * T))
    assert near > 0.95 and abs(far) < 0.25
    assert soon > 0.95 and abs(late) < 0.25


def test_seeded_and_deterministic():
    x = np.random.default_rng(4).uniform(-1, 1, (10, 3))
    a = field(seed=3).field(x, 0.5)
    np.testing.assert_array_equal(a, field(seed=3).field(x, 0.5))
    assert not np.allclose(a, field(seed=4).field(x, 0.5))
    assert not np.allclose(a, field(seed=3, stream=1).field(x, 0.5))


def test_only_particles_with_mass_are_pushed():
    mass = np.array([1.0, 0.0, 2.0])
    f = field(mass=mass)
    x = np.random.default_rng(5).uniform(-1, 1, (3, 3))
    out = np.zeros((3, 3))
    f.accumulate(x, np.zeros((3, 3)), 0.2, out)
    assert np.all(out[1] == 0) and np.all(out[[0, 2]] != 0)
    np.testing.assert_array_equal(out[[0, 2]], f.field(x[[0, 2]], 0.2))


def test_two_winds_get_different_fields():
    text = """
duration: 0.5
dt: 0.01
forces:
  - {type: wind, velocity: [0, 0, 0], k: 0, turbulence: 1}
  - {type: wind, velocity: [0, 0, 0], k: 0, turbulence: 1}
particles:
  - {id: p, mass: 1, position: [0, 0, 0]}
"""
    compiled, _, _ = simulate_text(text)
    turb = [t for t in compiled.dynamics.terms if isinstance(t, Turbulence)]
    assert len(turb) == 2
    assert not np.allclose(turb[0].k, turb[1].k)


TURBULENT = """
duration: 2.0
dt: 0.1
seed: 11
integrator: {integrator}
record: {{every: 1000000}}
forces:
  - {{type: wind, velocity: [1, 0, 0], k: 0.5, turbulence: 2.0, turbulence_scale: 0.7, turbulence_time: 0.5}}
particles:
  - {{id: a, mass: 1, position: [0, 0, 0]}}
  - {{id: b, mass: 0.5, position: [0.3, 1, -0.2], velocity: [0, 1, 0]}}
"""


def final(integrator: str, dt: float) -> np.ndarray:
    _, result, _ = simulate_text(TURBULENT.format(integrator=integrator), dt=dt)
    return np.concatenate([result.final_state.particle_position, result.final_state.particle_velocity])


@functools.cache
def reference() -> np.ndarray:
    return final("rk4", 0.0005)


# Step ladders inside each method's asymptotic range (explicit Euler needs small steps).
LADDERS = {"euler": (0.004, 0.002, 0.001), "midpoint": (0.02, 0.01, 0.005), "rk4": (0.04, 0.02, 0.01)}
ORDERS = {"euler": 1, "midpoint": 2, "rk4": 4}


@pytest.mark.parametrize("integrator", list(ORDERS))
def test_turbulent_trajectories_converge_at_the_integrators_order(integrator):
    errors = np.array([np.abs(final(integrator, dt) - reference()).max() for dt in LADDERS[integrator]])
    observed = np.log2(errors[:-1] / errors[1:])
    assert np.all(np.abs(observed - ORDERS[integrator]) < 0.35), (errors, observed)
