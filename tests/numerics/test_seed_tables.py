"""The course notes' worked projectile tables, reproduced to 1e-9.

A ball launched from the ground with v0 = [10, 10, 0] under g = [0, -9.81, 0]
at dt = 0.1 s. The first lecture steps explicit Euler (position with the old
velocity), the second semi-implicit Euler (velocity first). The first
lecture's slide shows v4 = 7.0570, a copy of v3: the arithmetic gives
10 - 4 * 0.981 = 6.076, which is what we check.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import SCENES

EXPLICIT_Y = [0.0, 1.0, 1.9019, 2.7057, 3.4114, 4.019]
SEMI_IMPLICIT_Y = [0.0, 0.9019, 1.7057, 2.4114, 3.019, 3.5285]
VY = [10 - 0.981 * n for n in range(6)]
TOL = 1e-9


def _run(path):
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.record import MemorySink
    from animsim.scene.loader import load_scene

    loaded = load_scene(path)
    sink = MemorySink()
    result = run(compile_scene(loaded.scene, loaded.name), [sink])
    assert result.status == "ok"
    return sink.times(), sink.positions()[:, 0, :], sink.velocities()[:, 0, :]


@pytest.mark.parametrize(
    ("scene", "expected_y"),
    [("projectile_euler.yaml", EXPLICIT_Y), ("projectile_semi_implicit.yaml", SEMI_IMPLICIT_Y)],
)
def test_notes_table(scene, expected_y):
    t, x, v = _run(SCENES / scene)
    np.testing.assert_allclose(t, [0, 0.1, 0.2, 0.3, 0.4, 0.5], atol=0, rtol=0)
    np.testing.assert_allclose(x[:, 0], [0, 1, 2, 3, 4, 5], atol=TOL)
    np.testing.assert_allclose(x[:, 1], expected_y, atol=TOL)
    np.testing.assert_allclose(x[:, 2], 0.0, atol=0)
    np.testing.assert_allclose(v[:, 0], 10.0, atol=TOL)
    np.testing.assert_allclose(v[:, 1], VY, atol=TOL)
    np.testing.assert_allclose(v[:, 2], 0.0, atol=0)


def test_slide_typo_is_not_reproduced():
    _, _, v = _run(SCENES / "projectile_euler.yaml")
    assert abs(v[4, 1] - 6.076) < TOL
    assert abs(v[4, 1] - 7.057) > 0.5


def test_large_step_table():
    t, x, v = _run(SCENES / "projectile_large_step.yaml")
    np.testing.assert_allclose(t, [0.0, 0.5])
    np.testing.assert_allclose(x[1], [5.0, 5.0, 0.0], atol=TOL)
    np.testing.assert_allclose(v[1], [10.0, 5.095, 0.0], atol=TOL)
    # The exact height is 10*0.5 - 9.81/2*0.25 = 3.77375: the big step is far off.
    assert abs(x[1, 1] - 3.77375) > 1.0
