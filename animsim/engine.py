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
from animsim.measures.watchdog import WatchBooks
from animsim.record import FrameSink
from animsim.run_frames import Held, arrays_frame, emit, emit_arrays, flush, frame_copy
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
    guard = guard or Guard(compiled, dt=stepper.largest_dt)
    resume_collector()  # start-up is over (animsim.startup): collect as usual from here
    dyn.evaluations = 0

    # The first poll says the loop has begun: a stop asked for before it (loading, compiling the
    # scene or its numba kernels) unwinds at once and writes nothing; from here on it finishes
    # the step and keeps the frames (the CLI's handler tells the two apart by this poll).
    if stop is not None:
        stop()
    for sink in sinks:
        sink.begin(compiled.header)
    try:
        frames = next_rec = 0
        if compiled.record_steps[0] == 0:
            emit(compiled, state, sinks, observers)
            frames = next_rec = 1
        # Overflow on the way to a blow-up is the watchdog's to report, not numpy's.
        with np.errstate(over="ignore", invalid="ignore"):
            energy_start = _energy(dyn, state)
            guard.start(state)
        t_start = _time.perf_counter()
        loop = _Loop.begin(compiled, stepper, guard, state, sinks, observers, frames, next_rec)
        with np.errstate(over="ignore", invalid="ignore"):
            while loop.k < loop.steps:
                if not loop.stretch(stop, progress):
                    break
        wall = _time.perf_counter() - t_start
        with np.errstate(over="ignore", invalid="ignore"):
            energy_end = _energy(dyn, state)
        meta = _meta(compiled, loop.status, state, wall, energy_start, energy_end, loop.frames, loop.failure)
        _run_facts(meta, compiled, stepper, compile_seconds, meta_extra)
        _writing(stop)
        return finish(
            sinks, state, dyn, loop.status, wall, energy_start, energy_end, loop.frames, loop.failure, meta
        )
    except BaseException:
        for sink in sinks:
            sink.abort()
        raise


def _energy(dyn: Dynamics, state: State) -> float:
    return dyn.energy(
        state.particle_position,
        state.particle_velocity,
        state.body_orientation,
        state.body_angular_velocity,
    )


def _run_facts(
    meta: dict[str, Any],
    compiled: Compiled,
    stepper: Stepper,
    compile_seconds: float,
    meta_extra: dict[str, Any] | None,
) -> None:
    """Add to ``meta`` what the backend, the stepper, the caller and the stages say of the run."""
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


@dataclass
class _Loop:
    """What the loop keeps from one stretch of steps to the next.

    The watchdog runs every ``stride`` steps, at the end, and when a stepper
    reports a non-finite state. Frames recorded in between wait (copied, a
    bounded number) until a check has passed, so no unverified frame
    reaches a sink; a failure is traced back to its first step by replaying
    from the last good check, one step at a time.
    """

    compiled: Compiled
    stepper: Stepper
    guard: Guard
    state: State
    sinks: Sequence[FrameSink]
    observers: Sequence[Callable[[State], None]]
    steps: int  # the clock's
    stride: int
    replayable: bool
    births: bool  # the run has emitters: the watchdog books every newborn at its birth step
    booked: bool  # the stepper books them itself, after each step
    one: int | None  # 1: advance one step at a time (to book newborns or check every step)
    inside: bool  # the stepper runs the checks itself
    last_good: State | None  # a copy of a checked state kept for a replay
    books: _Books | None  # what a replay restores with it
    passed_step: int  # the step of the last state that passed a check
    frames: int  # frames handed to the sinks so far
    next_rec: int  # the position in record_steps of the next frame to record
    pending: list[Held] = field(default_factory=list)
    k: int = 0  # position on the nominal clock (== steps taken, except with adaptive steps)
    checked: int = 0  # the position of the last check
    failure: Failure | None = None
    status: str = STATUS_OK

    @classmethod
    def begin(
        cls,
        compiled: Compiled,
        stepper: Stepper,
        guard: Guard,
        state: State,
        sinks: Sequence[FrameSink],
        observers: Sequence[Callable[[State], None]],
        frames: int,
        next_rec: int,
    ) -> _Loop:
        """The loop's start, ``frames`` recorded already."""
        replayable = stepper.replayable
        last_good = state.copy() if replayable else None
        books = _snapshot(compiled, guard) if replayable else None
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
        return cls(
            compiled,
            stepper,
            guard,
            state,
            sinks,
            observers,
            steps=compiled.clock.steps,
            stride=stepper.check_stride,
            replayable=replayable,
            births=births,
            booked=booked,
            one=one,
            inside=inside,
            last_good=last_good,
            books=books,
            passed_step=state.step,
            frames=frames,
            next_rec=next_rec,
        )

    def stretch(self, stop: Callable[[], bool] | None, progress: Callable[[int, int], None] | None) -> bool:
        """Advance to the next record step or check, then check, record, poll ``stop`` and
        report ``progress``; False when the run ends here (a failure, or a stop)."""
        goal = self.aim()
        verified = False  # the stepper checked the state at k and it passed
        if self.inside:
            nonfinite, verified = self.advance_checked(goal)
        else:
            goal = min(goal, self.checked + self.stride)
            self.k, self.failure, nonfinite = self.stepper.advance(
                self.state, self.k, goal, max_steps=self.one
            )
        if self.births and not self.booked:
            self.guard.book(self.state)
        if self.failure is not None:  # the stepper itself gave up (adaptive: below dt_min)
            return self.end(STATUS_UNSTABLE)
        record = self.compiled.record_steps
        recording = self.next_rec < len(record) and record[self.next_rec] == self.k
        if recording:
            self.next_rec += 1
        interrupted = stop is not None and stop()
        check_now = not verified and (
            self.k - self.checked >= self.stride
            or not self.replayable
            or self.k == self.steps
            or nonfinite
            or interrupted
            or len(self.pending) >= MAX_PENDING_FRAMES
        )
        if verified and recording:
            self.record_frame()
        if recording and not check_now and not verified:
            self.hold()
        if check_now and not self.check(recording):
            return False
        if progress is not None:
            progress(self.k, self.steps)
        if interrupted:
            return self.end(STATUS_INTERRUPTED)
        return True

    def aim(self) -> int:
        """The next record step ahead of the clock (the last step when none is left)."""
        record = self.compiled.record_steps
        while self.next_rec < len(record) and record[self.next_rec] <= self.k:  # never aim behind us
            self.next_rec += 1
        return int(record[self.next_rec]) if self.next_rec < len(record) else self.steps

    def advance_checked(self, goal: int) -> tuple[bool, bool]:
        """Advance with the stepper running the checks (and copying the states at the record
        positions on the way): (non-finite state met, the state at k checked and passed)."""
        stepper = self.stepper
        assert isinstance(stepper, Fused)  # only the fused chunks run the checks inside
        # Several frames a call: the stepper copies the states at the record
        # positions before the goal (observers read whole states: one a call).
        record = self.compiled.record_steps
        ahead = min(self.next_rec + (1 if self.observers else stepper.shots_per_call), len(record))
        if ahead > self.next_rec:
            goal = int(record[ahead - 1])
        rec = record[self.next_rec : ahead - 1] if ahead > self.next_rec else record[:0]
        self.k, passed, nonfinite, shots = stepper.advance_checked(
            self.state, self.k, goal, self.checked, self.stride, rec
        )
        verified = False
        if passed > self.checked:  # as the check at `passed` would have: frames out, good state
            self.frames += flush(self.pending, self.sinks, self.observers, None)
            self.checked = passed
            verified = passed == self.k
            if self.last_good is not None:
                stepper.good_state(self.last_good)
                self.books = _snapshot(self.compiled, self.guard)
                self.passed_step = self.last_good.step
        for at, x_at, v_at in shots:  # frames passed on the way, in order
            self.next_rec += 1
            if at <= self.checked:
                self.frames += emit_arrays(self.compiled, at, x_at, v_at, self.sinks)
            else:  # to wait for the next check, as a frame between checks does
                self.pending.append((at, arrays_frame(self.compiled, at, x_at.copy(), v_at.copy()), None))
        return nonfinite, verified

    def check(self, recording: bool) -> bool:
        """The watchdog's check of the state now (a failure traced back to its first step),
        the held frames handed on; False when the run fails here."""
        state = self.state
        failure = self.guard.check(state)
        if failure is not None and self.last_good is not None and state.step - self.passed_step > 1:
            assert self.books is not None  # kept with last_good (replayable runs)
            failure = _first_failure(
                state,
                self.last_good,
                self.books,
                failure,
                self.stepper,
                self.guard,
                self.compiled.dynamics,
                self.passed_step,
                self.booked,
            )
        self.failure = failure
        self.frames += flush(self.pending, self.sinks, self.observers, failure)
        self.checked = self.k
        if failure is not None:
            self.status = STATUS_UNSTABLE
            return False
        self.passed_step = state.step
        if recording:
            self.record_frame()
        if self.last_good is not None and state.step - self.last_good.step >= REPLAY_COPY_EVERY:
            self.last_good.assign(state)
            self.books = _snapshot(self.compiled, self.guard)
        return True

    def record_frame(self) -> None:
        """Record the state now (it passed a check)."""
        emit(self.compiled, self.state, self.sinks, self.observers)
        self.frames += 1

    def hold(self) -> None:
        """Keep a copy of the state now until the next check."""
        state = self.state
        self.pending.append(
            (
                state.step,
                frame_copy(self.compiled, state) if self.sinks else None,
                state.copy() if self.observers else None,
            )
        )

    def end(self, status: str) -> bool:
        """End the run with ``status``, the held frames handed on; False."""
        self.status = status
        self.frames += flush(self.pending, self.sinks, self.observers, None)
        return False


#: what a replay restores besides the state: the watchdog's books (Guard.snapshot) and each
#: replayed stage with its own bookkeeping (whatever that stage's snapshot returns)
_Books = tuple[WatchBooks | None, list[tuple[StepStage, object]]]


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
