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
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.backends import block_stage, fused_unsupported
from animsim.guard import Failure, Guard
from animsim.measures.stability import particle_name
from animsim.system import State

if TYPE_CHECKING:  # types only: compile and the fused backend import this module's neighbours
    from animsim.backends.fused import FusedStepper
    from animsim.compile import Compiled

#: a doubled step has about DOUBLING_BASE^(p+1) times the local error of the two halves
DOUBLING_BASE = 2.0
#: a step this close (relative) to the distance left lands on the record time, so
#: rounding in the accumulated time never leaves a sliver of a step behind
LANDING_SLACK = 1e-6
#: a rest shorter than dt_min by up to this fraction of dt_min counts as a sliver too, so
#: rounding in the accumulated time cannot turn a rest of exactly dt_min into a step below it
SLIVER_SLACK = 1e-3
#: steps between watchdog checks on the NumPy path (a check costs about a step of a small scene)
CHECK_STRIDE = 16
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
#: seconds of compiling after which the person waiting is told why
COMPILE_NOTICE_SECONDS = 0.5


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


class _Base:
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
        # Not sparser for small scenes: the watchdog judges energy at its checks, and a run
        # whose energy spikes between two far-apart checks and falls back would pass unseen.
        self.check_stride = CHECK_STRIDE if self.replayable else 1
        self._x_old = np.empty((n, 3))
        self._v_old = np.empty((n, 3))
        #: the one post-step stage, when it meets the rows a block at a time inside the
        #: integrator's step (:func:`block_stage`)
        self._block_stage = None if numba else block_stage(compiled)

    def prepare(self, state: State, notice: Callable[[str], None] | None) -> float:
        self.forget()
        if not self.numba:
            return 0.0
        return _compile_numba(self, state, notice)

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


def _compile_numba(stepper: Any, state: State, notice: Callable[[str], None] | None) -> float:
    """Swap the NumPy force sum for the numba kernels' and compile them (on a throwaway state)."""
    import time

    t0 = time.perf_counter()
    from animsim.backends.numba_forces import NumbaForces

    integ = stepper.compiled.integrator
    dyn = stepper.compiled.dynamics
    if not hasattr(stepper, "forces"):
        stepper.forces = NumbaForces(dyn)
    # Integrators evaluate forces only through dynamics.acceleration: point it at the kernels.
    integ.dynamics = _NumbaDynamics(dyn, stepper.forces)
    emitters = stepper.compiled.emitters
    if emitters is not None:  # newborns fly on with the same force sum (a full evaluation a step)
        emitters.dynamics = integ.dynamics
        emitters.use_numba(state)  # births and deaths in compiled calls (the same slots)
    scratch = np.zeros_like(state.particle_position)
    stepper.forces.acceleration(state.particle_position, state.particle_velocity, state.time, scratch)
    dyn.evaluations -= 1
    return time.perf_counter() - t0


class _NumbaDynamics:
    """A Dynamics whose acceleration runs the elements' numba kernels (everything else delegated)."""

    #: never the NumPy force terms a block at a time: every evaluation goes to the kernels
    blocks = False

    def __init__(self, dynamics: Any, forces: Any):
        self._dynamics = dynamics
        self.acceleration = forces.acceleration
        self.forces = forces  # the kernels' tables (an emitter's compiled birth step)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._dynamics, name)


class StepByStep(_Base):
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


class Fused(_Base):
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
        self.check_stride = CHECK_STRIDE if self.replayable else 1
        emitters = self.compiled.emitters
        if emitters is not None:  # newborns fly on with the numba force sum, as step by step
            from animsim.backends.numba_forces import NumbaForces

            dyn = self.compiled.dynamics
            forces = NumbaForces(dyn)
            emitters.dynamics = _NumbaDynamics(dyn, forces)
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


class StepDoubling(_Base):
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


#: the steppers the loop drives (make_stepper picks one)
Stepper = StepByStep | Fused | StepDoubling
