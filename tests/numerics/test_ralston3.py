"""Ralston's third-order method: its tableau, its order, its stability limit.

The method is one module of data (animsim/methods/ralston3.py); everything else
(the scene language, the steppers on both backends, bodies, the stability
analysis, compare) follows from its tableau. Checked here against the theory:
the order conditions of a three-stage method (Butcher; Hairer, Norsett and
Wanner I, II.2, Table 2.1), the closed-form solution of the oscillator, and the
stability interval sqrt(3) of R(z) = 1 + z + z^2/2 + z^3/6 on the imaginary axis.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim import methods
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.measures.stability import analyse, largest_stable_dt
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text

OSCILLATOR = """
duration: {duration!r}
dt: {dt!r}
integrator: ralston3
record: {{every: 1}}
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0]}}
  - {{id: bob, mass: 1.0, position: [{x0!r}, 0, 0]}}
springs:
  - {{between: [anchor, bob], ks: {ks!r}, rest: 1.0}}
"""


def test_tableau_meets_the_order_conditions_of_order_three():
    tab = methods.get("ralston3").tableau
    b, c, a = np.array(tab.b), np.array(tab.c), tab.matrix()
    assert b.sum() == pytest.approx(1.0, abs=1e-15)
    assert b @ c == pytest.approx(1 / 2, abs=1e-15)
    assert b @ c**2 == pytest.approx(1 / 3, abs=1e-15)
    assert b @ a @ c == pytest.approx(1 / 6, abs=1e-15)
    # the rows of A sum to c (the stages are consistent)
    assert np.allclose(a.sum(axis=1), c, atol=1e-15)


def test_stability_polynomial_is_the_third_order_taylor_polynomial():
    coeffs = methods.get("ralston3").tableau.stability_polynomial()
    assert coeffs == pytest.approx((1.0, 1.0, 0.5, 1.0 / 6.0), abs=1e-15)


def _bob_x(text: str, backend: str = "numpy") -> tuple[np.ndarray, np.ndarray, str]:
    """(times, the bob's x at every step, status) of a run of ``text``."""
    sink = MemorySink()
    result = run(compile_scene(load_scene_text(text).scene, "osc", backend=backend), [sink])
    return sink.times(), sink.positions()[:, 1, 0], result.status


def _final_error(dt: float, backend: str) -> float:
    omega, amplitude = 2.0, 0.1
    text = OSCILLATOR.format(duration=1.0, dt=dt, x0=1.0 + amplitude, ks=omega**2)
    t, x, status = _bob_x(text, backend)
    assert status == "ok"
    return abs(x[-1] - (1.0 + amplitude * math.cos(omega * t[-1])))


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_global_error_falls_as_dt_cubed(backend):
    errors = [_final_error(dt, backend) for dt in (0.02, 0.01, 0.005)]
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(abs(p - 3.0) < 0.15 for p in orders), (errors, orders)


def test_stability_limit_is_root_three_over_omega_and_the_code_agrees():
    omega = 2.0
    limit = float(largest_stable_dt("ralston3", omega, 0.0)[0])
    assert limit == pytest.approx(math.sqrt(3.0) / omega, rel=1e-9)
    text = OSCILLATOR.format(duration=1.0, dt=0.01, x0=1.1, ks=omega**2)
    report = analyse(compile_scene(load_scene_text(text).scene))
    assert report.limits["ralston3"] == pytest.approx(limit, rel=1e-9)
    # the code itself: bounded for 2,000 steps just below the limit, growing just above it
    for factor, grows in ((0.98, False), (1.05, True)):
        dt = factor * limit
        amplitude = 0.1
        text = OSCILLATOR.format(duration=2000 * dt, dt=dt, x0=1.0 + amplitude, ks=omega**2)
        _, x, _ = _bob_x(text)
        peak = np.nanmax(np.abs(x - 1.0))
        assert bool(peak > 10 * amplitude) is grows, (factor, peak)
