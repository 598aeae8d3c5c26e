"""Methods that treat position and velocity differently.

* ``symplectic_euler``: the course notes' semi-implicit Euler, v += dt a(t);
  x += dt v(t + dt). Symplectic, so the energy of an undamped oscillator stays
  bounded for omega dt < 2.
* ``euler_average``: the "Euler 2" of the CSE 3541 notes, endv = v + dt a;
  x += dt (v + endv)/2; v = endv. Exact for a constant force, first order
  otherwise.
* ``verlet``: velocity Verlet (Swope et al. 1982). Velocity-dependent forces
  (drag, spring damping) are evaluated at the predicted velocity v + dt a,
  then corrected by the trapezoid rule, so the method stays second order.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.bodies import integrate as bodies
from animsim.bodies.integrate import step as body_step
from animsim.dynamics import Dynamics
from animsim.integrators.base import (
    FUSED_EULER_AVERAGE,
    FUSED_SYMPLECTIC_EULER,
    FUSED_VERLET,
    Integrator,
)
from animsim.system import State

#: relative tolerance when deciding that Verlet's cached acceleration is for this time
CACHE_TIME_RTOL = 1e-9


class SymplecticEuler(Integrator):
    method_name = "symplectic_euler"

    def body_rule(self, state: State, dt: float) -> bool:
        return bodies.symplectic_euler(self, state, dt)

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        self._a = np.zeros((dynamics.system.particle_count, 3))
        #: dt * a for a constant acceleration (Dynamics.constant_acceleration), for the
        #: acceleration array and the dt it was made from
        self._dv = np.zeros_like(self._a)
        self._dv_of: tuple[np.ndarray, float] | None = None

    def numba_chunk_kind(self) -> tuple[int, None]:
        return FUSED_SYMPLECTIC_EULER, None

    block_stages = True

    def step(self, state: State, dt: float, stage: Any = None) -> None:
        if state.body_orientation is not None:  # rigid bodies: (q, omega) advance too
            return body_step(self, state, dt)
        x, v = state.particle_position, state.particle_velocity
        dyn = self.dynamics
        a0 = dyn.constant_acceleration
        if a0 is not None:
            # Every force constant (gravity alone): dt * a is the same product at every
            # step of the same dt, so it is made once, not copied and scaled each step
            # (two of a tiny scene's six NumPy calls a step); the same numbers.
            dyn.evaluations += 1
            made = self._dv_of
            if made is None or made[0] is not a0 or made[1] != dt:
                np.multiply(a0, dt, out=self._dv)
                self._dv_of = (a0, dt)
            v += self._dv
            np.multiply(v, dt, out=self._a)
            x += self._a
            return
        if dyn.blocks:  # many particles: each block of rows updated while it is in cache

            def update(rows: slice, a: np.ndarray) -> None:
                a *= dt
                v[rows] += a
                np.multiply(v[rows], dt, out=a)
                x[rows] += a

            if stage is not None:  # a post-step stage meets each block while it is in cache

                def update_and_stage(rows: slice, a: np.ndarray) -> None:
                    stage.before(rows)
                    update(rows, a)
                    stage.after(rows)

                dyn.acceleration_blocks(x, v, state.time, self._a, update_and_stage, stage.block_rows)
                return
            dyn.acceleration_blocks(x, v, state.time, self._a, update)
            return
        a = dyn.acceleration(x, v, state.time, self._a)
        # In place through our own buffer: the same products as v += dt*a;
        # x += dt*v, without two (N, 3) temporaries per step.
        a *= dt
        v += a
        np.multiply(v, dt, out=a)
        x += a


class EulerAverage(Integrator):
    method_name = "euler_average"

    def body_rule(self, state: State, dt: float) -> bool:
        return bodies.euler_average(self, state, dt)

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        n = dynamics.system.particle_count
        self._a = np.zeros((n, 3))
        self._v1 = np.zeros((n, 3))

    def numba_chunk_kind(self) -> tuple[int, None]:
        return FUSED_EULER_AVERAGE, None

    def step(self, state: State, dt: float) -> None:
        if state.body_orientation is not None:  # rigid bodies: (q, omega) advance too
            return body_step(self, state, dt)
        x, v = state.particle_position, state.particle_velocity
        a = self.dynamics.acceleration(x, v, state.time, self._a)
        v1 = self._v1
        np.multiply(a, dt, out=v1)
        v1 += v  # endv = v + dt*a
        x += (0.5 * dt) * (v + v1)
        np.copyto(v, v1)


class Verlet(Integrator):
    method_name = "verlet"

    def body_rule(self, state: State, dt: float) -> bool:
        return bodies.verlet(self, state, dt)

    def __init__(self, dynamics: Dynamics):
        super().__init__(dynamics)
        n = dynamics.system.particle_count
        self._a0 = np.zeros((n, 3))
        self._a1 = np.zeros((n, 3))
        self._vp = np.zeros((n, 3))
        self._cache: tuple[int, float] | None = None  # (revision, time) _a0 is valid for

    def reset(self) -> None:
        self._cache = None

    def numba_chunk_kind(self) -> tuple[int, None]:
        return FUSED_VERLET, None

    def step(self, state: State, dt: float) -> None:
        if state.body_orientation is not None:  # rigid bodies: (q, omega) advance too
            return body_step(self, state, dt)
        x, v = state.particle_position, state.particle_velocity
        # The loop sets state.time from the clock (duration * i / steps), which can
        # differ from the cached time + dt in the last bit; compare with a tolerance
        # so the cached acceleration is reused and Verlet costs one evaluation per step.
        cached = self._cache
        if (
            cached is None
            or cached[0] != state.revision
            or abs(cached[1] - state.time) > CACHE_TIME_RTOL * max(abs(state.time), dt)
        ):
            self.dynamics.acceleration(x, v, state.time, self._a0)
        a0 = self._a0
        np.multiply(a0, dt, out=self._vp)
        self._vp += v  # predicted v(t+dt)
        x += dt * v + (0.5 * dt * dt) * a0
        a1 = self.dynamics.acceleration(x, self._vp, state.time + dt, self._a1)
        v += (0.5 * dt) * (a0 + a1)
        # a1 is the next step's a0 unless something changes the state in between.
        self._a0, self._a1 = a1, a0
        self._cache = (state.revision, state.time + dt)
