"""Explicit Runge-Kutta methods as Butcher tableaux on one engine.

The second-order ODE x'' = a(x, v, t) is integrated as the first-order system
y = (x, v), y' = (v, a). For a tableau (c, A, b) with s stages:

    X_i = x + dt sum_j A_ij V_j,   V_i = v + dt sum_j A_ij K_j,   K_i = a(X_i, V_i, t + c_i dt)
    x  += dt sum_i b_i V_i,        v  += dt sum_i b_i K_i

(Hairer, Norsett and Wanner, "Solving Ordinary Differential Equations I",
II.1.) With the one-stage tableau this is exactly the course notes' Euler
method, x += dt v(t), v += dt a(t); the explicit midpoint tableau is the
notes' "Midpoint method", derivative at t + dt/2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from animsim.dynamics import Dynamics
from animsim.integrators.base import FUSED_RUNGE_KUTTA, Integrator
from animsim.system import State


@dataclass(frozen=True)
class Tableau:
    c: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]  # strictly lower triangular rows
    b: tuple[float, ...]


EULER = Tableau(c=(0.0,), a=((),), b=(1.0,))
MIDPOINT = Tableau(c=(0.0, 0.5), a=((), (0.5,)), b=(0.0, 1.0))
HEUN = Tableau(c=(0.0, 1.0), a=((), (1.0,)), b=(0.5, 0.5))
RK4 = Tableau(
    c=(0.0, 0.5, 0.5, 1.0),
    a=((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)),
    b=(1 / 6, 1 / 3, 1 / 3, 1 / 6),
)


class RungeKutta(Integrator):
    tableau: Tableau

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        n = dynamics.system.particle_count
        s = len(self.tableau.b)
        self._kx = np.zeros((s, n, 3))  # stage velocities V_i (the x-derivative)
        self._kv = np.zeros((s, n, 3))  # stage accelerations K_i
        self._x = np.zeros((n, 3))
        self._v = np.zeros((n, 3))

    def numba_chunk_kind(self) -> tuple[int, Tableau]:
        return FUSED_RUNGE_KUTTA, self.tableau

    def step(self, state: State, dt: float) -> None:
        tab = self.tableau
        x, v = state.particle_position, state.particle_velocity
        kx, kv = self._kx, self._kv
        for i, ci in enumerate(tab.c):
            if i == 0:
                xi, vi = x, v
            else:
                xi, vi = self._x, self._v
                np.copyto(xi, x)
                np.copyto(vi, v)
                for j, aij in enumerate(tab.a[i]):
                    if aij != 0.0:
                        xi += (dt * aij) * kx[j]
                        vi += (dt * aij) * kv[j]
            np.copyto(kx[i], vi)
            self.dynamics.acceleration(xi, vi, state.time + ci * dt, kv[i])
        for i, bi in enumerate(tab.b):
            if bi != 0.0:
                x += (dt * bi) * kx[i]
                v += (dt * bi) * kv[i]


class Euler(RungeKutta):
    name = "euler"
    order = 1
    evaluations_per_step = 1
    description = "explicit (forward) Euler: x += dt*v(t); v += dt*a(t)"
    tableau = EULER


class Midpoint(RungeKutta):
    name = "midpoint"
    order = 2
    evaluations_per_step = 2
    description = "explicit midpoint (RK2): derivative taken at t + dt/2"
    tableau = MIDPOINT


class Heun(RungeKutta):
    name = "heun"
    order = 2
    evaluations_per_step = 2
    description = "Heun's method (explicit trapezoid, RK2)"
    tableau = HEUN


class RK4(RungeKutta):
    name = "rk4"
    order = 4
    evaluations_per_step = 4
    description = "classical fourth-order Runge-Kutta"
    tableau = RK4
