"""The frames a run hands to its sinks and observers (animsim.engine's loop).

A frame of the live state goes out once the watchdog has passed it (:func:`emit`);
a frame recorded between two checks is held as a copy (:func:`frame_copy`) and
handed on when the next check passes (:func:`flush`); a stepper that runs the
checks itself copies positions and velocities on its way (:func:`arrays_frame`,
:func:`emit_arrays`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from animsim.compile import Compiled
from animsim.guard import Failure
from animsim.record import Frame, FrameSink
from animsim.system import State

#: a frame held until a check passes: (its step, the frame for the sinks, the state for the observers)
Held = tuple[int, Frame | None, State | None]


def flush(
    pending: list[Held],
    sinks: Sequence[FrameSink],
    observers: Sequence[Callable[[State], None]],
    failure: Failure | None,
) -> int:
    """Hand the held frames before ``failure``'s step (all, without one) to the sinks; how many."""
    count = 0
    for step, frame, seen in pending:
        if failure is None or step < failure.step:
            if seen is not None:
                for observe in observers:
                    observe(seen)
            if frame is not None:
                for sink in sinks:
                    sink.write(frame)
            count += 1
    pending.clear()
    return count


def emit(
    compiled: Compiled,
    state: State,
    sinks: Sequence[FrameSink],
    observers: Sequence[Callable[[State], None]] = (),
) -> None:
    for observe in observers:
        observe(state)
    if not sinks:
        return
    if compiled.emitters is None:
        frame = Frame(
            step=state.step,
            time=state.time,
            index=_all_index(compiled),
            position=state.particle_position,
            velocity=state.particle_velocity,
            spring_intact=state.spring_intact,
        )
    else:
        frame = compiled.emitters.frame(compiled, state)
        if state.spring_intact is not None:
            import dataclasses

            frame = dataclasses.replace(frame, spring_intact=state.spring_intact)
    frame = _with_bodies(frame, state, copy=False)
    for sink in sinks:
        sink.write(frame)


def emit_arrays(
    compiled: Compiled, step: int, x: np.ndarray, v: np.ndarray, sinks: Sequence[FrameSink]
) -> int:
    """Write the frame of a copied state that passed a check (as emit); 1, the frame count."""
    if sinks:
        frame = arrays_frame(compiled, step, x, v)
        for sink in sinks:
            sink.write(frame)
    return 1


def frame_copy(compiled: Compiled, state: State) -> Frame:
    """A frame that owns its arrays, held until a check passes."""
    if compiled.emitters is not None:
        # the alive rows, gathered (so copies); ids are given in recording order, as emit does
        frame = compiled.emitters.frame(compiled, state)
        if state.spring_intact is not None:
            import dataclasses

            frame = dataclasses.replace(frame, spring_intact=state.spring_intact.copy())
        return _with_bodies(frame, state, copy=True)
    return _with_bodies(
        Frame(
            step=state.step,
            time=state.time,
            index=_all_index(compiled),
            position=state.particle_position.copy(),
            velocity=state.particle_velocity.copy(),
            spring_intact=None if state.spring_intact is None else state.spring_intact.copy(),
        ),
        state,
        copy=True,
    )


def arrays_frame(compiled: Compiled, step: int, x: np.ndarray, v: np.ndarray) -> Frame:
    """The frame of a state a stepper copied on its way (a run without emitters, bodies or
    tearing springs, whose frames hold positions and velocities only)."""
    return Frame(
        step=step, time=compiled.clock.time(step), index=_all_index(compiled), position=x, velocity=v
    )


def _with_bodies(frame: Frame, state: State, copy: bool) -> Frame:
    """The frame with the bodies' orientations and angular velocities (unchanged without bodies)."""
    if state.body_orientation is None:
        return frame
    import dataclasses

    q, w = state.body_orientation, state.body_angular_velocity
    assert w is not None  # bodies carry both (State)
    return dataclasses.replace(
        frame, orientation=q.copy() if copy else q, angular_velocity=w.copy() if copy else w
    )


def _all_index(compiled: Compiled) -> np.ndarray:
    idx = getattr(compiled, "_all_index", None)
    if idx is None:
        idx = np.arange(compiled.system.particle_count, dtype=np.int64)
        compiled._all_index = idx  # type: ignore[attr-defined]
    return idx
