"""A pile of grains comes to rest, and static friction holds grains on a slope.

The pile: grains dropped into a box of colliders (benchmarks/pile_rest.py, the 10,000-grain
measurement's own code on a smaller pile) end with every speed below 1e-6 m/s and every
overlap below 1 % of the radius, the same on both backends, and once at rest a step's
warm-started resting solve ends after a pass or two instead of running all its passes. The
slope: Coulomb's law says grains on a plane tilted by less than atan(friction) stay; steeper,
they slide.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from animsim.colliders import BOX, Colliders, Shape, axis_angle_quaternion, quaternion_matrix
from animsim.particle_contacts import ITERATIONS, ParticleContacts
from benchmarks.pile_rest import settle


def _backends() -> list[str]:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover
        return ["numpy"]
    return ["numpy", "numba"]


@pytest.fixture(scope="module")
def piles() -> dict[str, tuple[dict[str, float], np.ndarray, np.ndarray]]:
    # 1,000 grains of 1 cm, about 8 layers deep once landed; at rest well before 2.5 s
    return {b: settle(1000, 0.01, 2.5, b, seed=3) for b in _backends()}


@pytest.mark.parametrize("backend", _backends())
def test_a_pile_comes_to_rest_without_overlaps(piles, backend: str) -> None:
    measures, x, _ = piles[backend]
    assert measures["layers"] > 6, measures  # a pile, not a layer
    assert measures["max_speed"] < 1e-6, measures
    assert measures["max_overlap_over_r"] < 0.01, measures
    assert measures["max_drift_last_0.2s"] < 1e-6, measures


@pytest.mark.parametrize("backend", _backends())
def test_a_pile_at_rest_ends_its_resting_passes_early(piles, backend: str) -> None:
    """Over the last 0.2 s the impulses kept from the step before hold the pile: the first pass
    changes no impulse by more than the tolerance, or the second does not."""
    measures, _, _ = piles[backend]
    assert measures["max_passes_last_0.2s"] <= 2 < ITERATIONS, measures


@pytest.mark.skipif(len(_backends()) < 2, reason="needs numba")
def test_both_backends_settle_the_same_pile(piles) -> None:
    """1,250 steps of a chaotic flow: any last-bit difference between the backends would grow."""
    (_, x_np, v_np), (_, x_nb, v_nb) = piles["numpy"], piles["numba"]
    np.testing.assert_allclose(x_nb, x_np, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(v_nb, v_np, rtol=1e-12, atol=1e-15)
    # and end their resting passes at the same passes
    assert piles["numba"][0]["mean_passes_last_0.2s"] == piles["numpy"][0]["mean_passes_last_0.2s"]


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("degrees", [20.0, 30.0])
def test_grains_on_a_slope_stay_below_the_friction_angle(backend: str, degrees: float) -> None:
    """Three touching grains on a plane box tilted by 20 degrees (tan 20 = 0.36 < friction 0.5)
    stay where they are put; at 30 degrees (tan 30 = 0.58) they slide."""
    r, mu, dt = 0.01, 0.5, 0.002
    rot = quaternion_matrix(axis_angle_quaternion(np.array([0.0, 0.0, 1.0]), degrees))
    normal, down_slope = rot @ [0.0, 1.0, 0.0], rot @ [-1.0, 0.0, 0.0]
    slab = Shape(
        BOX, np.zeros(3), half=np.array([1.0, 0.05, 1.0]), rotation=rot, restitution=0.0, friction=mu
    )
    # on the slab's top face, touching each other along the slope
    x = np.array([(0.05 + r) * normal + k * 2 * r * down_slope for k in range(3)])
    v = np.zeros((3, 3))
    radius = np.full(3, r)
    walls = Colliders([slab], np.ones(3), radius=radius, backend=backend)
    contacts = ParticleContacts(
        radius, 0.1, mu, np.ones(3), np.ones(3, dtype=bool), np.zeros(0, np.int64), backend
    )
    contacts.colliders = walls
    start = x.copy()
    for step in range(500):
        x_old, v_old = x.copy(), v.copy()
        v += np.array([0.0, -9.81, 0.0]) * dt
        x += v * dt
        st = SimpleNamespace(particle_position=x, particle_velocity=v, particle_alive=None)
        walls.apply(st, x_old, v_old, step * dt, (step + 1) * dt)
        contacts.apply(st, x_old, v_old, step * dt, (step + 1) * dt)
    moved = np.linalg.norm(x - start, axis=1).max()
    if degrees < np.degrees(np.arctan(mu)):
        assert moved < 1e-9 and np.abs(v).max() < 1e-6, (moved, np.abs(v).max())
    else:
        # sliding: g (sin - mu cos) t^2 / 2 = 0.36 m in 1 s, less what the first steps take
        assert moved > 0.1, moved
