"""Keyframed paths: every key hit exactly, velocity = the path's derivative, ends held."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.keyframes import KeyframeDrive, PathEvaluator
from animsim.paths import make_paths

KEYS = [
    (0.0, (0.0, 2.0, 0.0)),
    (0.4, (0.5, 2.5, -0.2)),
    (1.0, (1.5, 2.0, 0.3)),
    (1.3, (1.0, 1.0, 1.0)),
]


def _paths():
    # the same keys linear and smooth, plus a one-key path and a shifted two-key one
    return make_paths(
        [KEYS, KEYS, [(0.5, (1.0, 1.0, 1.0))], [(0.2, (0.0, 0.0, 0.0)), (0.7, (1.0, -1.0, 2.0))]],
        [False, True, True, True],
    )


def _backends():
    out = ["numpy"]
    try:
        import numba  # noqa: F401

        out.append("numba")
    except ImportError:  # pragma: no cover
        pass
    return out


@pytest.mark.parametrize("backend", _backends())
def test_every_key_is_hit_exactly(backend: str) -> None:
    ev = PathEvaluator(_paths(), backend)
    for t, p in KEYS:
        pos, _ = ev(t)
        assert np.array_equal(pos[0], p) and np.array_equal(pos[1], p)
    pos, _ = ev(0.2)
    assert np.array_equal(pos[3], (0.0, 0.0, 0.0))
    pos, _ = ev(0.7)
    assert np.array_equal(pos[3], (1.0, -1.0, 2.0))


@pytest.mark.parametrize("backend", _backends())
def test_velocity_is_the_derivative_of_the_position(backend: str) -> None:
    ev = PathEvaluator(_paths(), backend)
    h = 1e-6
    for t in np.linspace(-0.3, 1.6, 97):
        if any(abs(t - k[0]) < 2 * h for k in KEYS) or abs(t - 0.2) < 2 * h or abs(t - 0.7) < 2 * h:
            continue
        pos_p, _ = ev(t + h)
        pos_p = pos_p.copy()
        pos_m, _ = ev(t - h)
        pos_m = pos_m.copy()
        _, vel = ev(t)
        central = (pos_p - pos_m) / (2 * h)
        np.testing.assert_allclose(vel, central, atol=1e-6)


def test_smooth_path_is_c1_at_interior_keys_and_eases_at_the_ends() -> None:
    ev = PathEvaluator(_paths(), "numpy")
    for t, _ in KEYS[1:-1]:
        _, v_before = ev(t - 1e-9)
        v_before = v_before.copy()
        _, v_after = ev(t + 1e-9)
        np.testing.assert_allclose(v_before[1], v_after[1], atol=1e-6)
    # zero tangent at both ends: the velocity is continuous into the holds
    _, v0 = ev(1e-9)
    _, v1 = ev(1.3 - 1e-9)
    assert np.abs(v0[1]).max() < 1e-6
    assert np.abs(v1[1]).max() < 1e-6
    # the Catmull-Rom tangent at key 1: (p2 - p0) / (t2 - t0)
    _, v = ev(0.4)
    np.testing.assert_allclose(v[1], (np.array(KEYS[2][1]) - KEYS[0][1]) / 1.0, atol=1e-12)


def test_holds_before_the_first_and_after_the_last_key() -> None:
    ev = PathEvaluator(_paths(), "numpy")
    for t in (-5.0, -1e-12):
        pos, vel = ev(t)
        assert np.array_equal(pos[0], KEYS[0][1]) and not vel[:2].any()
    for t in (1.3 + 1e-12, 99.0):
        pos, vel = ev(t)
        assert np.array_equal(pos[1], KEYS[-1][1]) and not vel[:2].any()
    pos, vel = ev(3.0)
    assert np.array_equal(pos[2], (1.0, 1.0, 1.0)) and not vel[2].any()


def test_linear_velocity_is_the_segment_slope() -> None:
    ev = PathEvaluator(_paths(), "numpy")
    _, vel = ev(0.7)
    slope = (np.array(KEYS[2][1]) - KEYS[1][1]) / 0.6
    np.testing.assert_allclose(vel[0], slope, rtol=1e-12)


def test_numba_and_numpy_agree() -> None:
    pytest.importorskip("numba")
    a, b = PathEvaluator(_paths(), "numpy"), PathEvaluator(_paths(), "numba")
    for t in np.linspace(-1, 2, 301):
        pa, va = a(t)
        pb, vb = b(t)
        np.testing.assert_allclose(pa, pb, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(va, vb, rtol=1e-12, atol=1e-12)


def test_drive_puts_rows_on_base_plus_path() -> None:
    paths = make_paths([[(0.0, (0.0, 0.0, 0.0)), (1.0, (1.0, 0.0, 0.0))]], [False])
    drive = KeyframeDrive(
        np.array([2, 0]), np.array([0, 0]), np.array([[0, 1, 0], [5, 5, 5]]), paths, "numpy"
    )
    x = np.zeros((3, 3))
    v = np.zeros((3, 3))
    drive.drive(0.25, x, v)
    np.testing.assert_allclose(x, [[5.25, 5, 5], [0, 0, 0], [0.25, 1, 0]])
    np.testing.assert_allclose(v, [[1, 0, 0], [0, 0, 0], [1, 0, 0]])
    assert drive.injects
