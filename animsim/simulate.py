"""The simulation loop, readable as a table of contents:

    for each step: integrate, collide, emit/age/kill, guard, record

Everything scene-specific was decided by the compiler; this loop only calls
the stages that exist. Frames stream to the sinks as they are made.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim import __version__
from animsim.compile import Compiled
from animsim.record import Frame, FrameSink
from animsim.system import State

STATUS_OK = "ok"
STATUS_UNSTABLE = "unstable"
STATUS_INTERRUPTED = "interrupted"


@dataclass
class Failure:
    """Where and why a run became unstable."""

    step: int
    time: float
    particle: str | None
    reason: str
    spring: str | None = None
    growth: float | None = None
    suggestion: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if v is not None}

    def describe(self) -> str:
        parts = [f"unstable at step {self.step} (t = {self.time:.6g} s): {self.reason}"]
        if self.particle is not None:
            parts.append(f"particle {self.particle!r}")
        if self.spring is not None:
            parts.append(f"spring {self.spring}")
        text = "; ".join(parts)
        if self.suggestion:
            text += f"\n  fix: {self.suggestion}"
        return text


@dataclass
class RunResult:
    status: str
    steps_taken: int
    wall_time: float  # s, the loop only
    energy_start: float
    energy_end: float
    force_evals: int
    frames: int
    final_state: State
    failure: Failure | None = None
    meta: dict[str, Any] = field(default_factory=dict)


class Guard:
    """Stops a run at the first step whose state is not finite.

    Issue 5's watchdog (energy growth, stable-dt advice) plugs in through
    ``check``: it returns a Failure or None.
    """

    def __init__(self, compiled: Compiled):
        self.compiled = compiled

    def check(self, state: State) -> Failure | None:
        x, v = state.particle_position, state.particle_velocity
        # One reduction each instead of an (N, 3) boolean array: a NaN or inf
        # anywhere makes the sum non-finite.
        if np.isfinite(x.sum()) and np.isfinite(v.sum()):
            return None
        bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        if not bad.any():  # the sum overflowed on huge but finite values
            return None
        i = int(np.flatnonzero(bad)[0])
        return Failure(
            step=state.step,
            time=state.time,
            particle=self.compiled.system.ids[i] if i < len(self.compiled.system.ids) else f"#{i}",
            reason="a position or velocity is not finite",
        )


def run(
    compiled: Compiled,
    sinks: Sequence[FrameSink] = (),
    *,
    stop: Callable[[], bool] | None = None,
    progress: Callable[[int, int], None] | None = None,
    guard: Guard | None = None,
    meta_extra: dict[str, Any] | None = None,
    observers: Sequence[Callable[[State], None]] = (),
) -> RunResult:
    """Simulate ``compiled`` from its initial state, streaming frames to ``sinks``.

    ``observers`` are called with the live state at every recorded frame
    (energy plots read whole states, which frames of alive rows are not).

    ``stop`` is polled at each step boundary (Ctrl-C handling sets it); the
    frames so far are kept and the status is ``interrupted``.
    """
    state = compiled.fresh_state()
    dyn = compiled.dynamics
    integ = compiled.integrator
    integ.reset()
    if compiled.emitters is not None:
        compiled.emitters.reset(compiled.system, state)
    colliders = compiled.colliders
    emitters = compiled.emitters
    clock = compiled.clock
    guard = guard or Guard(compiled)
    record = compiled.record_steps
    next_rec = 0
    dyn.evaluations = 0

    x_old = np.empty_like(state.particle_position) if colliders else None
    v_old = np.empty_like(state.particle_velocity) if colliders else None

    for sink in sinks:
        sink.begin(compiled.header)
    try:
        frames = 0
        if record[0] == 0:
            _emit(compiled, state, sinks, observers)
            frames += 1
            next_rec = 1
        energy_start = dyn.energy(state.particle_position, state.particle_velocity)
        failure: Failure | None = None
        status = STATUS_OK
        t_start = _time.perf_counter()
        steps = clock.steps
        for i in range(steps):
            dt = clock.step_size(i)
            if colliders is not None:
                np.copyto(x_old, state.particle_position)
                np.copyto(v_old, state.particle_velocity)
            integ.step(state, dt)
            if colliders is not None and colliders.apply(
                x_old, v_old, state.particle_position, state.particle_velocity, dt
            ):
                state.revision += 1
            t_end = clock.time(i + 1)
            if emitters is not None:
                emitters.advance(compiled, state, state.time, t_end)
            state.step = i + 1
            state.time = t_end
            failure = guard.check(state)
            if failure is not None:
                status = STATUS_UNSTABLE
                break
            if next_rec < len(record) and record[next_rec] == state.step:
                _emit(compiled, state, sinks, observers)
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
        meta.update(meta_extra or {})
        if emitters is not None:
            meta["emitters"] = emitters.summary()
        for sink in sinks:
            sink.close(meta)
    except BaseException:
        for sink in sinks:
            sink.abort()
        raise
    return RunResult(
        status=status,
        steps_taken=state.step,
        wall_time=wall,
        energy_start=energy_start,
        energy_end=energy_end,
        force_evals=dyn.evaluations,
        frames=frames,
        final_state=state,
        failure=failure,
        meta=meta,
    )


def _emit(
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
        )
    else:
        frame = compiled.emitters.frame(compiled, state)
    for sink in sinks:
        sink.write(frame)


def _all_index(compiled: Compiled) -> np.ndarray:
    idx = getattr(compiled, "_all_index", None)
    if idx is None:
        idx = np.arange(compiled.system.particle_count, dtype=np.int64)
        compiled._all_index = idx  # type: ignore[attr-defined]
    return idx


def _meta(
    compiled: Compiled,
    status: str,
    state: State,
    wall: float,
    e0: float,
    e1: float,
    frames: int,
    failure: Failure | None,
) -> dict[str, Any]:
    meta: dict[str, Any] = {
        "tool": "animsim",
        "version": __version__,
        "scene": compiled.name,
        "seed": compiled.seed,
        "integrator": compiled.integrator_name,
        "dt": compiled.clock.dt,
        "duration": compiled.clock.duration,
        "steps": compiled.clock.steps,
        "steps_taken": state.step,
        "frames": frames,
        "particles": compiled.system.particle_count,
        "springs": compiled.system.spring_count,
        "force_evaluations": compiled.dynamics.evaluations,
        "energy_start": e0,
        "energy_end": e1,
        "wall_time": wall,
        "status": status,
    }
    if failure is not None:
        meta["failure"] = failure.as_dict()
    return meta
