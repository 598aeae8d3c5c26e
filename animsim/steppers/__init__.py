"""Steppers: what advances the state between two points of the loop's clock.

The one loop (:func:`animsim.engine.run`) asks a stepper to move the state
from nominal clock position ``k`` to ``goal``; the stepper says where it got
to. Everything else (recording, the watchdog and its replay, stop, progress,
metadata, sinks) is the loop's, so it is the same for every stepper:

* :class:`StepByStep`: one integrator step at a time, then the post-step
  stages (collisions, births). NumPy kernels, or the elements' numba kernels
  (:class:`animsim.backends.numba_forces.NumbaForces`) on the numba backend.
* :class:`Fused`: the numba backend's fused chunks, many steps per call.
* :class:`StepDoubling`: adaptive step size (the course notes' "Adaptive
  Stepsizes"), on either backend's kernels.

The protocol (every stepper):

``largest_dt``
    the longest step it can take (the watchdog's one-step energy slack uses it).
``check_stride``
    the most steps between two watchdog checks it wants (1: every step).
``replayable``
    whether a stretch of steps can be replayed to find a failure's first step.
``end``
    the last clock position.
``prepare(state, notice) -> seconds``
    before the run, untimed: reset caches, compile kernels (numba), saying so
    through ``notice`` when it takes a while.
``advance(state, k, goal, max_steps=None) -> (k, failure, nonfinite)``
    move the state from position k toward ``goal``; stop early after
    ``max_steps`` steps or at a non-finite state. ``failure`` is set only when
    the stepper itself cannot go on (adaptive: below dt_min).
``check_inside(guard) -> bool``
    once, after the watchdog's books opened: whether the stepper runs ``guard``'s checks
    itself (the numba backend's fused chunks on small scenes); then the loop calls
    ``advance_checked`` instead of ``advance`` (a replay still calls ``advance``).
``books_inside(guard) -> bool``
    once, after the watchdog's books opened, for a run with births: whether the stepper
    books the newborns itself (``guard.book`` after every step's stages); then the loop
    need not step the run one step at a time for its books.
``quick_check(guard) -> callable or None``
    once, when the checks stay in Python: a compiled test of a state that is True only
    where ``guard.check`` passes it (numba backend); ``guard.check`` then returns at once.
``advance_checked(state, k, goal, checked, stride, rec) -> (k, passed, stopped, shots)``
    ``advance`` toward ``goal`` that checks the state as the loop would (at every
    ``checked`` + j ``stride`` and at ``end``, deciding as ``guard.check``); ``passed``
    is the position of the last check that passed (``checked`` if none), ``stopped``
    that the state is where a check did not pass or after a non-finite step (the loop
    then checks it in Python and replays from the last passed check). ``rec`` are
    record positions before ``goal`` (at most ``shots_per_call``); ``shots`` lists
    (position, positions, velocities) of the states at those it passed before ``k``
    (views, valid until the next call).
``good_state(dest)``
    assign the state of the last check ``advance_checked`` passed into ``dest``.
``position(state) -> k``
    the clock position of a state this run went through (for the replay).
``forget()``
    drop cached quantities (Verlet's force) after the state was replaced.
``summary() -> dict``
    extra metadata.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from animsim.backends import fused_unsupported
from animsim.steppers.doubling import StepDoubling, next_step
from animsim.steppers.fused import Fused
from animsim.steppers.step_by_step import StepByStep
from animsim.system import State

if TYPE_CHECKING:  # types only: compile imports this package's neighbours
    from animsim.compile import Compiled

__all__ = ["Fused", "StepByStep", "StepDoubling", "Stepper", "make_stepper", "next_step", "start"]


def start(compiled: Compiled, notice: Callable[[str], None] | None = None) -> tuple[State, Stepper, float]:
    """What a run starts from: a fresh state, the elements bound to it and the stages reset,
    and the stepper prepared (numba's kernels compiled or loaded): (state, stepper, seconds
    spent compiling, which are not run time)."""
    state = compiled.fresh_state()
    stepper = make_stepper(compiled)
    compiled.dynamics.bind(state)
    for stage in compiled.post_step:
        stage.reset(state)
    return state, stepper, stepper.prepare(state, notice)


def make_stepper(compiled: Compiled) -> Stepper:
    """The stepper for ``compiled`` on its backend (chosen once, at compile time)."""
    numba = compiled.backend == "numba"
    if compiled.adaptive is not None:
        return StepDoubling(compiled, numba=numba)
    if numba and not fused_unsupported(compiled):
        return Fused(compiled)
    return StepByStep(compiled, numba=numba)


#: the steppers the loop drives (make_stepper picks one)
Stepper = StepByStep | Fused | StepDoubling
