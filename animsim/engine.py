"""The one simulation loop, readable as a table of contents:

    for each stretch of steps: advance (integrate, collide, emit), guard, record

Everything scene-specific was decided by the compiler; which code advances
the state (NumPy step by step, numba fused chunks, adaptive steps) is the
stepper's business (:mod:`animsim.steppers`). Frames stream to the sinks as
they are made.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.backends import numba_threads
from animsim.compile import Compiled
from animsim.compile_notice import compile_notices
from animsim.dynamics import Dynamics
from animsim.elements import StepStage
from animsim.export.meta import run_facts
from animsim.guard import Failure, Guard
from animsim.measures.drift import annotate
from animsim.record import Frame, FrameSink
from animsim.startup import resume_collector
from animsim.steppers import Fused, Stepper, start
from animsim.system import State
from animsim.version import __version__

STATUS_OK = "ok"
STATUS_UNSTABLE = "unstable"
STATUS_INTERRUPTED = "interrupted"


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


#: frames held (copied) at most while waiting for a watchdog check; more forces a check
MAX_PENDING_FRAMES = 64
#: steps at least between two copies of a checked state kept for a replay. A copy costs
#: what copying the state and the stages' bookkeeping costs (about 1.7 ms for a
#: 100,000-slot fountain: a tenth of its stepping when taken at every 16-step check, 3 %
#: every 64 steps, under 1 % every 256); a failure is rare, its replay from an older copy
#: re-runs at most this many steps, and it checks only the steps after the last passing
#: check, so it names the same first failing step
REPLAY_COPY_EVERY = 256


def run(
    compiled: Compiled,
    sinks: Sequence[FrameSink] = (),
    *,
    stop: Callable[[], bool] | None = None,
    progress: Callable[[int, int], None] | None = None,
    guard: Guard | None = None,
    meta_extra: dict[str, Any] | None = None,
    observers: Sequence[Callable[[State], None]] = (),
    notice: Callable[[str], None] | None = None,
) -> RunResult:
    """THE loop: simulate ``compiled`` from its initial state, streaming frames to ``sinks``.

    The stepper (:mod:`animsim.steppers`: NumPy step by step, numba fused
    chunks, or adaptive step doubling) only advances the state; this loop
    owns the clock, recording, the watchdog, stop, progress, metadata and the
    sinks, so every stepper behaves the same.

    ``observers`` are called with the live state at every recorded frame
    (energy plots read whole states, which frames of alive rows are not).
    ``stop`` is polled between stretches of steps (Ctrl-C handling sets it);
    the frames so far are kept and the status is ``interrupted``.
    ``notice`` hears one-line messages meant for a person (numba compiling).

    On the numba backend, ``compiled.threads`` (when set) is numba's thread count for
    the run, and numba's own count is put back after it.
    """
    # every kernel numba compiles for this run (a disk-cache miss) is announced as it starts
    with numba_threads(compiled), compile_notices(notice, numba=compiled.backend == "numba"):
        return _run(
            compiled,
            sinks,
            stop=stop,
            progress=progress,
            guard=guard,
            meta_extra=meta_extra,
            observers=observers,
            notice=notice,
        )


def _run(
    compiled: Compiled,
    sinks: Sequence[FrameSink],
    *,
    stop: Callable[[], bool] | None,
    progress: Callable[[int, int], None] | None,
    guard: Guard | None,
    meta_extra: dict[str, Any] | None,
    observers: Sequence[Callable[[State], None]],
    notice: Callable[[str], None] | None,
) -> RunResult:
    """run's loop (see run)."""
    # Compiling numba kernels (first run on a machine) is not run time.
    state, stepper, compile_seconds = start(compiled, notice)
    dyn = compiled.dynamics
    clock = compiled.clock
    guard = guard or Guard(compiled, dt=stepper.largest_dt)
    resume_collector()  # start-up is over (animsim.startup): collect as usual from here
    record = compiled.record_steps
    next_rec = 0
    dyn.evaluations = 0
    steps = clock.steps

    # The first poll says the loop has begun: a stop asked for before it (loading, compiling the
    # scene or its numba kernels) unwinds at once and writes nothing; from here on it finishes
    # the step and keeps the frames (the CLI's handler tells the two apart by this poll).
    if stop is not None:
        stop()
    for sink in sinks:
        sink.begin(compiled.header)
    try:
        frames = 0
        if record[0] == 0:
            _emit(compiled, state, sinks, observers)
            frames += 1
            next_rec = 1
        # Overflow on the way to a blow-up is the watchdog's to report, not numpy's.
        with np.errstate(over="ignore", invalid="ignore"):
            energy_start = dyn.energy(
                state.particle_position,
                state.particle_velocity,
                state.body_orientation,
                state.body_angular_velocity,
            )
            guard.start(state)
        failure: Failure | None = None
        status = STATUS_OK
        t_start = _time.perf_counter()
        # The watchdog runs every `stride` steps, at the end, and when a stepper
        # reports a non-finite state. Frames recorded in between wait (copied, a
        # bounded number) until a check has passed, so no unverified frame
        # reaches a sink; a failure is traced back to its first step by replaying
        # from the last good check, one step at a time.
        stride = stepper.check_stride
        replayable = stepper.replayable
        last_good = state.copy() if replayable else None
        books = _snapshot(compiled, guard) if replayable else None
        passed_step = state.step  # the step of the last state that passed a check
        # A run that cannot be replayed is checked after every step. The watchdog books every
        # newborn at its birth step (as a check at every step would): the stepper after each
        # step when it can, else the loop, stepping the run one step at a time; the full
        # checks keep the stride, and the emitters' streams are restored with the state for
        # a replay.
        births = state.particle_alive is not None
        booked = births and stepper.books_inside(guard)
        one = 1 if ((births and not booked) or not replayable) else None
        # A stepper may run the checks itself between record steps (the numba backend's
        # fused chunks on small scenes: one call per frame instead of one per stride); its
        # checks are these, at the same steps, deciding as guard.check does.
        inside = stepper.check_inside(guard)
        if not inside:  # the checks stay here: the stepper may pass the clear ones compiled
            guard.quick = stepper.quick_check(guard)
        pending: list[tuple[int, Frame | None, State | None]] = []
        k = 0  # position on the nominal clock (== steps taken, except with adaptive steps)
        checked = 0
        with np.errstate(over="ignore", invalid="ignore"):
            while k < steps:
                while next_rec < len(record) and record[next_rec] <= k:  # never aim behind us
                    next_rec += 1
                goal = int(record[next_rec]) if next_rec < len(record) else steps
                verified = False  # the stepper checked the state at k and it passed
                if inside:
                    assert isinstance(stepper, Fused)  # only the fused chunks run the checks inside
                    # Several frames a call: the stepper copies the states at the record
                    # positions before the goal (observers read whole states: one a call).
                    ahead = min(next_rec + (1 if observers else stepper.shots_per_call), len(record))
                    if ahead > next_rec:
                        goal = int(record[ahead - 1])
                    rec = record[next_rec : ahead - 1] if ahead > next_rec else record[:0]
                    k, passed, nonfinite, shots = stepper.advance_checked(
                        state, k, goal, checked, stride, rec
                    )
                    if passed > checked:  # as the check at `passed` would have: frames out, good state
                        frames += _flush(pending, sinks, observers, None)
                        checked = passed
                        verified = passed == k
                        if last_good is not None:
                            stepper.good_state(last_good)
                            books = _snapshot(compiled, guard)
                            passed_step = last_good.step
                    for at, x_at, v_at in shots:  # frames passed on the way, in order
                        next_rec += 1
                        if at <= checked:
                            frames += _emit_arrays(compiled, at, x_at, v_at, sinks)
                        else:  # to wait for the next check, as a frame between checks does
                            pending.append((at, _arrays_frame(compiled, at, x_at.copy(), v_at.copy()), None))
                else:
                    goal = min(goal, checked + stride)
                    k, failure, nonfinite = stepper.advance(state, k, goal, max_steps=one)
                if births and not booked:
                    guard.book(state)
                if failure is not None:  # the stepper itself gave up (adaptive: below dt_min)
                    status = STATUS_UNSTABLE
                    frames += _flush(pending, sinks, observers, None)
                    break
                recording = next_rec < len(record) and record[next_rec] == k
                if recording:
                    next_rec += 1
                interrupted = stop is not None and stop()
                check_now = not verified and (
                    k - checked >= stride
                    or not replayable
                    or k == steps
                    or nonfinite
                    or interrupted
                    or len(pending) >= MAX_PENDING_FRAMES
                )
                if verified and recording:
                    _emit(compiled, state, sinks, observers)
                    frames += 1
                if recording and not check_now and not verified:
                    pending.append(
                        (
                            state.step,
                            _frame_copy(compiled, state) if sinks else None,
                            state.copy() if observers else None,
                        )
                    )
                if check_now:
                    failure = guard.check(state)
                    if failure is not None and last_good is not None and state.step - passed_step > 1:
                        assert books is not None  # kept with last_good (replayable runs)
                        failure = _first_failure(
                            state, last_good, books, failure, stepper, guard, dyn, passed_step, booked
                        )
                    frames += _flush(pending, sinks, observers, failure)
                    checked = k
                    if failure is not None:
                        status = STATUS_UNSTABLE
                        break
                    passed_step = state.step
                    if recording:
                        _emit(compiled, state, sinks, observers)
                        frames += 1
                    if last_good is not None and state.step - last_good.step >= REPLAY_COPY_EVERY:
                        last_good.assign(state)
                        books = _snapshot(compiled, guard)
                if progress is not None:
                    progress(k, steps)
                if interrupted:
                    status = STATUS_INTERRUPTED
                    frames += _flush(pending, sinks, observers, None)
                    break
        wall = _time.perf_counter() - t_start
        with np.errstate(over="ignore", invalid="ignore"):
            energy_end = dyn.energy(
                state.particle_position,
                state.particle_velocity,
                state.body_orientation,
                state.body_angular_velocity,
            )
        meta = _meta(compiled, status, state, wall, energy_start, energy_end, frames, failure)
        meta["backend"] = compiled.backend
        if compile_seconds:
            meta["compile_time"] = compile_seconds
        meta.update(stepper.summary())
        meta.update(meta_extra or {})
        annotate(meta, compiled)  # energy drift as a verdict of its own, in the metadata
        if compiled.emitters is not None:
            meta["emitters"] = compiled.emitters.summary()
        for stage in compiled.post_step:  # tearing: how many springs broke, and when first
            report = stage.run_summary()
            if report is not None:
                meta.update(report)
        _writing(stop)
        return finish(sinks, state, dyn, status, wall, energy_start, energy_end, frames, failure, meta)
    except BaseException:
        for sink in sinks:
            sink.abort()
        raise


def _flush(
    pending: list[tuple[int, Frame | None, State | None]],
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


#: what a replay restores besides the state: the watchdog's books (Guard.snapshot) and each
#: replayed stage with its own bookkeeping (whatever that stage's snapshot returns)
_Books = tuple[Any, list[tuple[StepStage, Any]]]


def _snapshot(compiled: Compiled, guard: Guard) -> _Books:
    """What a replay restores besides the state: the watchdog's books and the stages' own
    bookkeeping (the emitters' random streams and pools)."""
    stages = [(st, st.snapshot()) for st in compiled.post_step if st.replays]
    return guard.snapshot(), stages


def _restore(books: _Books, guard: Guard) -> None:
    watch, stages = books
    guard.restore(watch)
    for st, snap in stages:
        st.restore(snap)


def _first_failure(
    state: State,
    last_good: State,
    books: _Books,
    failure: Failure,
    stepper: Stepper,
    guard: Guard,
    dyn: Dynamics,
    passed_step: int,
    booked: bool = False,
) -> Failure:
    """Replay from the last state kept for it (a state that passed a check), checking every
    step after ``passed_step`` (the last step whose check passed), so the report names the
    first failing step; ``state`` ends there.

    The replay is the same computation (the emitters' random streams are
    restored with the state, so the same births are drawn again), except that
    Verlet re-evaluates its first force. Its force evaluations are not counted.
    ``booked``: the stepper books the newborns itself (``books_inside``).
    The steps up to ``passed_step`` are not checked again: a check at one of them
    that the run never made could stop a run whose energy swung and came back by
    the next check, which the run had passed.
    """
    failed_at = state.step
    evaluations = dyn.evaluations
    state.assign(last_good)
    _restore(books, guard)
    stepper.forget()
    k = stepper.position(last_good)
    first = failure
    while state.step < failed_at:
        k, _, _ = stepper.advance(state, k, stepper.end, max_steps=1)
        if state.step <= passed_step:
            if state.particle_alive is not None and not booked:
                guard.book(state)  # newborns booked at their birth step, as the run did
            continue
        found = guard.check(state)
        if found is not None:
            first = found
            break
    dyn.evaluations = evaluations
    return first


def _frame_copy(compiled: Compiled, state: State) -> Frame:
    """A frame that owns its arrays, held until a check passes."""
    if compiled.emitters is not None:
        # the alive rows, gathered (so copies); ids are given in recording order, as _emit does
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


def _arrays_frame(compiled: Compiled, step: int, x: np.ndarray, v: np.ndarray) -> Frame:
    """The frame of a state a stepper copied on its way (a run without emitters, bodies or
    tearing springs, whose frames hold positions and velocities only)."""
    return Frame(
        step=step, time=compiled.clock.time(step), index=_all_index(compiled), position=x, velocity=v
    )


def _emit_arrays(
    compiled: Compiled, step: int, x: np.ndarray, v: np.ndarray, sinks: Sequence[FrameSink]
) -> int:
    """Write the frame of a copied state that passed a check (as _emit); 1, the frame count."""
    if sinks:
        frame = _arrays_frame(compiled, step, x, v)
        for sink in sinks:
            sink.write(frame)
    return 1


def _writing(stop: Callable[[], bool] | None) -> None:
    """Tell ``stop`` that the steps are over and the sinks are about to write their files,
    when it listens (a ``writing`` method, as the CLI's flag has): a signal from here on
    cannot stop a step, so the CLI unwinds at once instead, the sinks remove their
    temporary files and nothing is written (docs/limits.md, Signals)."""
    hear = getattr(stop, "writing", None)
    if callable(hear):
        hear()


def finish(
    sinks: Sequence[FrameSink],
    state: State,
    dyn: Dynamics,
    status: str,
    wall: float,
    energy_start: float,
    energy_end: float,
    frames: int,
    failure: Failure | None,
    meta: dict[str, Any],
) -> RunResult:
    """Close the sinks with the run's metadata and say how it went (every backend's last act)."""
    for sink in sinks:
        sink.close(meta)
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
    colliders = len(compiled.scene.colliders or [])
    if colliders:  # a CSV does not carry them: its drawers refuse to leave them out unsaid
        meta["solid_colliders"] = colliders
    if failure is not None:
        meta["failure"] = failure.as_dict()
    meta.update(run_facts(compiled, state))
    return meta
