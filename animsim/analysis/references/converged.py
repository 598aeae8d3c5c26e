"""References from converged runs, for scenes without a closed form: SciPy's
DOP853 at tight tolerances for smooth scenes (:func:`dop853_reference`, and
:func:`dop853_rate`, the pace a plan estimates it from), or RK4 with the step
halved until the change is far below the smallest error measured
(:func:`rk4_reference`); and the runs both need, recorded exactly at the
compared times (:func:`record_at`, :func:`run_trajectory`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from animsim.analysis.references.trajectory import Reference, ReferenceFailed, Trajectory
from animsim.compile import Compiled, compile_scene, with_overrides
from animsim.engine import run
from animsim.errors import SimulationError
from animsim.record import MemorySink
from animsim.scene import models as m

# DOP853 (Hairer, Norsett and Wanner, "Solving ODEs I", II.10) via SciPy.
DOP853_RTOL = 1e-12
#: a second solve at this looser tolerance measures the first one's error
DOP853_CHECK_RTOL = 1e-11

#: the RK4 reference starts at the finest compared dt divided by this ...
FINE_START_DIVISOR = 4
#: ... and is halved until the last change is below this fraction of the
#: smallest error measured ("far below": a thousandth)
FINE_TARGET_RATIO = 1e-3
#: never more steps than this for one reference run, nor more than
#: FINE_MAX_FACTOR times the finest compared run's (a scene with collisions
#: may never converge at fourth order; compare says so instead of running forever)
FINE_MAX_STEPS = 2_000_000
FINE_MAX_FACTOR = 8
#: ... but a short scene may always take this many (they cost little)
FINE_MIN_STEPS = 20_000
#: Richardson's estimate of RK4's error at h/2 from the change between h and h/2
RK4_RICHARDSON = 2**4 - 1


def smooth(compiled: Compiled) -> bool:
    """True when the right-hand side is smooth enough for DOP853 (no stage after the
    step: no collisions, no births) and is all in ``Dynamics.acceleration`` (rigid bodies
    add orientations and torques it does not hold: their reference is a converged RK4 run)."""
    return not compiled.post_step and not compiled.system.body_count


def _dop853_problem(compiled: Compiled) -> tuple[Callable[..., np.ndarray], np.ndarray, float, float]:
    """(rhs, y0, length, speed) of the DOP853 solve: y = (x, v), y' = (v, a(x, v, t))."""
    dyn = compiled.dynamics
    n = compiled.system.particle_count
    x0 = compiled.initial.particle_position
    v0 = compiled.initial.particle_velocity
    acc = np.zeros((n, 3))

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        x = y[: 3 * n].reshape(n, 3)
        v = y[3 * n :].reshape(n, 3)
        dyn.acceleration(x, v, t, acc)
        return np.concatenate([y[3 * n :], acc.ravel()])

    duration = compiled.clock.duration
    length = max(
        float(np.max(np.abs(x0), initial=0.0)), float(np.max(np.abs(v0), initial=0.0)) * duration, 1e-6
    )
    return rhs, np.concatenate([x0.ravel(), v0.ravel()]), length, length / duration


def _dop853_solve(compiled: Compiled, rhs: Callable[..., np.ndarray], times: np.ndarray, rtol: float) -> Any:
    from scipy.integrate import solve_ivp

    _, y0, length, speed = _dop853_problem(compiled)
    n3 = 3 * compiled.system.particle_count
    atol = np.concatenate([np.full(n3, rtol * length), np.full(n3, rtol * speed)])
    return solve_ivp(
        rhs, (0.0, compiled.clock.duration), y0, method="DOP853", t_eval=times, rtol=rtol, atol=atol
    )


class _OutOfTime(Exception):
    pass


#: right-hand-side calls per DOP853 step (SciPy's, Hairer's 12 stages)
DOP853_STAGES = 12


def dop853_rate(compiled: Compiled, seconds: float) -> tuple[float, float]:
    """(simulated time, wall time) of :func:`dop853_reference`'s first solve, whose ratio is
    its pace: the whole solve when it ends within about ``seconds`` of wall time, else the
    simulated time its last quarter of right-hand-side calls covered, over what that many
    calls cost on average. DOP853's first steps are short while it finds the step the
    problem's stiffness allows, and then long ones follow; the step it settles on is what
    the rest of the solve goes at. The whole probe's average pace was four times too fast on
    a stiff cloth (a plan promised 1.4 min for a reference of over 5)."""
    import time

    import scipy.integrate  # noqa: F401  (imported before the clock starts: it takes a while)

    rhs, _, _, _ = _dop853_problem(compiled)
    start = time.perf_counter()
    deadline = start + seconds
    calls: list[float] = []  # the time each call was made at

    def timed(t: float, y: np.ndarray) -> np.ndarray:
        if time.perf_counter() > deadline:
            raise _OutOfTime
        calls.append(t)
        return rhs(t, y)

    try:
        with np.errstate(all="ignore"):
            _dop853_solve(compiled, timed, np.array([0.0, compiled.clock.duration]), DOP853_RTOL)
        return compiled.clock.duration, time.perf_counter() - start
    except _OutOfTime:
        pass
    wall = time.perf_counter() - start
    n = len(calls)
    last = n // 4
    if last < 2 * DOP853_STAGES:  # too few calls to see a settled step: the whole probe's pace
        return (max(calls) if calls else 0.0), wall
    # where the solve stood at a call: no later call goes behind an accepted step (a rejected
    # try may reach far ahead), so the least of the calls from there on
    stood = np.minimum.accumulate(np.asarray(calls)[::-1])[::-1]
    covered = float(stood[n - DOP853_STAGES] - stood[n - last])
    return covered, wall * (last - DOP853_STAGES) / n


def dop853_reference(compiled: Compiled, times: np.ndarray) -> Reference:
    """Solve the compiled Dynamics with SciPy's DOP853 at rtol 1e-12.

    The right-hand side is exactly what every integrator sees,
    y = (x, v), y' = (v, a(x, v, t)). A second solve at rtol 1e-11 measures
    the error: the two differ by about the looser one's error, a tenth of
    which is taken as the tighter one's accuracy.
    """
    n = compiled.system.particle_count
    rhs, _, _, _ = _dop853_problem(compiled)

    def solve(rtol: float) -> np.ndarray:
        sol = _dop853_solve(compiled, rhs, times, rtol)
        if not sol.success:
            raise ReferenceFailed(f"DOP853 failed: {sol.message}")
        return sol.y.T

    y = solve(DOP853_RTOL)
    check = solve(DOP853_CHECK_RTOL)
    diff = (y - check)[:, : 3 * n].reshape(len(times), n, 3)
    # The global error of DOP853 scales about in proportion to its tolerance, so
    # the difference is ~ the looser solve's error and ~10x the tighter one's.
    agreement = float(np.max(np.linalg.norm(diff, axis=2), initial=0.0))
    accuracy = agreement * DOP853_RTOL / DOP853_CHECK_RTOL
    x = y[:, : 3 * n].reshape(len(times), n, 3)
    v = y[:, 3 * n :].reshape(len(times), n, 3)
    desc = f"DOP853 (SciPy solve_ivp, rtol {DOP853_RTOL:g}; agrees with rtol {DOP853_CHECK_RTOL:g} to {agreement:.1e} m)"
    return Reference("fine", desc, Trajectory(np.asarray(times), list(x), list(v)), accuracy)


def record_at(
    scene: m.Scene, name: str, integrator: str, dt: float, times: np.ndarray, backend: str = "numpy"
) -> Compiled:
    """Compile ``scene`` with ``integrator`` and ``dt`` for ``backend``, recording exactly at ``times``."""
    return compile_scene(
        with_overrides(scene, integrator=integrator, dt=dt), name, backend=backend, record_times=times
    )


def run_trajectory(compiled: Compiled) -> tuple[Trajectory, str]:
    """Run ``compiled`` into memory; returns the trajectory and the run's status."""
    sink = MemorySink()
    with np.errstate(all="ignore"):
        result = run(compiled, [sink])
    return Trajectory.from_sink(sink, compiled.emitters is None), result.status


def _unstable_reference(dt: float, status: str) -> SimulationError:
    return SimulationError(
        f"the RK4 reference run at dt = {dt:.3g} s was {status}, so there is nothing to compare against; "
        "the scene may be unstable whatever the step (see animsim check)"
    )


def rk4_reference(
    scene: m.Scene,
    name: str,
    times: np.ndarray,
    finest_dt: float,
    smallest_error: Callable[[Trajectory], float],
    distance: Callable[[Trajectory, Trajectory], float],
    backend: str = "numpy",
    min_steps: int = FINE_MIN_STEPS,
    roundoff: Callable[[Trajectory, int], float] | None = None,
) -> Reference:
    """RK4 with dt halved until the change is far below the smallest error measured.

    Starts at ``finest_dt / 4``; after each halving, ``distance`` between the
    last two solutions is RK4's error estimate (Richardson: the finer one is
    off by about change/15). Stops when the change is below a thousandth of
    ``smallest_error(reference)`` (re-measured against each new reference), or
    at :data:`FINE_MAX_STEPS` or :data:`FINE_MAX_FACTOR` times the finest
    compared run's steps (but never below ``min_steps``), saying so. A change at the
    round-off floor (``roundoff(trajectory, steps)``, m) is convergence too: halving
    further cannot make it smaller.
    """
    dt = finest_dt / FINE_START_DIVISOR
    first = record_at(scene, name, "rk4", dt, times, backend)
    # The finest compared run's steps (the first reference run takes FINE_START_DIVISOR times as many).
    finest_steps = max(1, first.clock.steps // FINE_START_DIVISOR)
    prev, status = run_trajectory(first)
    if status != "ok":
        raise _unstable_reference(dt, status)
    notes: list[str] = []
    while True:
        dt /= 2
        compiled = record_at(scene, name, "rk4", dt, times, backend)
        cur, status = run_trajectory(compiled)
        if status != "ok":
            raise _unstable_reference(dt, status)
        change = distance(cur, prev)
        target = FINE_TARGET_RATIO * smallest_error(cur)
        prev = cur
        if change <= target or change == 0.0:
            break
        if roundoff is not None and change <= roundoff(cur, compiled.clock.steps):
            break  # rounding, not truncation: as converged as double precision allows
        limit = min(FINE_MAX_STEPS, max(min_steps, FINE_MAX_FACTOR * finest_steps))
        if compiled.clock.steps * 2 > limit:
            notes.append(
                f"the RK4 reference stopped at {compiled.clock.steps} steps (the limit is {limit}): its last "
                f"halving changed it by {change:.1e} m, more than the {target:.1e} m it aims for (a "
                f"thousandth of the smallest error measured); errors within about {change:.1e} m of "
                "it are not trusted"
            )
            break
    desc = f"RK4 at dt = {dt:.3g} s ({compiled.clock.steps} steps; last halving changed it by {change:.1e} m)"
    return Reference("fine", desc, cur, change / RK4_RICHARDSON if not notes else change, notes)
