"""Every integrator against closed-form solutions, and its order of convergence.

Closed forms: uniform gravity with linear drag (exponential approach to the
terminal velocity); a particle on a spring to a pinned anchor, moving along
the spring (a damped harmonic oscillator, under- damped); two free particles
on one spring (centre of mass at rest, relative coordinate oscillates at
sqrt(k/mu)); a circular orbit around a point attractor. The observed order is
the slope of log(error) against log(dt) over a range of halvings.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import simulate_text
from tests.numerics.theory import ORDER_TOLERANCE, ORDERS

ORDER_TOL = ORDER_TOLERANCE


def observed_order(dts, errors):
    slope, _ = np.polyfit(np.log(dts), np.log(errors), 1)
    return slope


# --- linear drag projectile -------------------------------------------------------

M, K_DRAG, G = 2.0, 0.5, 9.81
V0 = np.array([10.0, 10.0, 0.0])


def drag_exact(t):
    tau = M / K_DRAG
    v_inf = np.array([0.0, -G * tau, 0.0])
    decay = math.exp(-t / tau)
    v = v_inf + (V0 - v_inf) * decay
    x = v_inf * t + (V0 - v_inf) * tau * (1 - decay)
    return x, v


DRAG_SCENE = f"""
duration: 1.0
dt: {{dt}}
integrator: {{method}}
particles: [{{{{id: p, mass: {M}, position: [0, 0, 0], velocity: [10, 10, 0]}}}}]
forces: [{{{{type: gravity, g: [0, -{G}, 0]}}}}, {{{{type: drag, k: {K_DRAG}}}}}]
"""


def drag_error(method, dt):
    _, result, sink = simulate_text(DRAG_SCENE.format(dt=dt, method=method))
    assert result.status == "ok"
    err = 0.0
    for f in sink.frames:
        x, _ = drag_exact(f.time)
        err = max(err, float(np.abs(f.position[0] - x).max()))
    return err


@pytest.mark.parametrize("method", list(ORDERS))
def test_drag_projectile_order(method):
    dts = [0.02, 0.01, 0.005, 0.0025]
    errs = [drag_error(method, dt) for dt in dts]
    assert errs[-1] < 2e-2
    assert abs(observed_order(dts, errs) - ORDERS[method]) < ORDER_TOL, errs


def test_free_fall_exact_for_constant_force():
    # Under a constant force euler_average and verlet are exact (notes: "exact
    # under constant force only"); rk4 too.
    scene = """
duration: 1.0
dt: 0.1
integrator: {method}
particles: [{{id: p, mass: 1, position: [0, 0, 0], velocity: [10, 10, 0]}}]
forces: [{{type: gravity}}]
"""
    for method in ("euler_average", "verlet", "rk4", "midpoint", "heun"):
        _, _, sink = simulate_text(scene.format(method=method))
        last = sink.frames[-1]
        np.testing.assert_allclose(last.position[0], [10.0, 10.0 - 9.81 / 2, 0.0], atol=1e-12)


# --- oscillator: a particle on a spring to a pinned anchor, along the spring ------

OSC_M, OSC_K, OSC_REST, OSC_X0 = 1.0, 16.0, 1.0, 1.5  # omega = 4


def oscillator_exact(t, kd):
    omega0 = math.sqrt(OSC_K / OSC_M)
    zeta = kd / (2 * math.sqrt(OSC_K * OSC_M))
    wd = omega0 * math.sqrt(1 - zeta**2)
    a = OSC_X0 - OSC_REST
    # x(0) = a, v(0) = 0
    u = math.exp(-zeta * omega0 * t) * (a * math.cos(wd * t) + a * zeta * omega0 / wd * math.sin(wd * t))
    return OSC_REST + u


OSC_SCENE = f"""
duration: 2.0
dt: {{dt}}
integrator: {{method}}
particles:
  - {{{{id: anchor, pinned: true, position: [0, 0, 0]}}}}
  - {{{{id: bob, mass: {OSC_M}, position: [{OSC_X0}, 0, 0]}}}}
springs:
  - {{{{between: [bob, anchor], ks: {OSC_K}, kd: {{kd}}, rest: {OSC_REST}}}}}
"""


def oscillator_error(method, dt, kd):
    _, result, sink = simulate_text(OSC_SCENE.format(dt=dt, method=method, kd=kd))
    assert result.status == "ok"
    return max(abs(f.position[1, 0] - oscillator_exact(f.time, kd)) for f in sink.frames)


@pytest.mark.parametrize("kd", [0.0, 1.6])
@pytest.mark.parametrize("method", list(ORDERS))
def test_oscillator_order(method, kd):
    dts = [0.01, 0.005, 0.0025, 0.00125]
    errs = [oscillator_error(method, dt, kd) for dt in dts]
    assert errs[-1] < 2e-2
    assert abs(observed_order(dts, errs) - ORDERS[method]) < ORDER_TOL, errs


def test_oscillator_stays_on_axis():
    _, _, sink = simulate_text(OSC_SCENE.format(dt=0.001, method="rk4", kd=0.5))
    y = np.array([f.position[1, 1:] for f in sink.frames])
    assert np.all(y == 0.0)
    anchor = np.array([f.position[0] for f in sink.frames])
    assert np.all(anchor == 0.0)


# --- two free particles on a spring ------------------------------------------------


def test_two_body_spring():
    m1, m2, k, rest, stretch = 1.0, 3.0, 12.0, 1.0, 0.3
    mu = m1 * m2 / (m1 + m2)
    omega = math.sqrt(k / mu)
    scene = f"""
duration: 2.0
dt: 0.0005
integrator: rk4
particles:
  - {{id: a, mass: {m1}, position: [0, 0, 0], velocity: [0, 0, 0]}}
  - {{id: b, mass: {m2}, position: [{rest + stretch}, 0, 0], velocity: [0, 0, 0]}}
springs: [{{between: [a, b], ks: {k}, rest: {rest}}}]
"""
    _, _, sink = simulate_text(scene)
    com0 = (m2 * (rest + stretch)) / (m1 + m2)
    for f in sink.frames:
        xa, xb = f.position[0, 0], f.position[1, 0]
        sep = rest + stretch * math.cos(omega * f.time)
        assert abs((xb - xa) - sep) < 1e-9
        assert abs((m1 * xa + m2 * xb) / (m1 + m2) - com0) < 1e-12


# --- circular orbit ----------------------------------------------------------------


@pytest.mark.parametrize(("method", "tol"), [("rk4", 1e-8), ("verlet", 5e-4), ("midpoint", 5e-3)])
def test_circular_orbit(method, tol):
    scene = f"""
duration: {2 * math.pi}
dt: 0.005
integrator: {method}
particles: [{{id: p, mass: 1, position: [1, 0, 0], velocity: [0, 1, 0]}}]
forces: [{{type: attractor, gm: 1.0}}]
"""
    _, result, sink = simulate_text(scene)
    assert result.status == "ok"
    for f in sink.frames:
        exact = np.array([math.cos(f.time), math.sin(f.time), 0.0])
        assert np.abs(f.position[0] - exact).max() < tol


def test_euler_orbit_spirals_out():
    scene = f"""
duration: {2 * math.pi}
dt: 0.01
integrator: euler
particles: [{{id: p, mass: 1, position: [1, 0, 0], velocity: [0, 1, 0]}}]
forces: [{{type: attractor, gm: 1.0}}]
"""
    _, _result, sink = simulate_text(scene)
    r = np.linalg.norm(sink.frames[-1].position[0])
    # Explicit Euler multiplies r^2 v^2 terms by (1 + dt^2) each step: r grows.
    assert r > 1.05


# --- energy ------------------------------------------------------------------------


def test_explicit_euler_energy_growth_is_exact():
    # x'' = -w^2 (x - R): one Euler step maps E to E (1 + (w dt)^2) exactly.
    dt, omega = 0.05, 4.0
    compiled, _, sink = simulate_text(
        OSC_SCENE.format(dt=dt, method="euler", kd=0.0).replace("duration: 2.0", "duration: 1.0")
    )
    energies = [compiled.dynamics.energy(f.position, f.velocity) for f in sink.frames]
    ratios = np.array(energies[1:]) / np.array(energies[:-1])
    np.testing.assert_allclose(ratios, 1 + (omega * dt) ** 2, rtol=1e-12)


@pytest.mark.parametrize("method", ["symplectic_euler", "verlet"])
def test_symplectic_energy_bounded(method):
    dt = 0.05  # omega dt = 0.2, well inside the stability limit 2
    text = OSC_SCENE.format(dt=dt, method=method, kd=0.0).replace("duration: 2.0", "duration: 100.0")
    compiled, _, sink = simulate_text(text)
    e = np.array([compiled.dynamics.energy(f.position, f.velocity) for f in sink.frames])
    e0 = e[0]
    # A symplectic method conserves a modified energy that differs from E by
    # O(omega dt) for symplectic Euler and O((omega dt)^2) for Verlet: the
    # true energy oscillates within that band, with no secular growth over
    # 320 periods.
    omega_dt = 4.0 * dt
    band = 0.6 * omega_dt if method == "symplectic_euler" else 0.6 * omega_dt**2
    assert np.abs(e / e0 - 1).max() < band
    first, last = e[: len(e) // 10], e[-len(e) // 10 :]
    assert abs(last.mean() - first.mean()) / e0 < 1e-3
