"""implicit_euler: Baraff & Witkin's linearised backward Euler.

Closed forms: on x'' = -omega^2 x backward Euler multiplies the energy by
1/(1 + (omega dt)^2) each step (A-stable, so no dt blows up) and converges with
order 1. The Jacobians the force terms expose are checked against central
finite differences.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.engine import STATUS_OK, STATUS_UNSTABLE
from animsim.forces.drag import Drag, QuadraticDrag
from animsim.forces.penalty import PenaltyPlane
from animsim.forces.springs import Springs
from animsim.forces.wind import Wind
from animsim.integrators import REGISTRY
from animsim.integrators.implicit import ImplicitEuler
from tests.conftest import simulate_text

OSCILLATOR = """
duration: {duration}
dt: {dt}
integrator: implicit_euler
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0]}}
  - {{id: bob, mass: {m}, position: [1.2, 0, 0]}}
springs:
  - {{between: [anchor, bob], ks: {k}, rest: 1.0}}
"""


def test_registered():
    assert REGISTRY["implicit_euler"] is ImplicitEuler


def test_stable_at_omega_dt_20_and_energy_decays_as_backward_euler():
    k, m, dt = 400.0, 1.0, 1.0  # omega = 20 rad/s, omega dt = 20
    text = OSCILLATOR.format(duration=30.0, dt=dt, m=m, k=k)
    _c, r, sink = simulate_text(text)
    assert r.status == STATUS_OK
    x = sink.positions()[:, 1, 0] - 1.0
    v = sink.velocities()[:, 1, 0]
    energy = 0.5 * k * x**2 + 0.5 * m * v**2
    ratio = energy[1:6] / energy[:5]
    assert ratio == pytest.approx(1 / (1 + (math.sqrt(k / m) * dt) ** 2), rel=1e-9)
    # the same scene with symplectic Euler (limit omega dt = 2) is stopped by the watchdog
    assert simulate_text(text, integrator="symplectic_euler")[1].status == STATUS_UNSTABLE


def test_observed_order_is_one():
    k, m, duration = 4.0, 1.0, 1.0  # omega = 2
    omega = math.sqrt(k / m)
    dts = [0.02, 0.01, 0.005, 0.0025]
    errors = []
    for dt in dts:
        _, r, _ = simulate_text(OSCILLATOR.format(duration=duration, dt=dt, m=m, k=k))
        exact = 1.0 + 0.2 * math.cos(omega * duration)
        errors.append(abs(r.final_state.particle_position[1, 0] - exact))
    order = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert order == pytest.approx(1.0, abs=0.1)


def chain_text(duration: float) -> str:
    return f"""
duration: {duration}
dt: 0.016666666666666666
integrator: implicit_euler
structures:
  - type: strand
    id: chain
    start: [0, 0, 0]
    end: [0, -0.99, 0]
    count: 100
    mass: 0.01
    stretch: {{ks: 1.0e4}}
    pin: ["chain[0]"]
forces:
  - {{type: gravity}}
"""


def test_settles_the_hanging_chain_where_symplectic_euler_blows_up_at_step_2():
    c, r, _ = simulate_text(chain_text(4.0))
    assert r.status == STATUS_OK
    x, v = r.final_state.particle_position, r.final_state.particle_velocity
    stretch = np.linalg.norm(np.diff(x, axis=0), axis=1) - c.system.spring_rest_length
    # static sag: link i carries the weight of the 99 - i particles below it
    expected = (99 - np.arange(99)) * 0.01 * 9.81 / 1e4
    assert np.abs(stretch - expected).max() < 1e-3 * expected[0]
    assert np.abs(v).max() < 1e-3
    assert c.integrator.direct_solves == 0  # CG converged every step
    _, bad, _ = simulate_text(chain_text(0.1), integrator="symplectic_euler")
    assert bad.status == STATUS_UNSTABLE and bad.failure.step == 2


def test_moving_anchor_keeps_its_velocity_and_pulls():
    text = """
duration: 1.0
dt: 0.05
integrator: implicit_euler
particles:
  - {id: hand, pinned: true, position: [0, 0, 0], velocity: [1, 0, 0]}
  - {id: weight, mass: 0.1, position: [-0.1, 0, 0]}
springs:
  - {between: [hand, weight], ks: 1.0e5, rest: 0.1}
"""
    _, r, _ = simulate_text(text)
    x = r.final_state.particle_position
    assert x[0, 0] == pytest.approx(1.0)
    assert x[1, 0] == pytest.approx(0.9, abs=1e-3)  # dragged along at the rest length


def numeric_jacobian(term, x, v, wrt: str, h: float = 1e-6) -> np.ndarray:
    n = x.size
    out = np.zeros((n, n))
    for j in range(n):
        xp, xm, vp, vm = x.copy(), x.copy(), v.copy(), v.copy()
        if wrt == "x":
            xp.flat[j] += h
            xm.flat[j] -= h
        else:
            vp.flat[j] += h
            vm.flat[j] -= h
        fp, fm = np.zeros_like(x), np.zeros_like(x)
        term.accumulate(xp, vp, 0.0, fp)
        term.accumulate(xm, vm, 0.0, fm)
        out[:, j] = (fp - fm).ravel() / (2 * h)
    return out


def dense(m) -> np.ndarray | None:
    return None if m is None else m.toarray()


def test_spring_jacobians_match_finite_differences(rng):
    n = 5
    x, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    index = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [0, 4]])
    d = np.linalg.norm(x[index[:, 0]] - x[index[:, 1]], axis=1)
    rest = 0.5 * d  # all stretched: the geometric term is not clamped
    springs = Springs(index, rest, rng.uniform(1, 10, 5), np.zeros(5), n)
    kx, kv = springs.jacobians(x, v)
    assert kv is None
    np.testing.assert_allclose(dense(kx), numeric_jacobian(springs, x, v, "x"), atol=1e-6)
    damped = Springs(index, rest, np.zeros(5), rng.uniform(1, 10, 5), n)
    _, kv = damped.jacobians(x, v)
    np.testing.assert_allclose(dense(kv), numeric_jacobian(damped, x, v, "v"), atol=1e-6)


def test_compressed_springs_are_clamped_to_stay_negative_semidefinite(rng):
    n = 4
    x = rng.normal(size=(n, 3))
    index = np.array([[0, 1], [1, 2], [2, 3]])
    rest = 3.0 * np.linalg.norm(x[index[:, 0]] - x[index[:, 1]], axis=1)  # all compressed
    kx, _ = Springs(index, rest, np.ones(3), np.zeros(3), n).jacobians(x, np.zeros_like(x))
    k = dense(kx)
    np.testing.assert_allclose(k, k.T)
    assert np.linalg.eigvalsh(k).max() <= 1e-12


def test_coincident_zero_rest_spring_is_linear():
    x = np.zeros((2, 3))
    kx, _ = Springs(np.array([[0, 1]]), np.zeros(1), np.array([7.0]), np.zeros(1), 2).jacobians(x, x)
    assert np.isfinite(dense(kx)).all()
    np.testing.assert_allclose(dense(kx)[:3, :3], -7.0 * np.eye(3))


@pytest.mark.parametrize(
    "term",
    [
        Drag(0.3),
        QuadraticDrag(1.2, 0.47, 0.1),
        Wind(np.array([1.0, 2.0, 0.0]), 0.5),
        PenaltyPlane(np.zeros(3), np.array([0.0, 1.0, 0.2]), 1e3, 5.0),
    ],
)
def test_other_jacobians_match_finite_differences(term, rng):
    x, v = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    kx, kv = term.jacobians(x, v)
    for got, wrt in ((kx, "x"), (kv, "v")):
        want = numeric_jacobian(term, x, v, wrt)
        np.testing.assert_allclose(np.zeros_like(want) if got is None else dense(got), want, atol=1e-5)
