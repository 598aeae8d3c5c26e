"""Explicit Runge-Kutta methods as Butcher tableaux on one engine.

The second-order ODE x'' = a(x, v, t) is integrated as the first-order system
y = (x, v), y' = (v, a). For a tableau (c, A, b) with s stages:

    X_i = x + dt sum_j A_ij V_j,   V_i = v + dt sum_j A_ij K_j,   K_i = a(X_i, V_i, t + c_i dt)
    x  += dt sum_i b_i V_i,        v  += dt sum_i b_i K_i

(Hairer, Norsett and Wanner, "Solving Ordinary Differential Equations I",
II.1.) With the one-stage tableau this is exactly the course notes' Euler
method, x += dt v(t), v += dt a(t); the explicit midpoint tableau is the
notes' "Midpoint method", derivative at t + dt/2. The tableaux themselves
are data, one module each in :mod:`animsim.methods`.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from animsim.bodies import integrate as bodies
from animsim.bodies.integrate import step as body_step
from animsim.dynamics import Dynamics
from animsim.integrators.base import FUSED_RUNGE_KUTTA, Integrator
from animsim.methods import Method, Tableau
from animsim.system import State


class RungeKutta(Integrator):
    tableau: Tableau

    def body_rule(self, state: State, dt: float) -> bool:
        return bodies.runge_kutta(self, state, dt)

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        n = dynamics.system.particle_count
        tab = self.tableau
        s = len(tab.b)
        self._kx = np.zeros((s, n, 3))  # stage velocities V_i (the x-derivative)
        self._kv = np.zeros((s, n, 3))  # stage accelerations K_i
        self._x = np.zeros((n, 3))
        self._v = np.zeros((n, 3))
        self._tmp = np.zeros((n, 3))
        # The tableau read once: per stage its c_i and nonzero (A_ij, j); the
        # nonzero (b_i, i); the stage arrays as views. A tiny scene's step is
        # mostly NumPy calls, so each is counted: V_i is summed straight into its
        # own K row (no copy of V_i), and X_i = x + dt A_i1 V_1 + ... starts from the
        # first product (x + p and p + x are the same number).
        kx, kv = list(self._kx), list(self._kv)
        self._kx0 = kx[0]  # the view the stage rows hold (V_1 is read from v instead)
        self._stages = [
            (ci, [(aij, kx[j], kv[j]) for j, aij in enumerate(tab.a[i]) if aij != 0.0], kx[i], kv[i])
            for i, ci in enumerate(tab.c)
        ]
        self._weights = [(bi, i, kx[i], kv[i]) for i, bi in enumerate(tab.b) if bi != 0.0]

    def numba_chunk_kind(self) -> tuple[int, Tableau]:
        return FUSED_RUNGE_KUTTA, self.tableau

    def step(self, state: State, dt: float) -> None:
        if state.body_orientation is not None:  # rigid bodies: (q, omega) advance too
            return body_step(self, state, dt)
        if self.dynamics.drivers:  # keyframed rows are moved inside each evaluation
            return self._step_driven(state, dt)
        x, v = state.particle_position, state.particle_velocity
        t = state.time
        acceleration = self.dynamics.acceleration
        xi, tmp, kx0 = self._x, self._tmp, self._kx0
        multiply = np.multiply
        for i, (ci, row, kxi, kvi) in enumerate(self._stages):
            if i == 0:
                # V_1 = v, read from v itself: v changes only after its last use
                # (the first weight's position update, below)
                acceleration(x, v, t + ci * dt, kvi)
                continue
            if not row:  # X_i = x, V_i = v
                np.copyto(xi, x)
                np.copyto(kxi, v)
            for m, (aij, kxj, kvj) in enumerate(row):
                c = dt * aij
                if kxj is kx0:
                    kxj = v
                if m == 0:
                    multiply(kxj, c, out=xi)
                    xi += x
                    multiply(kvj, c, out=kxi)
                    kxi += v
                else:
                    multiply(kxj, c, out=tmp)
                    xi += tmp
                    multiply(kvj, c, out=tmp)
                    kxi += tmp
            acceleration(xi, kxi, t + ci * dt, kvi)
        for bi, i, kxi, kvi in self._weights:
            c = dt * bi
            multiply(v if i == 0 else kxi, c, out=tmp)
            x += tmp
            multiply(kvi, c, out=tmp)
            v += tmp

    def _step_driven(self, state: State, dt: float) -> None:
        """The step with keyframe drives, which move driven rows of the arrays an evaluation
        is given: each stage's V_i is kept as it was before its evaluation."""
        x, v = state.particle_position, state.particle_velocity
        t = state.time
        acceleration = self.dynamics.acceleration
        xi, vi = self._x, self._v
        for i, (ci, row, kxi, kvi) in enumerate(self._stages):
            if i == 0:
                np.copyto(kxi, v)
                acceleration(x, v, t + ci * dt, kvi)
                continue
            np.copyto(xi, x)
            np.copyto(vi, v)
            for aij, kxj, kvj in row:
                xi += (dt * aij) * kxj
                vi += (dt * aij) * kvj
            np.copyto(kxi, vi)
            acceleration(xi, vi, t + ci * dt, kvi)
        for bi, _i, kxi, kvi in self._weights:
            x += (dt * bi) * kxi
            v += (dt * bi) * kvi


def runge_kutta_class(method: Method) -> type[RungeKutta]:
    """The stepper of an explicit Runge-Kutta method: the one tableau engine with its tableau."""
    if method.tableau is None:
        raise ValueError(f"method {method.name!r} has no tableau")
    cls = cast(
        type[RungeKutta], type(f"RungeKutta_{method.name}", (RungeKutta,), {"tableau": method.tableau})
    )
    cls.bind_method(method)
    return cls
