"""The damped spring force (Lander Eq. 2) and its scatter."""

from __future__ import annotations

import numpy as np

from animsim.forces.springs import Springs


def loop_forces(x, v, index, rest, ks, kd):
    """Reference: the article's Listing 3, one spring at a time."""
    f = np.zeros_like(x)
    for (a, b), r, k, c in zip(index, rest, ks, kd, strict=True):
        d = x[a] - x[b]
        dist = np.linalg.norm(d)
        if dist == 0:
            continue
        hterm = (dist - r) * k
        dterm = np.dot(v[a] - v[b], d) * c / dist
        fs = -(hterm + dterm) * d / dist
        f[a] += fs
        f[b] -= fs
    return f


def test_matches_listing_3_with_repeated_indices(rng):
    n, s = 30, 200
    x = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    index = rng.integers(0, n, size=(s, 2))
    index = index[index[:, 0] != index[:, 1]]
    rest = rng.uniform(0.1, 1.0, len(index))
    ks = rng.uniform(0, 100, len(index))
    kd = rng.uniform(0, 2, len(index))
    out = np.zeros((n, 3))
    Springs(index, rest, ks, kd, n).accumulate(x, v, 0.0, out)
    np.testing.assert_allclose(out, loop_forces(x, v, index, rest, ks, kd), rtol=1e-12, atol=1e-12)
    # Newton's third law: no net force from internal springs
    np.testing.assert_allclose(out.sum(axis=0), 0.0, atol=1e-10)


def test_coincident_particles_give_zero_force_not_nan():
    x = np.zeros((2, 3))
    v = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    out = np.zeros((2, 3))
    sp = Springs(np.array([[0, 1]]), np.array([0.0]), np.array([1e6]), np.array([5.0]), 2)
    sp.accumulate(x, v, 0.0, out)
    assert np.all(out == 0.0)
    assert sp.potential(x) == 0.0


def test_stretched_spring_pulls_together():
    x = np.array([[0.0, 0, 0], [2.0, 0, 0]])
    out = np.zeros((2, 3))
    Springs(np.array([[0, 1]]), np.array([1.0]), np.array([10.0]), np.array([0.0]), 2).accumulate(
        x, np.zeros((2, 3)), 0.0, out
    )
    np.testing.assert_allclose(out, [[10.0, 0, 0], [-10.0, 0, 0]])
