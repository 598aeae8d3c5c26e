"""Observed orders of convergence measured by ``compare`` match the theory.

Global error ~ C dt^p (Hairer, Norsett and Wanner, "Solving ODEs I", II.1).
The step sizes are chosen in the asymptotic regime (omega dt <= 0.06 on the
oscillators) and above round-off (RK4's smallest error here is ~1e-11 m), on
a one-second run, so every fit uses all three points.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from animsim.analysis.compare import compare, parse_integrators
from animsim.integrators import REGISTRY
from animsim.scene.loader import load_scene
from tests.numerics.theory import ORDER_TOLERANCE, ORDERS

SCENES = Path(__file__).resolve().parents[2] / "scenes"
STEP_SIZES = (0.01, 0.005, 0.0025)
DURATION = 1.0
TOLERANCE = ORDER_TOLERANCE
EXPECTED = ORDERS
METHODS = [name for name in EXPECTED if name in REGISTRY]
SCENE_NAMES = ("oscillator", "damped_oscillator", "drag_projectile")


@pytest.fixture(scope="module", params=SCENE_NAMES)
def comparison(request):
    loaded = load_scene(SCENES / f"{request.param}.yaml")
    scene = loaded.scene.model_copy(update={"duration": DURATION})
    names = list(dict.fromkeys(parse_integrators(None) + METHODS))
    return compare(scene, loaded.name, integrators=names, dts=STEP_SIZES, repeat=1)


def test_reference_is_the_closed_form(comparison):
    assert comparison.reference.kind == "analytic"
    assert comparison.reference.accuracy == 0.0


@pytest.mark.parametrize("method", METHODS)
def test_observed_order(comparison, method):
    fit = next(o for o in comparison.orders if o.integrator == method)
    assert fit.expected == EXPECTED[method]
    assert fit.points == len(STEP_SIZES), f"{method}: only {fit.points} points above round-off"
    assert fit.order == pytest.approx(EXPECTED[method], abs=TOLERANCE), (
        f"{comparison.scene_name}/{method}: observed order {fit.order:.3f}, expected {EXPECTED[method]}"
    )


def test_errors_shrink_as_dt_halves(comparison):
    for method in METHODS:
        errs = [r.error for r in comparison.rows if r.integrator == method]
        assert errs == sorted(errs, reverse=True), method
