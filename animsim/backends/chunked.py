"""The simulation loop for a compiled-backend stepper: many steps per call.

The same table of contents as :func:`animsim.simulate.run` (step, collide,
guard, record), with the step and the collisions fused inside the stepper:
the loop calls it once per stretch of steps between recorded frames (or
between polls of ``stop``), and the stepper stops by itself at the first
step whose state is not finite, so the Guard reports the same step as the
NumPy loop would. A guard with more than the finiteness test (issue 5's
watchdog) sees the state at the end of each stretch.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from animsim.record import FrameSink


def run_chunked(
    compiled: Any,
    sinks: Sequence[FrameSink],
    *,
    stop: Callable[[], bool] | None,
    progress: Callable[[int, int], None] | None,
    guard: Any,
    meta_extra: dict[str, Any] | None,
) -> Any:
    from animsim.simulate import STATUS_INTERRUPTED, STATUS_OK, STATUS_UNSTABLE, _emit, _meta, finish

    state = compiled.fresh_state()
    dyn = compiled.dynamics
    stepper = compiled.stepper
    stepper.reset()
    clock = compiled.clock
    steps = clock.steps
    # Without sinks nothing is recorded, so nothing needs the loop between steps.
    record = compiled.record_steps if sinks else np.array([0, steps], dtype=np.int64)
    dyn.evaluations = 0
    for sink in sinks:
        sink.begin(compiled.header)
    try:
        frames = 0
        next_rec = 0
        if sinks and record[0] == 0:
            _emit(compiled, state, sinks)
            frames += 1
        while next_rec < len(record) and record[next_rec] <= 0:
            next_rec += 1
        energy_start = dyn.energy(state.particle_position, state.particle_velocity)
        failure = None
        status = STATUS_OK
        t_start = _time.perf_counter()
        # A short last step (dt does not divide the duration) gets a call of its own.
        regular_end = steps if clock.divides else steps - 1
        while state.step < steps:
            target = int(record[next_rec]) if next_rec < len(record) else steps
            i = state.step
            if i < regular_end:
                count, dt = min(target, regular_end) - i, clock.dt
            else:
                count, dt = 1, clock.step_size(i)
            count = min(count, stepper.max_steps_per_call)
            taken, evals, failed = stepper.advance(state, count, dt, clock)
            dyn.evaluations += evals
            state.step = i + taken
            state.time = clock.time(state.step)
            failure = guard.check(state)
            if failed and failure is None:  # a guard that does not test finiteness itself
                from animsim.simulate import Guard

                failure = Guard(compiled).check(state)
            if failure is not None:
                status = STATUS_UNSTABLE
                break
            if next_rec < len(record) and record[next_rec] == state.step:
                if sinks:
                    _emit(compiled, state, sinks)
                    frames += 1
                next_rec += 1
            if progress is not None:
                progress(state.step, steps)
            if stop is not None and stop():
                status = STATUS_INTERRUPTED
                break
        wall = _time.perf_counter() - t_start
        energy_end = dyn.energy(state.particle_position, state.particle_velocity)
        meta = _meta(compiled, status, state, wall, energy_start, energy_end, frames, failure)
        meta["backend"] = compiled.backend
        meta.update(meta_extra or {})
        from animsim.analysis.drift import annotate

        annotate(meta, compiled)  # energy drift as a verdict of its own, in the metadata
        return finish(sinks, state, dyn, status, wall, energy_start, energy_end, frames, failure, meta)
    except BaseException:
        for sink in sinks:
            sink.abort()
        raise
