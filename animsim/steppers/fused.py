"""The numba backend's stepper: many fused steps per compiled call, the watchdog's checks
inside them on small scenes."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.guard import Guard
from animsim.steppers.base import NumbaDynamics, StepperBase
from animsim.system import State

if TYPE_CHECKING:  # types only: the fused backend imports compile
    from animsim.backends.fused import FusedStepper
    from animsim.compile import Compiled

#: particles up to which the numba backend's fused chunks run the watchdog's checks
#: themselves instead of returning to Python every CHECK_STRIDE steps. Measured (CPU, one
#: thread, gravity only, symplectic Euler): a Python check costs 10-15 us on one or two
#: particles and a return from the chunk about 8 us, against 2-3 us for a stride's steps;
#: at 256 particles the check is 47 % of a stride's steps, at 4,096 12 % and falling
CHECKS_INSIDE_UP_TO = 4096
#: record positions one call of the checked chunks may pass, copying the states there for
#: their frames (a call costs about 15 us; a tiny scene's frame every 100 steps paid one each)
SHOTS_PER_CALL = 32
#: rows of those copies at most (so a scene of thousands of particles passes fewer)
SHOT_ROWS = 65_536
#: steps one call of the checked chunks takes at most, so stop and progress are served often
#: (65,536 steps of a one-particle scene take about 10 ms)
STEPS_PER_CHECKED_CALL = 65_536


class Fused(StepperBase):
    """The numba backend's fused chunks (:class:`animsim.backends.fused.FusedStepper`).

    Stages without a numba kernel that may run between fused steps (births,
    ``fused_between_steps``) are called from Python after every step: the chunks are
    then one step long, still one numba call for the forces, the integrator and the
    collisions (and an emitter's step is one more compiled call of its own where its
    forces and colliders allow, :meth:`animsim.emitters.Emitters.use_numba`)."""

    def __init__(self, compiled: Compiled):
        super().__init__(compiled, numba=True)
        clock = compiled.clock
        self.times = clock.times()
        self.dts = clock.step_sizes()
        self.fused: FusedStepper | None = None
        self.between = tuple(st for st in self.stages if st.numba_stage_source is None)
        n = compiled.system.particle_count
        #: record positions one advance_checked may pass (their states copied for the frames)
        self.shots_per_call = max(1, min(SHOTS_PER_CALL, SHOT_ROWS // max(n, 1)))
        self._shots: tuple[np.ndarray, np.ndarray] | None = None

    def prepare(self, state: State, notice: Callable[[str], None] | None) -> float:
        import time

        t0 = time.perf_counter()
        from animsim.backends.fused import FusedStepper

        self.fused = FusedStepper(self.compiled)
        # the same watchdog rhythm as step by step, so both backends report the same failures
        self.check_stride = self._watch_stride()
        emitters = self.compiled.emitters
        if emitters is not None:  # newborns fly on with the numba force sum, as step by step
            from animsim.backends.numba_forces import NumbaForces

            dyn = self.compiled.dynamics
            forces = NumbaForces(dyn)
            emitters.dynamics = NumbaDynamics(dyn, forces)
            emitters.use_numba(state)  # births and deaths in compiled calls (the same slots)
            forces.acceleration(
                state.particle_position,
                state.particle_velocity,
                state.time,
                np.zeros_like(state.particle_position),
            )  # compile or load
            dyn.evaluations -= 1
        self.fused.warm_up(state)
        self.fused.reset()
        return time.perf_counter() - t0

    @property
    def _ready(self) -> FusedStepper:
        """The fused stepper ``prepare`` built (every call but ``forget`` comes after it)."""
        assert self.fused is not None
        return self.fused

    def forget(self) -> None:
        if self.fused is not None:
            self.fused.reset()

    def check_inside(self, guard: Guard) -> bool:
        """Run the watchdog's checks inside the fused chunks when that saves the calls back
        to Python they cost (up to CHECKS_INSIDE_UP_TO particles) and the compiled checks
        decide as ``guard`` does: its own ``check`` (not a subclass's), no stage between the
        chunks, a replayable run, and a compiled energy sum for every element the watchdog sums
        (:meth:`animsim.backends.fused.FusedStepper.check_inside`)."""
        return (
            type(guard).check is Guard.check
            and not self.between
            and self.replayable
            and self.compiled.system.particle_count <= CHECKS_INSIDE_UP_TO
            and self._ready.check_inside(guard.watch)
        )

    def quick_check(self, guard: Guard) -> Callable[[State], bool] | None:
        """A compiled stand-in for ``guard``'s checks that stay in Python
        (:meth:`animsim.backends.fused.FusedStepper.quick_check`)."""
        return self._ready.quick_check(guard.watch)

    def advance_checked(
        self, state: State, k: int, goal: int, checked: int, stride: int, rec: np.ndarray
    ) -> tuple[int, int, bool, list[tuple[int, np.ndarray, np.ndarray]]]:
        stopped = False
        copied = 0
        if self._shots is None:
            n = self.compiled.system.particle_count
            self._shots = (np.zeros((self.shots_per_call, n, 3)), np.zeros((self.shots_per_call, n, 3)))
        xs, vs = self._shots
        while k < goal and not stopped:
            end = min(goal, k + self._ready.max_steps_per_call, k + STEPS_PER_CHECKED_CALL)
            taken, evals, checked, stopped, got = self._ready.advance_checked(
                state,
                k,
                self.times[k : end + 1],
                self.dts[k:end],
                checked,
                stride,
                self.end,
                rec[copied:],
                (xs[copied:], vs[copied:]),
            )
            copied += got
            self.compiled.dynamics.evaluations += evals
            k += taken
            state.step = k
            state.time = self.clock.time(k)
        self._good_step = checked
        shots = [(int(rec[i]), xs[i], vs[i]) for i in range(copied) if rec[i] < k]
        return k, checked, stopped, shots

    def good_state(self, dest: State) -> None:
        self._ready.good_state(dest)
        dest.step = self._good_step
        dest.time = self.clock.time(self._good_step)

    def advance(self, state: State, k: int, goal: int, max_steps: int | None = None) -> tuple[int, Any, bool]:
        stop = goal if max_steps is None else min(goal, k + max_steps)
        failed = False
        if self.between:
            return self._advance_between(state, k, stop)
        while k < stop and not failed:
            end = min(stop, k + self._ready.max_steps_per_call)
            taken, evals, failed = self._ready.advance(state, self.times[k:end], self.dts[k:end])
            self.compiled.dynamics.evaluations += evals
            k += taken
            state.step = k
            state.time = self.clock.time(k)
        return k, None, failed

    def _advance_between(self, state: State, k: int, stop: int) -> tuple[int, Any, bool]:
        """One fused step at a time, each followed by the stages called from Python (as _one)
        and, when the stepper books them (books_inside), the newborns' energy books."""
        failed = False
        threaded = self._ready.threaded()  # asked once for the stretch, not at every step
        while k < stop and not failed:
            t0 = state.time
            taken, evals, failed = self._ready.advance(
                state, self.times[k : k + 1], self.dts[k : k + 1], threaded
            )
            self.compiled.dynamics.evaluations += evals
            dt = self.dts[k]
            k += taken
            state.step = k
            t1 = self.clock.time(k)
            revision = state.revision
            for stage in self.between:
                if stage.apply(state, self._x_old, self._v_old, t0, t1, dt):
                    state.revision += 1
            if state.revision != revision:
                self._ready.reset()  # Verlet's force is stale after births and deaths
            state.time = t1
            if self._book is not None:
                self._book(state)
        return k, None, failed
