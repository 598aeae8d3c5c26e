"""The vortex force against an independent reference, on both backends.

f = k * (axis x (x - centre)). With axis z through the origin and no other
force, m x'' = k (-y, x, 0): a linear ODE whose solution SciPy's DOP853
gives at rtol 1e-12 from the formula written here (not from animsim's kernel).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from animsim import api
from animsim.analysis.compare import observed_order

SCENE = """
duration: 1.0
dt: {dt}
integrator: {method}
particles:
  - {{id: p, mass: 2.0, position: [1.0, 0.5, 0.2], velocity: [0.0, 0.3, 0.1]}}
forces:
  - {{type: vortex, center: [0, 0, 0], axis: [0, 0, 2], k: 3.0}}
"""


def _reference(times: np.ndarray) -> np.ndarray:
    k, m = 3.0, 2.0

    def rhs(t, y):
        x, v = y[:3], y[3:]
        f = k * np.array([-x[1], x[0], 0.0])
        return np.concatenate([v, f / m])

    y0 = [1.0, 0.5, 0.2, 0.0, 0.3, 0.1]
    sol = solve_ivp(rhs, (0, times[-1]), y0, t_eval=times, rtol=1e-12, atol=1e-14, method="DOP853")
    return sol.y[:3].T


def _final_error(method: str, dt: float, backend: str = "numpy") -> float:
    traj = api.simulate(api.loads(SCENE.format(dt=dt, method=method)), backend=backend)
    ref = _reference(traj.times)
    return float(np.abs(traj.positions[:, 0] - ref).max())


@pytest.mark.parametrize(("method", "order"), [("euler", 1), ("midpoint", 2), ("rk4", 4), ("verlet", 2)])
def test_vortex_converges_at_the_method_order(method, order):
    dts = [0.02, 0.01, 0.005]
    errs = [_final_error(method, dt) for dt in dts]
    assert errs[-1] < 1e-2
    assert abs(observed_order(dts, errs) - order) < 0.2


def test_implicit_euler_uses_the_jacobian():
    # first order, and exactly the linear system's backward Euler (the force is linear)
    errs = [_final_error("implicit_euler", dt) for dt in (0.02, 0.01, 0.005)]
    assert abs(observed_order([0.02, 0.01, 0.005], errs) - 1) < 0.2


def test_numba_backend_agrees():
    pytest.importorskip("numba")
    a = api.simulate(api.loads(SCENE.format(dt=0.01, method="rk4")), backend="numpy")
    b = api.simulate(api.loads(SCENE.format(dt=0.01, method="rk4")), backend="numba")
    np.testing.assert_array_equal(a.positions, b.positions)


def test_zero_axis_is_refused():
    with pytest.raises(api.SceneError) as err:
        api.loads(SCENE.format(dt=0.01, method="rk4").replace("axis: [0, 0, 2]", "axis: [0, 0, 0]"))
    assert "forces.0.axis" in str(err.value) and "must not be zero" in str(err.value)
