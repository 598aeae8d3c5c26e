"""The comparison itself: every (integrator, dt) run against one reference, and the
observed orders fitted to their errors.

Common record times. Runs at different dt must be compared at the same
instants. The candidates are the record times of the coarsest run (the
scene's ``record`` rule applied to the largest dt); a run takes part at a
time only if one of its steps lands exactly on it (to rounding). When every
dt is the largest one halved k times, every candidate is hit. Otherwise only
the candidates hit by every run are kept (always t = 0 and the end, where
every clock lands), and a note says how many were dropped. Nothing is ever
interpolated, since interpolation would add an error of its own.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.analysis.compare.options import (
    DEFAULT_MAX_STEPS,
    DEFAULT_REPEAT,
    REFERENCE_KINDS,
    no_closed_form,
)
from animsim.analysis.compare.results import (
    STATUS_OK,
    STATUS_UNSTABLE,
    Comparison,
    OrderFit,
    Row,
    energy_error,
    errors,
    motion_scale,
    observed_order,
    roundoff_floor,
)
from animsim.analysis.references import (
    NoClosedForm,
    Reference,
    ReferenceFailed,
    Trajectory,
    analytic_reference,
    dop853_reference,
    record_at,
    rk4_reference,
    smooth,
)
from animsim.compile import Compiled
from animsim.engine import run
from animsim.errors import UsageError
from animsim.integrators import integrator_class
from animsim.parallel import map_cases
from animsim.record import Clock, MemorySink, landing_steps, scene_record_steps
from animsim.scene import models as m

#: an error below this multiple of the reference's own accuracy measures the reference
REFERENCE_MARGIN = 3.0
#: a point whose error exceeds this fraction of how far the particles move is
#: outside the asymptotic regime (error ~ C dt^p holds only for small errors),
#: so it is left out of the order fit
ASYMPTOTIC_LIMIT = 0.5
#: the best order a scene with emitters allows (births within a step)
EMITTER_ORDER_CAP = 2


@dataclass
class _Run:
    integrator: str
    dt: float
    compiled: Compiled
    trajectory: Trajectory
    status: str
    steps: int
    seconds: float
    force_evals: int
    failure: str | None


def common_times(
    scene: m.Scene, dts: Sequence[float], max_steps: int = DEFAULT_MAX_STEPS
) -> tuple[np.ndarray, list[str]]:
    """Record times of the coarsest run that every run lands on, and notes on any dropped.

    Refuses (UsageError) a step size whose run would take more than ``max_steps``.
    """
    clocks = [Clock.make(scene.duration, dt) for dt in dts]
    for dt, clock in zip(dts, clocks, strict=True):  # before anything is allocated per step
        if clock.steps > max_steps:
            raise UsageError(
                f"--dt {dt:g}: {clock.steps} steps is more than the limit of {max_steps} (raise it with --max-steps)"
            )
    coarse = Clock.make(scene.duration, max(dts))
    recorded = scene_record_steps(coarse, scene.record.every, scene.record.fps)
    candidates = [coarse.time(int(s)) for s in recorded]
    keep = np.ones(len(candidates), dtype=bool)
    for clock in clocks:
        keep &= np.array([s is not None for s in landing_steps(clock, candidates)])
    notes = []
    if not keep.all():
        notes.append(
            f"{int((~keep).sum())} of {len(candidates)} record times of the coarsest run are not on every "
            f"run's step grid; errors are measured at the {int(keep.sum())} common ones (always t = 0 and the end). "
            "Step sizes that halve the largest one share every record time."
        )
    return np.array(candidates)[keep], notes


def compare(
    scene: m.Scene,
    name: str,
    *,
    integrators: Sequence[str],
    dts: Sequence[float],
    reference: str = "auto",
    repeat: int = DEFAULT_REPEAT,
    progress: Callable[[str], None] | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    jobs: int = 1,
    scheduler: Any = None,
    backend: str = "numpy",
    fine_min_steps: int | None = None,
) -> Comparison:
    """Run every (integrator, dt), measure errors against a reference and time the runs.

    ``fine_min_steps``: the least step allowance of an RK4 reference (default
    its own, :data:`animsim.analysis.references.FINE_MIN_STEPS`).

    ``jobs`` > 1 or a Dask ``scheduler`` (see :func:`animsim.parallel.map_cases`)
    measures the rows in parallel: the errors are identical, the timings share
    cores and so are noisier than a serial run's.
    """
    if reference not in REFERENCE_KINDS:
        raise UsageError(f"--reference: {reference!r} is not one of {', '.join(REFERENCE_KINDS)}")
    if repeat < 0:
        raise UsageError(f"--repeat: must be >= 0, not {repeat}")
    notes: list[str] = []
    if scene.adaptive is not None:
        notes.append("the scene's adaptive stepping is ignored: compare runs each method at fixed steps")
    scene = scene.model_copy(update={"integrator": scene.integrator_name})
    dts = sorted(set(dts), reverse=True)
    times, time_notes = common_times(scene, dts, max_steps)
    notes.extend(time_notes)
    base = record_at(scene, name, integrators[0], dts[-1], times)

    ref, ref_seconds = _closed_or_smooth_reference(base, name, times, reference, notes)

    cases = [(scene, name, integ, dt, times, repeat, backend) for integ in integrators for dt in dts]
    runs = _measure_all(cases, times, jobs, scheduler, progress, backend)

    moving = None if base.emitters is not None else ~base.system.particle_pinned
    if ref is None:
        ref, seconds = _converged_reference(
            scene, name, times, dts[-1], runs, moving, progress, backend, fine_min_steps
        )
        ref_seconds += seconds
    notes.extend(ref.notes)

    conservative = base.conservative
    rows = [_row(r, ref, moving, conservative) for r in runs]
    ceiling = ASYMPTOTIC_LIMIT * motion_scale(ref.trajectory, moving)
    orders = _fit_orders(rows, integrators, ref, ceiling)
    if base.emitters is not None:
        for fit in orders:
            # A particle born inside a step is carried to the step's end with
            # its birth acceleration held constant: an O(dt^2) velocity error
            # whatever the method, so order min(p, 2) (animsim.emitters,
            # "The rest of the birth step"; smoke.yaml's rk4 measures 1.98).
            fit.capped = min(fit.expected, EMITTER_ORDER_CAP)
            fit.cap_reason = (
                "particles born inside a step finish it with constant acceleration, "
                "which limits any method to order 2"
            )
    result = Comparison(name, ref, rows, orders, times, repeat, conservative, notes)
    result.reference_seconds = ref_seconds
    return result


def _closed_or_smooth_reference(
    base: Compiled, name: str, times: np.ndarray, reference: str, notes: list[str]
) -> tuple[Reference | None, float]:
    """The closed form (``reference`` "auto" or "analytic") or else, on a smooth scene, a DOP853
    run; None when neither applies (then a converged RK4 run is the reference). Appends to
    ``notes`` why one was passed over; returns the seconds it took too."""
    ref: Reference | None = None
    ref_start = time.perf_counter()
    if reference in ("auto", "analytic"):
        try:
            ref = analytic_reference(base, times)
        except NoClosedForm as exc:
            if reference == "analytic":
                raise no_closed_form(name, exc) from None
            notes.append(f"no closed form: {exc}; the reference is a converged run")
    if ref is None and smooth(base):
        try:
            with np.errstate(all="ignore"):
                ref = dop853_reference(base, times)
        except ReferenceFailed as exc:
            notes.append(f"{exc}; falling back to RK4 with dt halved")
    return ref, time.perf_counter() - ref_start


# one row to measure: the arguments of _measure (scene, name, integrator, dt, times, repeat, backend)
_Case = tuple[m.Scene, str, str, float, np.ndarray, int, str]


def _measure_all(
    cases: list[_Case],
    times: np.ndarray,
    jobs: int,
    scheduler: Any,
    progress: Callable[[str], None] | None,
    backend: str,
) -> list[_Run]:
    """Measure every case, one after the other or in parallel (see :func:`compare`)."""
    if jobs == 1 and scheduler is None:
        runs: list[_Run] = []
        for case in cases:
            if progress is not None:
                progress(f"{case[2]} dt={case[3]:g}")
            runs.append(_measure(*case))
        return runs

    # Rows in parallel (local processes or Dask): the same rows, noisier
    # seconds, since the runs share the cores they are timed on.
    def tick(done: int, total: int) -> None:
        if progress is not None:
            progress(f"{done}/{total} runs")

    runs = map_cases(_measure_case, cases, jobs=jobs, scheduler=scheduler, progress=tick)
    for r, case in zip(runs, cases, strict=True):
        r.compiled = record_at(*case[:4], times, backend)  # compiling is cheap; shipping it back is not
    return runs


def _converged_reference(
    scene: m.Scene,
    name: str,
    times: np.ndarray,
    dt: float,
    runs: list[_Run],
    moving: np.ndarray | None,
    progress: Callable[[str], None] | None,
    backend: str,
    fine_min_steps: int | None,
) -> tuple[Reference, float]:
    """RK4 with dt halved until it converges (:func:`rk4_reference`), from the rows' smallest
    ``dt``; returns it and the seconds it took."""
    ok = [r for r in runs if r.status == STATUS_OK]

    def smallest(candidate: Trajectory) -> float:
        errs = [errors(r.trajectory, candidate, moving)[0] for r in ok]
        floor = roundoff_floor(candidate, max((r.steps for r in ok), default=1))
        real = [e for e in errs if math.isfinite(e) and e > floor]
        return min(real, default=floor)

    def distance(a: Trajectory, b: Trajectory) -> float:
        return errors(a, b, moving)[0]

    if progress is not None:
        progress("reference (RK4, halving dt)")
    # On the rows' backend: numba's RK4 is the same method, several times faster.
    floor = {} if fine_min_steps is None else {"min_steps": fine_min_steps}
    ref_start = time.perf_counter()
    ref = rk4_reference(scene, name, times, dt, smallest, distance, backend, **floor, roundoff=roundoff_floor)
    return ref, time.perf_counter() - ref_start


def _measure(
    scene: m.Scene,
    name: str,
    integ: str,
    dt: float,
    times: np.ndarray,
    repeat: int,
    backend: str = "numpy",
) -> _Run:
    """One accuracy run into memory (also the warm-up), then ``repeat`` timed runs without sinks.

    With ``repeat`` = 0 the accuracy run's own wall time is the row's seconds.
    """
    import dataclasses

    compiled = record_at(scene, name, integ, dt, times, backend)
    sink = MemorySink()
    with np.errstate(all="ignore"):
        result = run(compiled, [sink])
    traj = Trajectory.from_sink(sink, compiled.emitters is None)
    walls = [result.wall_time]
    if repeat > 0:
        # Timed without record times: the loop would otherwise stop at each of
        # them (leaving numba's compiled loop) even with no sink to feed. The
        # watchdog still checks as often; the status is the accuracy run's.
        bare = dataclasses.replace(compiled, record_steps=np.array([0, compiled.clock.steps], dtype=np.int64))
        walls = []
        with np.errstate(all="ignore"):
            for _ in range(repeat):
                walls.append(run(bare, []).wall_time)
    return _Run(
        integ,
        dt,
        compiled,
        traj,
        result.status,
        result.steps_taken,
        statistics.median(walls),
        result.force_evals,
        result.failure.describe() if result.failure is not None else None,
    )


def _measure_case(case: tuple[Any, ...]) -> _Run:
    """``_measure`` for a worker process: the run without its compiled scene."""
    run = _measure(*case)
    run.compiled = None  # type: ignore[assignment]
    return run


def _row(r: _Run, ref: Reference, moving: np.ndarray | None, conservative: bool) -> Row:
    status, failure = r.status, r.failure
    err = final = rms = energy = None
    if status == STATUS_OK:
        err, final, rms = errors(r.trajectory, ref.trajectory, moving)
        if not all(math.isfinite(x) for x in (err, final, rms)):
            status, failure = STATUS_UNSTABLE, "the position error is not finite"
            err = final = rms = None
        elif conservative:
            energy = energy_error(r.compiled, r.trajectory, ref.trajectory)
    elif status != STATUS_UNSTABLE:  # interrupted cannot happen here, but never print it as ok
        status = STATUS_UNSTABLE
    return Row(
        integrator=r.integrator,
        dt=r.compiled.clock.dt,
        steps=r.steps,
        seconds=r.seconds,
        force_evals=r.force_evals,
        error=err,
        final_error=final,
        rms_error=rms,
        energy_error=energy,
        status=status,
        failure=failure,
    )


def _fit_orders(
    rows: list[Row], integrators: Sequence[str], ref: Reference, ceiling: float
) -> list[OrderFit]:
    """Fit each integrator over its stable points above round-off and below ``ceiling``."""
    fits = []
    for integ in integrators:
        mine = [r for r in rows if r.integrator == integ]
        stable = [r for r in mine if r.status == STATUS_OK and r.error is not None]
        low = [
            r
            for r in stable
            if r.error is not None
            and r.error <= max(roundoff_floor(ref.trajectory, r.steps), REFERENCE_MARGIN * ref.accuracy)
        ]
        high = [r for r in stable if ceiling > 0 and r.error is not None and r.error >= ceiling]
        usable = [r for r in stable if r not in low and r not in high]
        for r in usable:
            r.in_fit = True
        order = None
        if len(usable) >= 2:
            order = observed_order([r.dt for r in usable], [r.error for r in usable])  # type: ignore[misc]
        fit = OrderFit(integ, integrator_class(integ).order, order, len(usable), len(stable), len(mine))
        fit.below = len(low)
        fit.above = len(high)
        fits.append(fit)
    return fits
