"""What every stepper shares: the clock, the watchdog's rhythm, the post-step stages after
one integrator step, and (numba backend) the elements' kernels in place of the NumPy force sum.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.backends import block_stage
from animsim.guard import Guard
from animsim.system import State

if TYPE_CHECKING:  # types only: compile imports this package's neighbours
    from animsim.compile import Compiled

#: steps between watchdog checks on the NumPy path (a check costs about a step of a small scene)
CHECK_STRIDE = 16


class StepperBase:
    """The clock, the watchdog's rhythm and one step's stages, shared by every stepper."""

    def __init__(self, compiled: Compiled, numba: bool = False):
        self.compiled = compiled
        self.clock = compiled.clock
        self.end = compiled.clock.steps
        self.largest_dt = compiled.clock.dt
        self.numba = numba
        self.stages = compiled.post_step
        # A stage that draws random numbers (births) can be replayed when it snapshots its
        # streams (``snapshot``/``restore``, restored with the state); else such runs are
        # checked at every step instead of replayed.
        self.replayable = all(not st.random or st.replays for st in compiled.post_step)
        n = compiled.system.particle_count
        self.check_stride = self._watch_stride()
        self._x_old = np.empty((n, 3))
        self._v_old = np.empty((n, 3))
        #: the one post-step stage, when it meets the rows a block at a time inside the
        #: integrator's step (:func:`block_stage`)
        self._block_stage = None if numba else block_stage(compiled)

    def _watch_stride(self) -> int:
        """Steps between two watchdog checks: CHECK_STRIDE, or 1 for a run that cannot be
        replayed. Not sparser for small scenes: the watchdog judges energy at its checks, and
        a run whose energy spikes between two far-apart checks and falls back would pass unseen."""
        return CHECK_STRIDE if self.replayable else 1

    def prepare(self, state: State, notice: Callable[[str], None] | None) -> float:
        self.forget()
        if not self.numba:
            return 0.0
        return compile_numba(self, state, notice)

    def forget(self) -> None:
        self.compiled.integrator.reset()

    def position(self, state: State) -> int:
        return state.step

    def check_inside(self, guard: Guard) -> bool:
        return False

    #: the watchdog's booking of newborns after every step, when the stepper books them
    _book: Callable[[State], None] | None = None

    def books_inside(self, guard: Guard) -> bool:
        """Book the newborns at every step here (``guard.book`` after its stages), for a
        replayable run: the loop then advances a run with births a stride at a time, not a
        step (its Python between two steps was about 40 us of a 100,000-slot fountain's
        step on numba). A run that cannot be replayed is checked at every step anyway."""
        if not self.replayable:
            return False
        self._book = guard.book
        return True

    def quick_check(self, guard: Guard) -> Callable[[State], bool] | None:
        return None

    def summary(self) -> dict[str, Any]:
        return {}

    def _one(self, state: State, dt: float, t1: float) -> None:
        """One integrator step of dt ending at t1, then the post-step stages."""
        t0 = state.time
        if self._block_stage is not None and self.compiled.integrator.dynamics.blocks:
            # the only stage meets each block of rows inside the integrator's step, while the
            # block is in cache (the same values: each row meets it by itself)
            session = self._block_stage.block_session(state, dt)
            # a block stage exists only for integrators with block_stages (symplectic Euler),
            # whose step takes the stage's session
            self.compiled.integrator.step(state, dt, session)  # type: ignore[call-arg]
            if session.finish():
                state.revision += 1
            state.time = t1
            return
        if self.stages:
            np.copyto(self._x_old, state.particle_position)
            np.copyto(self._v_old, state.particle_velocity)
        self.compiled.integrator.step(state, dt)
        for stage in self.stages:
            if stage.apply(state, self._x_old, self._v_old, t0, t1, dt):
                state.revision += 1
        state.time = t1


def compile_numba(stepper: Any, state: State, notice: Callable[[str], None] | None) -> float:
    """Swap the NumPy force sum for the numba kernels' and compile them (on a throwaway state)."""
    import time

    t0 = time.perf_counter()
    from animsim.backends.numba_forces import NumbaForces

    integ = stepper.compiled.integrator
    dyn = stepper.compiled.dynamics
    if not hasattr(stepper, "forces"):
        stepper.forces = NumbaForces(dyn)
    # Integrators evaluate forces only through dynamics.acceleration: point it at the kernels.
    integ.dynamics = NumbaDynamics(dyn, stepper.forces)
    emitters = stepper.compiled.emitters
    if emitters is not None:  # newborns fly on with the same force sum (a full evaluation a step)
        emitters.dynamics = integ.dynamics
        emitters.use_numba(state)  # births and deaths in compiled calls (the same slots)
    scratch = np.zeros_like(state.particle_position)
    stepper.forces.acceleration(state.particle_position, state.particle_velocity, state.time, scratch)
    dyn.evaluations -= 1
    return time.perf_counter() - t0


class NumbaDynamics:
    """A Dynamics whose acceleration runs the elements' numba kernels (everything else delegated)."""

    #: never the NumPy force terms a block at a time: every evaluation goes to the kernels
    blocks = False

    def __init__(self, dynamics: Any, forces: Any):
        self._dynamics = dynamics
        self.acceleration = forces.acceleration
        self.forces = forces  # the kernels' tables (an emitter's compiled birth step)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._dynamics, name)
