"""How each integrator advances bodies' orientations and angular velocities with the particles.

The state of a body is (x, v) in its particle row plus (q, omega). Each method
treats (q, omega) as it treats (x, v), with q' = 1/2 (0, omega) (x) q in place of
x' = v and omega' from Euler's equations in place of v' = F/m
(:mod:`animsim.bodies.dynamics`):

* explicit Runge-Kutta tableaux (euler, midpoint, heun, rk4): the same stages on
  the whole system y = (x, v, q, omega), so the order is the method's;
* symplectic_euler: omega += dt I_w^-1 tau(t) (a kick by the torques), then the free rotation
  for dt by the implicit midpoint rule on the body-frame angular momentum, which keeps the
  kinetic energy and |L| (:func:`animsim.bodies.quaternion.advance_rotation`);
* euler_average: omega1 = omega + dt omega'; q += dt q'(q, (omega + omega1) / 2);
* verlet: x and v as velocity Verlet; q by a midpoint step with omega at
  t + dt/2 predicted, omega by the trapezoid rule on omega' at the start and at
  the predicted end (second order; two force evaluations per step).

Keeping q unit: stage quaternions are normalised before the forces see them
(q / |q| is a smooth extension of the rotation off the unit sphere, so the
method's order is unchanged), and q is normalised after every step. The
exact flow keeps |q| = 1, so the correction is of the size of the step's
local error and never spoils the order.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.bodies import quaternion as quat


class _Work:
    """Per-integrator scratch arrays (allocated once)."""

    def __init__(self, n: int, b: int, stages: int) -> None:
        self.kx = np.zeros((stages, n, 3))
        self.kv = np.zeros((stages, n, 3))
        self.kq = np.zeros((stages, b, 4))
        self.kw = np.zeros((stages, b, 3))
        self.x = np.zeros((n, 3))
        self.v = np.zeros((n, 3))
        self.q = np.zeros((b, 4))
        self.w = np.zeros((b, 3))


def _work(integ: Any, stages: int) -> _Work:
    work = getattr(integ, "_body_work", None)
    if work is None:
        n = integ.dynamics.system.particle_count
        b = integ.dynamics.system.body_count
        work = _Work(n, b, stages)
        integ._body_work = work
    return work


def step(integ: Any, state: Any, dt: float) -> None:
    """One step of ``integ`` (an animsim integrator) on a state with bodies: the rule its
    class names (``body_rule``, calling one of the functions below; compile refuses bodies
    to a method without one), then q back on the unit sphere."""
    if integ.body_rule(state, dt):
        state.body_orientation[:] = quat.normalise(state.body_orientation)


def runge_kutta(integ: Any, state: Any, dt: float) -> bool:
    """Every explicit tableau: the same stages on the whole system (x, v, q, omega)."""
    tab = integ.tableau
    dyn = integ.dynamics
    bodies = dyn.bodies
    s = len(tab.b)
    wk = _work(integ, s)
    x, v = state.particle_position, state.particle_velocity
    q, w = state.body_orientation, state.body_angular_velocity
    for i, ci in enumerate(tab.c):
        if i == 0:
            xi, vi, qi, wi = x, v, q, w
        else:
            xi, vi, qi, wi = wk.x, wk.v, wk.q, wk.w
            np.copyto(xi, x)
            np.copyto(vi, v)
            np.copyto(qi, q)
            np.copyto(wi, w)
            for j, aij in enumerate(tab.a[i]):
                if aij != 0.0:
                    xi += (dt * aij) * wk.kx[j]
                    vi += (dt * aij) * wk.kv[j]
                    qi += (dt * aij) * wk.kq[j]
                    wi += (dt * aij) * wk.kw[j]
            qi[:] = quat.normalise(qi)
        np.copyto(wk.kx[i], vi)
        wk.kq[i] = quat.derivative(qi, wi)
        bodies.accelerations(dyn, xi, vi, qi, wi, state.time + ci * dt, wk.kv[i], wk.kw[i])
    for i, bi in enumerate(tab.b):
        if bi != 0.0:
            x += (dt * bi) * wk.kx[i]
            v += (dt * bi) * wk.kv[i]
            q += (dt * bi) * wk.kq[i]
            w += (dt * bi) * wk.kw[i]
    return True


def symplectic_euler(integ: Any, state: Any, dt: float) -> bool:
    dyn = integ.dynamics
    wk = _work(integ, 1)
    x, v = state.particle_position, state.particle_velocity
    q, w = state.body_orientation, state.body_angular_velocity
    a, alpha = wk.kv[0], wk.kw[0]
    dyn.bodies.accelerations(dyn, x, v, q, w, state.time, a, alpha, gyroscopic=False)
    v += dt * a
    x += dt * v
    bodies = dyn.bodies
    if bodies.numba:
        quat.numba_advance_rotation()(q, w, alpha, bodies.inertia, bodies.inv_inertia, dt)
    else:
        quat.advance_rotation(q, w, alpha, bodies.inertia, bodies.inv_inertia, dt)
    return False  # advance_rotation normalises q itself


def euler_average(integ: Any, state: Any, dt: float) -> bool:
    dyn = integ.dynamics
    wk = _work(integ, 1)
    x, v = state.particle_position, state.particle_velocity
    q, w = state.body_orientation, state.body_angular_velocity
    a, alpha = wk.kv[0], wk.kw[0]
    dyn.bodies.accelerations(dyn, x, v, q, w, state.time, a, alpha)
    v1 = v + dt * a
    w1 = w + dt * alpha
    x += (0.5 * dt) * (v + v1)
    q += dt * quat.derivative(q, 0.5 * (w + w1))
    np.copyto(v, v1)
    np.copyto(w, w1)
    return True


def verlet(integ: Any, state: Any, dt: float) -> bool:
    dyn = integ.dynamics
    wk = _work(integ, 2)
    x, v = state.particle_position, state.particle_velocity
    q, w = state.body_orientation, state.body_angular_velocity
    a0, a1 = wk.kv[0], wk.kv[1]
    al0, al1 = wk.kw[0], wk.kw[1]
    dyn.bodies.accelerations(dyn, x, v, q, w, state.time, a0, al0)
    vp = v + dt * a0
    wp = w + dt * al0
    x += dt * v + (0.5 * dt * dt) * a0
    q_half = quat.normalise(q + (0.5 * dt) * quat.derivative(q, w))
    q += dt * quat.derivative(q_half, w + (0.5 * dt) * al0)
    q[:] = quat.normalise(q)
    dyn.bodies.accelerations(dyn, x, vp, q, wp, state.time + dt, a1, al1)
    v += (0.5 * dt) * (a0 + a1)
    w += (0.5 * dt) * (al0 + al1)
    integ.reset()  # the particle path's cached force is not this step's
    return True
