"""The stepper of one integrator step at a time (NumPy kernels, or the elements' numba kernels)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from animsim.steppers.base import StepperBase
from animsim.system import State

if TYPE_CHECKING:
    from animsim.compile import Compiled


class StepByStep(StepperBase):
    """One step at a time through the integrator and the post-step stages."""

    def __init__(self, compiled: Compiled, numba: bool = False):
        super().__init__(compiled, numba)

    def advance(self, state: State, k: int, goal: int, max_steps: int | None = None) -> tuple[int, Any, bool]:
        clock = self.clock
        stop = goal if max_steps is None else min(goal, k + max_steps)
        if self.stages or not clock.divides:
            book = self._book
            while k < stop:
                self._one(state, clock.step_size(k), clock.time(k + 1))
                k += 1
                state.step = k
                if book is not None:
                    book(state)
            return k, None, False
        # The fast path of a tiny scene, where Python's per-call costs are the
        # step: no stages, every step dt, and the clock's times
        # (duration * i / steps, exactly as Clock.time) computed inline.
        step = self.compiled.integrator.step
        dt, duration, steps = clock.dt, clock.duration, clock.steps
        while k < stop:
            step(state, dt)
            k += 1
            state.time = duration * k / steps if k < steps else duration
        state.step = k
        return k, None, False
