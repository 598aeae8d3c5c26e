"""Adaptive step size by step doubling, on either backend's kernels."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.guard import Failure, Guard
from animsim.measures.stability import particle_name
from animsim.steppers.base import StepperBase
from animsim.system import State

if TYPE_CHECKING:
    from animsim.compile import Compiled

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


class StepDoubling(StepperBase):
    """Adaptive step size by step doubling.

    "Every so often test the difference between using step size dt and dt/2. If
    the difference is big enough start using dt/2. Do the same for dt*2." (the
    course notes). Here the test is made on every step: one step of h and two of
    h/2 from the same state; their difference estimates the local error of the
    two half steps (Hairer, Norsett and Wanner I, II.4, "Richardson
    extrapolation"). The step is

    * rejected and retried with h/2 while the difference exceeds ``tolerance``
      (a run whose step would fall below ``dt_min`` stops as ``unstable``);
    * accepted otherwise, keeping the two half steps (the more accurate result);
    * doubled, up to ``dt_max``, when the difference is below
      tolerance / 2^(p+1), p the method's order: a step twice as long has about
      2^(p+1) times the local error, so the doubled step should still pass.

    Steps are shortened to land exactly on the record clock's times, without
    changing the step size the controller carries on with, and every step stays
    within [dt_min, dt_max] (:func:`next_step`): a step that would leave less
    than dt_min before a record time is stretched to land on it, or, where that
    would pass dt_max, the rest is split in two equal steps.
    """

    def __init__(self, compiled: Compiled, numba: bool = False):
        super().__init__(compiled, numba)
        spec = compiled.adaptive
        assert spec is not None  # make_stepper picks this stepper only for an adaptive clock
        self.tolerance = float(spec.tolerance)
        self.dt_min = float(spec.dt_min)
        self.dt_max = float(spec.dt_max)
        self.largest_dt = max(self.dt_max, compiled.clock.dt)
        # Steps grow past the nominal clock: run to each record time, check there (and replay).
        self.check_stride = self.end
        # The controller's step size is not restored for a replay, so births (drawn once per
        # accepted step) keep the check at every step here.
        self.replayable = not any(st.random for st in compiled.post_step)
        self.grow_below = self.tolerance / DOUBLING_BASE ** (compiled.integrator.order + 1)
        self._movable = compiled.system.particle_inv_mass > 0
        #: per body, its bounding radius (m): how far a turn moves its farthest point
        self._body_reach = (
            np.array([shape.bounding_radius for shape in compiled.system.body_shape])
            if compiled.system.body_count
            else None
        )
        self._big: State | None = None
        self._small: State | None = None
        self.h = min(max(compiled.clock.dt, self.dt_min), self.dt_max)
        self.accepted = 0
        self.rejected = 0
        self.smallest = np.inf
        self.largest = 0.0
        # Trial steps run the stages that draw no random numbers; the others run once accepted.
        self.once = tuple(st for st in self.stages if st.random)
        self.stages = tuple(st for st in self.stages if not st.random)

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

    def books_inside(self, guard: Guard) -> bool:
        return False  # births keep this stepper's runs checked (and booked) at every step

    def position(self, state: State) -> int:
        # the last clock point at or before the state's time (replays start from checked states)
        k = 0
        while k < self.end and self.clock.time(k + 1) <= state.time:
            k += 1
        return k

    def _error(self, big: State, small: State, h: float) -> tuple[float, int]:
        """Largest difference (m) between the two results, and the particle it is at."""
        dx = np.abs(big.particle_position - small.particle_position).max(axis=1)
        dv = np.abs(big.particle_velocity - small.particle_velocity).max(axis=1)
        e = np.where(self._movable, np.maximum(dx, h * dv), 0.0)
        if self._body_reach is not None:
            # a body's turn counts as the distance its farthest point moves: the angle between the
            # two orientations (2 atan2(|vector part|, |scalar part|) of q_big q_small^-1) and h
            # times the difference of angular velocities, times the body's bounding radius
            from animsim.bodies import quaternion as quat

            assert big.body_orientation is not None and small.body_orientation is not None
            assert big.body_angular_velocity is not None and small.body_angular_velocity is not None
            d = quat.multiply(big.body_orientation, quat.conjugate(small.body_orientation))
            angle = 2.0 * np.arctan2(np.linalg.norm(d[:, 1:], axis=1), np.abs(d[:, 0]))
            dw = np.abs(big.body_angular_velocity - small.body_angular_velocity).max(axis=1)
            turn = self._body_reach * np.maximum(angle, h * dw)
            rows = self.compiled.system.body_rows
            e[rows] = np.where(self._movable[rows], np.maximum(e[rows], turn), e[rows])
        i = int(np.argmax(np.where(np.isfinite(e), e, np.inf)))
        return float(e[i]) if np.isfinite(e[i]) else np.inf, i

    def _trial(self, trial: State, state: State, h: float, halves: int) -> None:
        trial.assign(state)
        self.compiled.integrator.reset()  # Verlet's cached force belongs to one trajectory
        for _ in range(halves):
            self._one(trial, h / halves, trial.time + h / halves)

    def advance(self, state: State, k: int, goal: int, max_steps: int | None = None) -> tuple[int, Any, bool]:
        if self._big is None:
            self._big, self._small = state.copy(), state.copy()
        big, small = self._big, self._small
        assert small is not None
        clock = self.clock
        taken = 0
        while k < goal and (max_steps is None or taken < max_steps):
            target = clock.time(goal)
            h_try, landing = next_step(self.h, target - state.time, self.dt_min, self.dt_max)
            # The trial steps only see dynamics (no births): emitters run once, on the accepted step.
            self._trial(big, state, h_try, 1)
            self._trial(small, state, h_try, 2)
            err, worst = self._error(big, small, h_try)
            if not err <= self.tolerance:  # NaN or inf count as too large
                if 0.5 * h_try < self.dt_min:
                    failure = Failure(
                        step=state.step,
                        time=state.time,
                        particle=particle_name(self.compiled, worst),
                        reason=(
                            f"adaptive step: the step-doubling error {err:.3g} m exceeds the "
                            f"tolerance {self.tolerance:g} m even at dt_min = {self.dt_min:g} s"
                        ),
                        suggestion=(
                            "raise tolerance or lower dt_min; for a stiff scene use "
                            "implicit_euler, which needs no tiny steps"
                        ),
                    )
                    return k, failure, False
                self.h = 0.5 * h_try
                self.rejected += 1
                continue
            t_start, t_end = state.time, (target if landing else state.time + h_try)
            state.assign(small)
            state.time = t_end
            for stage in self.once:  # births: once per accepted step, never on a trial
                if stage.apply(state, self._x_old, self._v_old, t_start, t_end, h_try):
                    state.revision += 1
            state.step += 1
            taken += 1
            self.accepted += 1
            self.smallest = min(self.smallest, h_try)
            self.largest = max(self.largest, h_try)
            if not landing and err < self.grow_below:
                self.h = min(2.0 * self.h, self.dt_max)
            if landing:
                k = goal
        return k, None, False
