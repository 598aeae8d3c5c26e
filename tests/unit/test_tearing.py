"""Tearing: a spring breaks once its strain passes the limit, for good, the same way every run."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from animsim.tearing import Tearing, strain


def _backends() -> list[str]:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover
        return ["numpy"]
    return ["numpy", "numba"]


def test_strain_is_length_over_rest_minus_one() -> None:
    x = np.array([[0.0, 0, 0], [1.5, 0, 0], [1.5, 0, 0]])
    s = strain(x, np.array([0, 1, 1]), np.array([1, 0, 2]), np.array([1.0, 3.0, 0.0]))
    np.testing.assert_allclose(s, [0.5, -0.5, 0.0])
    assert strain(x, np.array([0]), np.array([1]), np.array([0.0]))[0] == np.inf


@pytest.mark.parametrize("backend", _backends())
def test_breaks_past_the_limit_and_stays_broken(backend: str) -> None:
    index = np.array([[0, 1], [1, 2], [2, 3]])
    rest = np.array([1.0, 1.0, 1.0])
    limit = np.array([0.2, np.inf, 0.5])  # the middle one cannot tear
    tear = Tearing(index, rest, limit, backend)
    x = np.array([[0.0, 0, 0], [1.1, 0, 0], [5.0, 0, 0], [6.4, 0, 0]])
    state = SimpleNamespace(particle_position=x, spring_intact=np.ones(3, dtype=bool))
    tear.reset(state)
    assert not tear.apply(state, x, x, 0.0, 0.1)  # strains 0.1, 2.9 (no limit), 0.4
    x[3, 0] = 6.51  # strain 0.51 > 0.5
    assert tear.apply(state, x, x, 0.1, 0.2)
    assert state.spring_intact.tolist() == [True, True, False]
    x[3, 0] = 6.0  # relaxed again: still broken
    x[1, 0] = 1.3
    assert tear.apply(state, x, x, 0.2, 0.3)
    assert state.spring_intact.tolist() == [False, True, False]
    assert tear.run_summary() == {"springs_broken": 2, "first_break_time": 0.2}


def test_deterministic_and_backends_agree() -> None:
    rng = np.random.default_rng(4)
    n, s = 400, 1500
    index = rng.integers(0, n, (s, 2))
    rest = rng.uniform(0.5, 1.5, s)
    limit = np.where(rng.random(s) < 0.8, rng.uniform(0.1, 1.0, s), np.inf)
    x0 = rng.uniform(0, 1, (n, 3))
    results = []
    for backend in _backends() * 2:
        intact = np.ones(s, dtype=bool)
        tear = Tearing(index, rest, limit, backend)
        x = x0.copy()
        state = SimpleNamespace(particle_position=x, spring_intact=intact)
        tear.reset(state)
        log = []
        for k in range(20):
            x *= 1.05  # everything stretches a little more each step
            tear.apply(state, x, x, k * 0.1, (k + 1) * 0.1)
            log.append(intact.copy())
        results.append(np.array(log))
    for r in results[1:]:
        assert np.array_equal(r, results[0])
    assert 0 < (~results[0][-1]).sum() < s
