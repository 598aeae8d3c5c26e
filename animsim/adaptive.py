"""Adaptive step size by step doubling (the course notes' "Adaptive Stepsizes").

"Every so often test the difference between using step size dt and dt/2. If the
difference is big enough start using dt/2. Do the same for dt*2." Here the test
is made on every step: one step of h and two of h/2 from the same state; their
difference estimates the local error of the two half steps (Hairer, Norsett and
Wanner I, II.4, "Richardson extrapolation"). The step is

* rejected and retried with h/2 while the difference exceeds ``tolerance``
  (a run whose step would fall below ``dt_min`` stops as ``unstable``);
* accepted otherwise, keeping the two half steps (the more accurate result);
* doubled, up to ``dt_max``, when the difference is below
  tolerance / 2^(p+1), p the method's order: a step twice as long has about
  2^(p+1) times the local error, so the doubled step should still pass.

Steps are shortened to land exactly on the record clock's times, without
changing the step size the controller carries on with, and every step stays
within [dt_min, dt_max] (:func:`next_step`): a step that would leave less than
dt_min before a record time is stretched to land on it, or, where that would
pass dt_max, the rest is split in two equal steps.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from animsim.record import FrameSink
from animsim.system import State

#: a doubled step has about DOUBLING_BASE^(p+1) times the local error of the two halves
DOUBLING_BASE = 2.0
#: a step this close (relative) to the distance left lands on the record time, so
#: rounding in the accumulated time never leaves a sliver of a step behind
LANDING_SLACK = 1e-6


#: a rest shorter than dt_min by up to this fraction of dt_min counts as a sliver too, so
#: rounding in the accumulated time cannot turn a rest of exactly dt_min into a step below it
SLIVER_SLACK = 1e-3


def next_step(h: float, distance: float, dt_min: float, dt_max: float) -> tuple[float, bool]:
    """The step to try next and whether it lands on the record time ``distance`` ahead.

    ``h`` is the controller's step size, kept within [dt_min, dt_max]. The
    step is h, except near the record time:

    * the whole distance when it is at most h (within LANDING_SLACK), or
      when a step of h would leave less than dt_min and the distance is at most
      dt_max (one step of at most h + dt_min instead of h and a sliver);
    * half the distance when a step of h would leave less than dt_min but the
      distance is beyond dt_max: two equal steps, each at most dt_max (the
      distance is below h + dt_min <= 2 dt_max) and at least dt_min whenever
      dt_max >= 2 dt_min.

    So every step is within [dt_min, dt_max], except one that lands on a
    record time closer than dt_min to the previous one (the record clock's own
    spacing, which no step size can avoid).
    """
    h = min(max(h, dt_min), dt_max)
    sliver = distance - h < dt_min * (1.0 + SLIVER_SLACK)
    if distance <= h * (1.0 + LANDING_SLACK) and distance <= dt_max:
        return distance, True
    if sliver:
        if distance <= dt_max:
            return distance, True
        return 0.5 * distance, False
    return h, False


def _copy_into(dst: State, src: State) -> None:
    np.copyto(dst.particle_position, src.particle_position)
    np.copyto(dst.particle_velocity, src.particle_velocity)
    if src.particle_alive is not None and dst.particle_alive is not None:
        np.copyto(dst.particle_alive, src.particle_alive)
    dst.time, dst.step, dst.revision = src.time, src.step, src.revision


class StepDoubling:
    """Runs a compiled scene with an adaptive step (see the module docstring)."""

    def __init__(self, compiled: Any, adaptive: Any, guard: Any):
        self.compiled = compiled
        self.integ = compiled.integrator
        self.colliders = compiled.colliders
        self.guard = guard
        self.tolerance = float(adaptive.tolerance)
        self.dt_min = float(adaptive.dt_min)
        self.dt_max = float(adaptive.dt_max)
        self.grow_below = self.tolerance / DOUBLING_BASE ** (self.integ.order + 1)
        self.accepted = 0
        self.rejected = 0
        self.smallest = np.inf
        self.largest = 0.0
        n = compiled.system.particle_count
        self._x_old = np.empty((n, 3))
        self._v_old = np.empty((n, 3))
        self._movable = compiled.system.particle_inv_mass > 0

    def summary(self) -> dict[str, Any]:
        return {
            "adaptive": {
                "tolerance": self.tolerance,
                "dt_min": self.dt_min,
                "dt_max": self.dt_max,
                "accepted_steps": self.accepted,
                "rejected_steps": self.rejected,
                "smallest_dt": float(self.smallest) if self.accepted else None,
                "largest_dt": float(self.largest) if self.accepted else None,
            }
        }

    def _substep(self, s: State, h: float) -> None:
        if self.colliders is not None:
            np.copyto(self._x_old, s.particle_position)
            np.copyto(self._v_old, s.particle_velocity)
        self.integ.step(s, h)
        if self.colliders is not None and self.colliders.apply(
            self._x_old, self._v_old, s.particle_position, s.particle_velocity, h
        ):
            s.revision += 1
        s.time += h

    def _error(self, big: State, small: State, h: float) -> tuple[float, int]:
        """Largest difference (m) between the two results, and the particle it is at."""
        dx = np.abs(big.particle_position - small.particle_position).max(axis=1)
        dv = np.abs(big.particle_velocity - small.particle_velocity).max(axis=1)
        e = np.where(self._movable, np.maximum(dx, h * dv), 0.0)
        i = int(np.argmax(np.where(np.isfinite(e), e, np.inf)))
        return float(e[i]) if np.isfinite(e[i]) else np.inf, i

    def run(
        self,
        state: State,
        sinks: Sequence[FrameSink],
        frames: int,
        stop: Callable[[], bool] | None,
        progress: Callable[[int, int], None] | None,
        observers: Sequence[Callable[[State], None]] = (),
    ) -> tuple[str, Any, int]:
        """Advance ``state`` to the end of the clock; returns (status, failure, frames)."""
        from animsim.analysis.stability import particle_name
        from animsim.simulate import STATUS_INTERRUPTED, STATUS_OK, STATUS_UNSTABLE, Failure, _emit

        compiled = self.compiled
        clock = compiled.clock
        emitters = compiled.emitters
        targets = [clock.time(int(k)) for k in compiled.record_steps if k > 0]
        big, small = state.copy(), state.copy()
        h = min(max(clock.dt, self.dt_min), self.dt_max)
        nominal = clock.steps
        for target in targets:
            while state.time < target:
                h_try, landing = next_step(h, target - state.time, self.dt_min, self.dt_max)
                self.integ.reset()  # Verlet's cached force belongs to one trajectory
                _copy_into(big, state)
                self._substep(big, h_try)
                self.integ.reset()
                _copy_into(small, state)
                self._substep(small, 0.5 * h_try)
                self._substep(small, 0.5 * h_try)
                err, worst = self._error(big, small, h_try)
                if not err <= self.tolerance:  # NaN or inf count as too large
                    if 0.5 * h_try < self.dt_min:
                        return (
                            STATUS_UNSTABLE,
                            Failure(
                                step=state.step,
                                time=state.time,
                                particle=particle_name(compiled, worst),
                                reason=(
                                    f"adaptive step: the step-doubling error {err:.3g} m exceeds the "
                                    f"tolerance {self.tolerance:g} m even at dt_min = {self.dt_min:g} s"
                                ),
                                suggestion=(
                                    "raise tolerance or lower dt_min; for a stiff scene use "
                                    "implicit_euler, which needs no tiny steps"
                                ),
                            ),
                            frames,
                        )
                    h = 0.5 * h_try
                    self.rejected += 1
                    continue
                t_start, t_end = state.time, (target if landing else state.time + h_try)
                _copy_into(state, small)
                state.time = t_end
                if emitters is not None:
                    emitters.advance(compiled, state, t_start, t_end)
                state.step += 1
                self.accepted += 1
                self.smallest = min(self.smallest, h_try)
                self.largest = max(self.largest, h_try)
                failure = self.guard.check(state)
                if failure is not None:
                    return STATUS_UNSTABLE, failure, frames
                if not landing and err < self.grow_below:
                    h = min(2.0 * h, self.dt_max)
                if progress is not None:
                    progress(int(nominal * state.time / clock.duration), nominal)
                if stop is not None and stop():
                    return STATUS_INTERRUPTED, None, frames
            _emit(compiled, state, sinks, observers)
            frames += 1
        return STATUS_OK, None, frames
