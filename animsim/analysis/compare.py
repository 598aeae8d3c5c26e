"""``animsim compare``: error against run time for every integrator (``cli.md``).

For each integrator and each step size the scene is run once into memory,
its positions are compared with a reference
(:mod:`animsim.analysis.references`) at common record times, and, with
``repeat`` > 0 (default 1), it is run that many more times without any sink
to time the simulation loop alone (the median is reported). With ``repeat``
= 0 the accuracy run's own time is reported, recording included: cheaper, but
on the numba backend each recorded frame leaves the compiled loop, which can
cost more than the steps themselves (0.3 s for 251 frames of a 2-particle
scene), so it is not the default. The timed runs record nothing. The result is a table, one row per (integrator, dt), and each
integrator's observed order of convergence.

Common record times. Runs at different dt must be compared at the same
instants. The candidates are the record times of the coarsest run (the
scene's ``record`` rule applied to the largest dt); a run takes part at a
time only if one of its steps lands exactly on it (to rounding). When every
dt is the largest one halved k times, every candidate is hit. Otherwise only
the candidates hit by every run are kept (always t = 0 and the end, where
every clock lands), and a note says how many were dropped. Nothing is ever
interpolated, since interpolation would add an error of its own.

Errors, per run, over the compared frames and the moving particles (pinned
ones move exactly by construction and would only dilute the mean); with
emitters, rows are matched by particle id:

* ``error``: the largest distance |x - x_ref| over frames and particles, m;
* ``final_error``: the largest at the last frame, m;
* ``rms_error``: the root mean square over every frame after t = 0 and every
  particle, m (t = 0 is exact by construction);
* ``energy_error``: for conservative scenes, max |E(t) - E(0)| over the frames
  divided by the larger of |E(0)| and the reference's largest kinetic energy,
  so a scene whose energy starts near zero still gets a meaningful ratio.

Observed order: the least-squares slope of log(error) against log(dt) over an
integrator's stable points whose error is above round-off (``ROUNDOFF_SAFETY``
eps |x| sqrt(steps)), above the reference's own accuracy, and below half the
distance the particles move (``ASYMPTOTIC_LIMIT``: a run that is off by more
than that is not in the regime where error ~ C dt^p). Hairer, Norsett
and Wanner, "Solving ODEs I", II.1 (global error = C dt^p); the work-precision
idea is SciML DiffEqDevTools' ``WorkPrecisionSet``.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from animsim.analysis.references import (
    NoClosedForm,
    Reference,
    ReferenceFailed,
    Trajectory,
    analytic_reference,
    body_point_distances,
    dop853_reference,
    record_at,
    rk4_reference,
    smooth,
)
from animsim.compile import Compiled
from animsim.errors import UsageError
from animsim.integrators import FIXED_STEP, REGISTRY, integrator_class
from animsim.record import Clock, landing_steps, scene_record_steps
from animsim.scene import models as m

COLUMNS = (
    "integrator",
    "dt",
    "steps",
    "seconds",
    "force_evals",
    "error",
    "final_error",
    "rms_error",
    "energy_error",
    "status",
)
REFERENCE_KINDS = ("auto", "analytic", "fine")
#: the default step sizes, as multiples of the scene's dt: four points for the
#: order fit, nested (each halves the one before, so they share record times),
#: and the finest only 4 times finer than the scene's, so the rows together
#: cost 7.5 runs of the scene and the reference (from a quarter of the finest)
#: stays affordable; a bigger step also shows where a method stops being stable
DEFAULT_STEP_FACTORS = (2.0, 1.0, 0.5, 0.25)
#: timed runs per row, after its accuracy run (which also warms it up)
DEFAULT_REPEAT = 1
#: the probe that estimates the total time runs each method this many steps
PROBE_STEPS = 200
#: the most steps one run may take (the spec's limit; --max-steps raises it)
DEFAULT_MAX_STEPS = 100_000_000
#: an error below this many machine epsilons of |x| sqrt(steps) is round-off
#: (rounding errors of n steps add up like a random walk), not truncation
ROUNDOFF_SAFETY = 10.0
#: an error below this multiple of the reference's own accuracy measures the reference
REFERENCE_MARGIN = 3.0
#: a point whose error exceeds this fraction of how far the particles move is
#: outside the asymptotic regime (error ~ C dt^p holds only for small errors),
#: so it is left out of the order fit
ASYMPTOTIC_LIMIT = 0.5
#: below this (J) an energy scale means nothing
ENERGY_FLOOR = 1e-12
#: the best order a scene with emitters allows (births within a step)
EMITTER_ORDER_CAP = 2
STATUS_OK = "ok"
STATUS_UNSTABLE = "unstable"

CLOSED_FORM_FAMILIES = (
    "free flight under gravity with or without linear drag or steady wind",
    "one particle on one spring to a pinned anchor, moving along the spring",
    "two free particles on one spring, moving along it",
    "particles on bound orbits around one attractor",
    "free rigid bodies with no torque that are axisymmetric or spherical (or pinned)",
)


@dataclass
class Row:
    """One (integrator, dt) run; the fields of ``COLUMNS`` plus why it failed."""

    integrator: str
    dt: float
    steps: int  # steps taken (fewer than planned when the run became unstable)
    seconds: float  # median wall time of the simulation loop, s
    force_evals: int
    error: float | None  # m; None when unstable
    final_error: float | None
    rms_error: float | None
    energy_error: float | None  # None when the scene is not conservative (or the run unstable)
    status: str
    failure: str | None = None
    in_fit: bool = False  # used in the observed-order fit

    def csv_fields(self) -> list[str]:
        def num(v: float | None) -> str:
            return "" if v is None else repr(float(v))

        return [
            self.integrator,
            repr(float(self.dt)),
            str(self.steps),
            repr(float(self.seconds)),
            str(self.force_evals),
            num(self.error),
            num(self.final_error),
            num(self.rms_error),
            num(self.energy_error),
            self.status,
        ]


@dataclass
class OrderFit:
    """The observed order of one integrator."""

    integrator: str
    expected: int
    order: float | None  # None with fewer than two usable points
    points: int  # used in the fit
    stable: int  # stable points
    total: int
    below: int = 0  # stable points at round-off or reference accuracy
    above: int = 0  # stable points not yet in the asymptotic regime
    #: the order this scene allows, when something in it caps the method's own
    capped: int | None = None
    cap_reason: str = ""

    @property
    def expected_text(self) -> str:
        if self.capped is None or self.capped >= self.expected:
            return f"expected {self.expected}"
        return f"expected {self.capped}, not {self.expected}: {self.cap_reason}"

    def describe(self) -> str:
        if self.order is not None:
            return f"{self.order:.2f}  ({self.expected_text}; fit over {self.points} of {self.total} points)"
        if self.stable == 0:
            why = "unstable at every dt"
        elif self.below == self.stable:
            why = "every error is at round-off or reference accuracy: exact for this scene"
        else:
            left_out = [
                (self.total - self.stable, "unstable"),
                (self.below, "at round-off"),
                (self.above, "error above half the motion"),
            ]
            detail = ", ".join(f"{n} {what}" for n, what in left_out if n)
            why = f"{self.points} usable of {self.total} points ({detail}); need 2"
        return f"n/a  ({self.expected_text}; {why})"


@dataclass
class Comparison:
    scene_name: str
    reference: Reference
    rows: list[Row]
    orders: list[OrderFit]
    times: np.ndarray  # the compared record times, s
    repeat: int
    conservative: bool
    notes: list[str] = field(default_factory=list)

    @property
    def any_unstable(self) -> bool:
        return any(r.status != STATUS_OK for r in self.rows)


# --- option parsing (strings live at the edge) -----------------------------------------


def parse_integrators(text: str | None) -> list[str]:
    """Names from ``--integrators``; default every fixed-step method in this build."""
    if text is None:
        return [name for name in FIXED_STEP if name in REGISTRY]
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise UsageError("--integrators: give at least one name")
    for name in names:
        if name not in REGISTRY:
            if name in m.INTEGRATOR_NAMES:
                raise UsageError(f"--integrators: {name!r} is not available in this build")
            from animsim.scene.loader import did_you_mean

            hint = did_you_mean(name, list(REGISTRY))
            raise UsageError(f"--integrators: unknown method {name!r}{hint} (valid: {', '.join(REGISTRY)})")
    return list(dict.fromkeys(names))


def default_dts(dt: float, duration: float | None = None) -> list[float]:
    """2 dt, dt, dt/2, dt/4 (DEFAULT_STEP_FACTORS); when 2 dt is longer than the
    duration, dt/8 takes its place, so there are always four."""
    dts = [dt * f for f in DEFAULT_STEP_FACTORS]
    if duration is not None and dts[0] > duration:
        dts = [*dts[1:], dt * DEFAULT_STEP_FACTORS[-1] / 2]
    return dts


def parse_dts(text: str | None, scene: m.Scene) -> list[float]:
    """Step sizes from ``--dt``, largest first; default :func:`default_dts` of the scene's dt."""
    if text is None:
        return default_dts(scene.dt, scene.duration)
    values: list[float] = []
    for part in (s.strip() for s in text.split(",")):
        if not part:
            continue
        try:
            v = float(part)
        except ValueError:
            raise UsageError(f"--dt: {part!r} is not a number") from None
        if not (math.isfinite(v) and v > 0):
            raise UsageError(f"--dt: {part!r} must be a finite number > 0")
        if v > scene.duration:
            raise UsageError(f"--dt: {part} is longer than the duration {scene.duration!r}")
        values.append(v)
    if not values:
        raise UsageError("--dt: give at least one step size")
    return sorted(set(values), reverse=True)


# --- errors ------------------------------------------------------------------------------


def _distances(run: Trajectory, ref: Trajectory, moving: np.ndarray | None) -> list[np.ndarray]:
    """Per frame, |x_run - x_ref| of the particles both hold (moving ones only)."""
    out = []
    if run.ids is None and ref.ids is None:
        for xr, xf in zip(run.position, ref.position, strict=True):
            d = np.linalg.norm(xr - xf, axis=1)
            out.append(d if moving is None else d[moving])
        turned = body_point_distances(run, ref)  # rigid bodies: orientation errors count too
        if turned is not None:
            out = [np.concatenate([d, e]) for d, e in zip(out, turned, strict=True)]
        return out
    assert run.ids is not None and ref.ids is not None
    for ir, xr, jf, xf in zip(run.ids, run.position, ref.ids, ref.position, strict=True):
        where = {pid: k for k, pid in enumerate(jf)}
        a = [k for k, pid in enumerate(ir) if pid in where]
        b = [where[ir[k]] for k in a]
        out.append(np.linalg.norm(xr[a] - xf[b], axis=1) if a else np.zeros(0))
    return out


def errors(run: Trajectory, ref: Trajectory, moving: np.ndarray | None = None) -> tuple[float, float, float]:
    """(error, final_error, rms_error) of ``run`` against ``ref`` (see the module docstring)."""
    with np.errstate(all="ignore"):
        d = _distances(run, ref, moving)
        peak = max((float(np.max(x)) if x.size else 0.0) for x in d)
        if any(not np.all(np.isfinite(x)) for x in d):
            peak = math.inf
        final = float(np.max(d[-1])) if d[-1].size else 0.0
        later = [x for x in d[1:] if x.size] or [np.zeros(1)]
        rms = float(np.sqrt(np.mean(np.concatenate(later) ** 2)))
    return peak, final, rms


def _energy_error(compiled: Compiled, run: Trajectory, ref: Trajectory) -> float:
    dyn = compiled.dynamics
    with np.errstate(all="ignore"):
        energy = np.array([dyn.energy(x, v) for x, v in zip(run.position, run.velocity, strict=True)])
        scale = max(
            abs(energy[0]),
            max(dyn.kinetic_energy(v) for v in ref.velocity),
            ENERGY_FLOOR,
        )
        return float(np.max(np.abs(energy - energy[0])) / scale)


def _position_scale(ref: Trajectory) -> float:
    return max((float(np.max(np.abs(x))) for x in ref.position if x.size), default=1.0) or 1.0


def motion_scale(ref: Trajectory, moving: np.ndarray | None) -> float:
    """How far the moving particles get from where they started, m (largest over frames)."""
    if ref.ids is not None:  # populations change: use the spread of positions instead
        return max((float(np.ptp(x, axis=0).max()) for x in ref.position if len(x)), default=0.0)
    start = ref.position[0]
    far = 0.0
    for x in ref.position:
        d = np.linalg.norm(x - start, axis=1)
        if moving is not None:
            d = d[moving]
        if d.size:
            far = max(far, float(d.max()))
    return far


def roundoff_floor(ref: Trajectory, steps: int) -> float:
    """Errors below this are rounding, not truncation (see ``ROUNDOFF_SAFETY``)."""
    return ROUNDOFF_SAFETY * np.finfo(float).eps * _position_scale(ref) * math.sqrt(max(steps, 1))


def observed_order(dts: Sequence[float], errs: Sequence[float]) -> float:
    """Least-squares slope of log(error) against log(dt)."""
    slope, _ = np.polyfit(np.log(np.asarray(dts)), np.log(np.asarray(errs)), 1)
    return float(slope)


# --- the comparison ----------------------------------------------------------------------


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
) -> Comparison:
    """Run every (integrator, dt), measure errors against a reference and time the runs.

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

    ref: Reference | None = None
    if reference in ("auto", "analytic"):
        try:
            ref = analytic_reference(base, times)
        except NoClosedForm as exc:
            if reference == "analytic":
                raise UsageError(
                    f"--reference analytic: scene {name!r} has no closed form: {exc}.\n"
                    f"  closed forms cover: {'; '.join(CLOSED_FORM_FAMILIES)}.\n"
                    "  use --reference fine (a converged run) or auto"
                ) from None
            notes.append(f"no closed form: {exc}; the reference is a converged run")
    if ref is None and smooth(base):
        try:
            with np.errstate(all="ignore"):
                ref = dop853_reference(base, times)
        except ReferenceFailed as exc:
            notes.append(f"{exc}; falling back to RK4 with dt halved")

    cases = [(scene, name, integ, dt, times, repeat, backend) for integ in integrators for dt in dts]
    if jobs == 1 and scheduler is None:
        runs: list[_Run] = []
        for case in cases:
            if progress is not None:
                progress(f"{case[2]} dt={case[3]:g}")
            runs.append(_measure(*case))
    else:
        # Rows in parallel (local processes or Dask): the same rows, noisier
        # seconds, since the runs share the cores they are timed on.
        from animsim.parallel import map_cases

        def tick(done: int, total: int) -> None:
            if progress is not None:
                progress(f"{done}/{total} runs")

        runs = map_cases(_measure_case, cases, jobs=jobs, scheduler=scheduler, progress=tick)
        for r, case in zip(runs, cases, strict=True):
            r.compiled = record_at(*case[:4], times, backend)  # compiling is cheap; shipping it back is not

    moving = None if base.emitters is not None else ~base.system.particle_pinned
    if ref is None:
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
        ref = rk4_reference(scene, name, times, dts[-1], smallest, distance, backend)
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
    return Comparison(name, ref, rows, orders, times, repeat, conservative, notes)


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

    from animsim.engine import run
    from animsim.record import MemorySink

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


@dataclass(frozen=True)
class Estimate:
    """What a comparison will cost, from a short timed probe of each method."""

    seconds: float  # the rows' runs (accuracy run + repeats), s
    runs: int
    steps: int  # steps of every run together
    backend: str  # what the probe ran on (numba, or numpy when numba cannot run the scene)

    def describe(self) -> str:
        return (
            f"{self.runs} runs, {self.steps:,} steps on {self.backend}: "
            f"about {_duration(self.seconds)} plus the reference"
        )


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{max(seconds, 0.1):.2g} s" if seconds < 10 else f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min"


def estimate(
    scene: m.Scene,
    name: str,
    *,
    integrators: Sequence[str],
    dts: Sequence[float],
    repeat: int = DEFAULT_REPEAT,
    backend: str = "numpy",
    notice: Callable[[str], None] | None = None,
) -> Estimate:
    """Time each method over a few steps at the largest dt and scale to every row's steps.

    Each probe runs twice (the first pays numba's compilation and NumPy's
    warm-up, the second is timed), so the estimate is of steady stepping.
    Recording is left out: compare records only at the common times.
    """
    from animsim.compile import with_overrides
    from animsim.engine import run

    dt = max(dts)
    total_steps = sum(Clock.make(scene.duration, d).steps for d in dts)
    probe_duration = min(scene.duration, PROBE_STEPS * dt)
    seconds = 0.0
    chosen = "numpy"
    for integ in integrators:
        probe = with_overrides(scene, integrator=integ, dt=dt, duration=probe_duration)
        compiled = record_at(probe, name, integ, dt, np.array([0.0, probe.duration]), backend)
        chosen = compiled.backend if compiled.backend != "numpy" else chosen
        with np.errstate(all="ignore"):
            run(compiled, [], notice=notice)
            result = run(compiled, [])
        per_step = result.wall_time / max(result.steps_taken, 1)
        seconds += per_step * total_steps * (1 + repeat)
    runs = len(integrators) * len(dts) * (1 + repeat)
    return Estimate(seconds, runs, total_steps * len(integrators) * (1 + repeat), chosen)


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
            energy = _energy_error(r.compiled, r.trajectory, ref.trajectory)
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


# --- output ------------------------------------------------------------------------------


def write_csv(comparison: Comparison, path: str | Path) -> None:
    """The table as CSV with exactly ``COLUMNS``, written atomically."""
    from animsim.atomic import write_text_atomic

    lines = [",".join(COLUMNS)] + [",".join(r.csv_fields()) for r in comparison.rows]
    write_text_atomic(path, "\n".join(lines) + "\n")


#: table columns by how much they matter when the screen is narrow: the last
#: ones are left out first (the CSV from -o always has every column)
_PRIORITY = (
    "integrator",
    "dt",
    "error",
    "seconds",
    "status",
    "energy_error",
    "steps",
    "rms_error",
    "final_error",
    "force_evals",
)


def _cells(comparison: Comparison, r: Row, shown_name: bool) -> dict[str, str]:
    from animsim.console import sig

    return {
        "integrator": r.integrator if shown_name else "",
        "dt": sig(r.dt, 4),
        "steps": str(r.steps),
        "seconds": sig(r.seconds),
        "force_evals": str(r.force_evals),
        "error": sig(r.error),
        "final_error": sig(r.final_error),
        "rms_error": sig(r.rms_error),
        "energy_error": sig(r.energy_error) if comparison.conservative else "",
        "status": "ok" if r.status == STATUS_OK else f"[bold red]{r.status}[/]",
    }


def _build_table(comparison: Comparison, columns: Sequence[str]) -> Any:
    from rich import box
    from rich.table import Table

    ref = comparison.reference
    t = Table(
        title=f"{comparison.scene_name}: error against cost",
        caption=f"reference: {ref.kind}: {ref.description}",
        caption_justify="left",
        header_style="bold",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
    )
    for col in columns:
        numeric = col not in ("integrator", "status")
        # no_wrap and no ellipsis: a number is shown whole or its column is left out
        t.add_column(col, justify="right" if numeric else "left", no_wrap=True, overflow="fold")
    current = None
    for r in comparison.rows:
        if current is not None and r.integrator != current:
            t.add_section()
        cells = _cells(comparison, r, r.integrator != current)
        t.add_row(*(cells[c] for c in columns))
        current = r.integrator
    return t


def table_columns(comparison: Comparison, width: int | None) -> list[str]:
    """The columns that fit in ``width`` characters (all of them when ``width`` is None)."""
    from rich.console import Console

    keep = [c for c in _PRIORITY if c != "energy_error" or comparison.conservative]
    if width is None:
        return [c for c in COLUMNS if c in keep]
    console = Console(width=10_000)
    while len(keep) > 3:
        cols = [c for c in COLUMNS if c in keep]
        if console.measure(_build_table(comparison, cols)).maximum <= width:
            return cols
        keep.pop()
    return [c for c in COLUMNS if c in keep]


def table(comparison: Comparison, width: int | None = None) -> Any:
    """The rich table printed by ``animsim compare``: one section per integrator.

    ``width``: the screen's columns; the least important columns are left out
    until every number fits whole (:data:`_PRIORITY`; :func:`left_out` names them).
    """
    return _build_table(comparison, table_columns(comparison, width))


def left_out(comparison: Comparison, width: int | None) -> list[str]:
    """Columns :func:`table` leaves out at ``width``."""
    shown = table_columns(comparison, width)
    return [c for c in COLUMNS if c not in shown and (c != "energy_error" or comparison.conservative)]


def summary_lines(comparison: Comparison) -> list[str]:
    """What ``animsim compare`` prints under the table."""
    times = comparison.times
    if comparison.repeat == 0:
        timing = "seconds: the accuracy run itself, recording included (--repeat 0)"
    else:
        runs = "1 timed run" if comparison.repeat == 1 else f"the median of {comparison.repeat} timed runs"
        timing = f"seconds: {runs} of the simulation loop only"
    lines = [
        f"errors at {len(times)} record times from {times[0]:g} to {times[-1]:g} s",
        timing,
        "observed order: least-squares slope of log error against log dt, over stable",
        "  points above round-off whose error is below half the distance moved:",
    ]
    width = max(len(o.integrator) for o in comparison.orders)
    for o in comparison.orders:
        lines.append(f"  {o.integrator:<{width}}  {o.describe()}")
    for r in comparison.rows:
        if r.status != STATUS_OK and r.failure:
            lines.append(f"{r.integrator} at dt = {r.dt:g}: {r.failure.splitlines()[0]}")
    for note in comparison.notes:
        lines.append(f"note: {note}")
    return lines
