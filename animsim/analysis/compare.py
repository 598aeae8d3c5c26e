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
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from animsim.analysis.references import (
    FINE_MAX_FACTOR,
    FINE_MAX_STEPS,
    FINE_MIN_STEPS,
    FINE_START_DIVISOR,
    NoClosedForm,
    Reference,
    ReferenceFailed,
    Trajectory,
    analytic_reference,
    body_point_distances,
    dop853_rate,
    dop853_reference,
    record_at,
    rk4_reference,
    smooth,
)
from animsim.atomic import write_text_atomic
from animsim.compile import Compiled, compile_scene, with_overrides
from animsim.console import sig
from animsim.engine import run
from animsim.errors import UsageError
from animsim.integrators import integrator_class, listed_methods
from animsim.parallel import map_cases
from animsim.record import Clock, MemorySink, landing_steps, scene_record_steps
from animsim.scene import models as m
from animsim.scene.loader import method_from_option

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
#: the probe that estimates the total time runs each method this many steps ...
PROBE_STEPS = 200
#: ... or for this long (wall time, s), whichever comes first
PROBE_METHOD_SECONDS = 0.08
#: then one method through the scene for at most this long (wall time, s), so
#: that a scene whose steps get dearer as it runs (births, contacts) is measured
PROBE_SECONDS = 0.75
#: and the DOP853 reference's first solve for at most this long, s
PROBE_REFERENCE_SECONDS = 0.5
#: a DOP853 reference predicted to take longer than this (s) is probed again, for
#: LONG_REFERENCE_SHARE of its predicted time, at most LONG_REFERENCE_PROBE s
LONG_REFERENCE = 20.0
LONG_REFERENCE_SHARE = 0.03
LONG_REFERENCE_PROBE = 5.0
#: with default options, compare plans its runs to take about this long (s):
#: with the probe, start-up and numba's compiling it finishes within 30 s
DEFAULT_BUDGET = 20.0
#: the methods kept when not every one fits the budget: first order, first
#: order symplectic, second order, fourth order (and the scene's own method)
CORE_INTEGRATORS = ("euler", "symplectic_euler", "midpoint", "rk4")
#: the probe's time counts against the budget, but leaves the runs at least this fraction of it
MIN_RUN_BUDGET = 0.5
#: the compared window is never cut below this many steps of the largest dt
MIN_WINDOW_STEPS = 20
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
    plan: Plan | None = None  # set by run_planned
    seconds: float | None = None  # wall time of the comparison (probe excluded), s
    reference_seconds: float = 0.0  # of which computing the reference, s

    @property
    def any_unstable(self) -> bool:
        return any(r.status != STATUS_OK for r in self.rows)


# --- option parsing (strings live at the edge) -----------------------------------------


def parse_integrators(text: str | None) -> list[str]:
    """Names from ``--integrators``; default every fixed-step method in this build."""
    if text is None:
        return list(listed_methods())
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise UsageError("--integrators: give at least one name")
    return list(dict.fromkeys(method_from_option(name, "--integrators") for name in names))


def default_dts(dt: float, duration: float | None = None) -> list[float]:
    """2 dt, dt, dt/2, dt/4 (DEFAULT_STEP_FACTORS); when 2 dt is longer than the
    duration, dt/8 takes its place, so there are always four."""
    dts = [dt * f for f in DEFAULT_STEP_FACTORS]
    if duration is not None and dts[0] > duration:
        dts = [*dts[1:], dt * DEFAULT_STEP_FACTORS[-1] / 2]
    return dts


def parse_dt_option(text: str | None) -> list[float] | None:
    """Step sizes from ``--dt`` (checked against the duration later), or None for the default."""
    if text is None:
        return None
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
        values.append(v)
    if not values:
        raise UsageError("--dt: give at least one step size")
    return sorted(set(values), reverse=True)


def parse_dts(text: str | None, scene: m.Scene) -> list[float]:
    """Step sizes from ``--dt``, largest first; default :func:`default_dts` of the scene's dt."""
    values = parse_dt_option(text)
    if values is None:
        return default_dts(scene.dt, scene.duration)
    for v in values:
        if v > scene.duration:
            raise UsageError(f"--dt: {v:g} is longer than the duration {scene.duration!r}")
    return values


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

    ref: Reference | None = None
    ref_start = time.perf_counter()
    if reference in ("auto", "analytic"):
        try:
            ref = analytic_reference(base, times)
        except NoClosedForm as exc:
            if reference == "analytic":
                raise _no_closed_form(name, exc) from None
            notes.append(f"no closed form: {exc}; the reference is a converged run")
    if ref is None and smooth(base):
        try:
            with np.errstate(all="ignore"):
                ref = dop853_reference(base, times)
        except ReferenceFailed as exc:
            notes.append(f"{exc}; falling back to RK4 with dt halved")
    ref_seconds = time.perf_counter() - ref_start

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
        floor = {} if fine_min_steps is None else {"min_steps": fine_min_steps}
        ref_start = time.perf_counter()
        ref = rk4_reference(
            scene, name, times, dts[-1], smallest, distance, backend, **floor, roundoff=roundoff_floor
        )
        ref_seconds += time.perf_counter() - ref_start
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


def _no_closed_form(name: str, exc: Exception) -> UsageError:
    return UsageError(
        f"--reference analytic: scene {name!r} has no closed form: {exc}.\n"
        f"  closed forms cover: {'; '.join(CLOSED_FORM_FAMILIES)}.\n"
        "  use --reference fine (a converged run) or auto"
    )


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


# --- the plan: what to run so that it finishes in time ------------------------------------


@dataclass
class Probe:
    """What the scene costs on this machine, from short timed runs of it.

    ``curve_t``/``curve_w``: simulated time reached and the loop's wall time to
    reach it, for ``method`` at ``dt`` (recording as the scene records), so a
    scene that gets dearer as it runs (births, contacts) is measured as it
    grows. ``per_step``: seconds per step of each method at ``dt`` over the
    first steps, for the ratios between methods.
    """

    backend: str
    method: str
    dt: float
    duration: float  # the scene's, s
    curve_t: np.ndarray
    curve_w: np.ndarray
    per_step: dict[str, float]
    setup: float  # compiling the scene once (every row and reference run does), s
    compile_seconds: float  # each method's first stretch: numba compiling its kernels (some on first call), s
    seconds: float  # the probe's own wall time, compile included, s
    reference_kind: str  # "analytic", "DOP853" or "RK4"
    dop853: tuple[float, float] | None = None  # (simulated s reached, wall s) of its first solve
    grows: bool = False  # births: each step costs more than the one before
    #: what one run() costs beyond its loop (the watchdog's stability limits, the stepper's
    #: start, the metadata), s: a few ms that add up over the 60-odd runs of a tiny scene
    overhead: float = 0.0

    def loop(self, window: float) -> float:
        """Wall time of ``method`` at ``dt`` to simulate ``window`` seconds.

        Beyond what the probe reached, the rate of its last quarter goes on,
        growing as it grew during the probe when births add particles."""
        t, w = self.curve_t, self.curve_w
        if window <= t[-1]:
            return float(np.interp(window, t, w))
        j = min(int(np.searchsorted(t, 0.75 * t[-1])), len(t) - 2)
        rate = (w[-1] - w[j]) / max(t[-1] - t[j], 1e-300)
        ahead = window - t[-1]
        growth = 0.0
        if self.grows:
            # Births keep adding particles: the rate grew from the first half to
            # the last quarter, and is taken to go on growing as fast.
            h = min(int(np.searchsorted(t, 0.5 * t[-1])), len(t) - 2)
            early = (w[h] - w[0]) / max(t[h] - t[0], 1e-300)
            growth = max(0.0, (rate - early) / max(0.5 * (t[-1] + t[j]) - 0.5 * (t[h] + t[0]), 1e-300))
        return float(w[-1] + rate * ahead + 0.5 * growth * ahead**2)

    def run_seconds(self, method: str, dt: float, window: float) -> float:
        """One run of ``method`` at ``dt`` over ``window``: steps scale as 1/dt, each
        method's step costs what it cost in the probe relative to ``method``'s."""
        ratio = self.per_step[method] / max(self.per_step[self.method], 1e-300)
        return self.loop(window) * (self.dt / dt) * ratio + self.setup + self.overhead

    def reference_seconds(self, dts: Sequence[float], window: float, min_steps: int | None = None) -> float:
        if self.reference_kind == "analytic":
            return 0.0
        if self.reference_kind == "DOP853":
            assert self.dop853 is not None
            reached, wall = self.dop853
            first = wall * min(window, self.duration) / max(reached, 1e-300)
            # The check solve at rtol 1e-11 takes about 10^(-1/8) as many steps
            # (an order-8 method's steps scale as rtol^(-1/8)).
            return first * (1 + 10 ** (-1 / 8)) + self.setup
        # RK4 halving (references.rk4_reference): at most the runs up to its step limit.
        return sum(self.run_seconds("rk4", d, window) for d in rk4_reference_dts(min(dts), window, min_steps))


def rk4_reference_dts(finest_dt: float, duration: float, min_steps: int | None = None) -> list[float]:
    """The step sizes :func:`animsim.analysis.references.rk4_reference` runs when it does
    not converge early (the most it may cost)."""
    dt = finest_dt / FINE_START_DIVISOR
    steps = Clock.make(duration, dt).steps
    finest_steps = max(1, steps // FINE_START_DIVISOR)
    floor = FINE_MIN_STEPS if min_steps is None else min_steps
    limit = min(FINE_MAX_STEPS, max(floor, FINE_MAX_FACTOR * finest_steps))
    out = [dt]
    while True:
        dt /= 2
        out.append(dt)
        if Clock.make(duration, dt).steps * 2 > limit:
            return out


@dataclass(frozen=True)
class Estimate:
    """What a comparison will cost, from a short timed probe of the scene."""

    seconds: float  # rows and reference together, s
    runs: int
    steps: int  # steps of every row run together
    backend: str  # what the rows run on (numba, or numpy when numba cannot run the scene)
    rows: float = 0.0  # s
    reference: float = 0.0  # s
    reference_kind: str = ""

    def describe(self) -> str:
        ref = (
            f"; the {self.reference_kind} reference about {_duration(self.reference)}"
            if self.reference_kind and self.reference_kind != "analytic"
            else ""
        )
        return (
            f"{self.runs} runs, {self.steps:,} steps on {self.backend}: "
            f"about {_duration(self.seconds)} in all{ref}"
        )


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{max(seconds, 0.1):.2g} s" if seconds < 10 else f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min"


def _reference_kind(base: Compiled, reference: str, name: str) -> str:
    """Which reference :func:`compare` will use (the same decision, made early, so
    that ``--reference analytic`` on a scene without a closed form is refused first)."""
    if reference in ("auto", "analytic"):
        try:
            analytic_reference(base, np.array([0.0, base.clock.duration]))
            return "analytic"
        except NoClosedForm as exc:
            if reference == "analytic":
                raise _no_closed_form(name, exc) from None
    return "DOP853" if smooth(base) else "RK4"


def _curve(full: Compiled, deadline: float, run: Any, sink: Any) -> tuple[np.ndarray, np.ndarray, bool]:
    """(simulated time, loop wall time, reached the end) of one run of ``full`` until ``deadline``."""
    clock = full.clock
    samples_t, samples_w = [0.0], [0.0]
    loop_start: list[float] = []

    def seen(k: int, _total: int) -> None:
        now = time.perf_counter()
        if not loop_start:  # the first stretch: the loop started before it, so take its rate
            loop_start.append(now)
            samples_t.append(clock.time(k))
            samples_w.append(0.0)
            return
        samples_t.append(clock.time(k))
        samples_w.append(now - loop_start[0])

    with np.errstate(all="ignore"):
        result = run(full, [sink()], stop=lambda: time.perf_counter() > deadline, progress=seen)
    t = np.array(samples_t)
    w = np.array(samples_w)
    if len(t) >= 3 and t[1] > 0:
        # The first stretch was not timed (no stamp before it): give it the rate of the next.
        rate = w[2] / max(t[2] - t[1], 1e-300)
        w[1:] += rate * t[1]
    elif result.steps_taken:
        t = np.array([0.0, clock.time(result.steps_taken)])
        w = np.array([0.0, result.wall_time])
    else:
        t, w = np.array([0.0]), np.array([0.0])
    return t, w, result.steps_taken >= clock.steps


def probe(
    scene: m.Scene,
    name: str,
    *,
    integrators: Sequence[str],
    reference: str = "auto",
    backend: str = "numpy",
    notice: Callable[[str], None] | None = None,
    seconds: float | None = None,
) -> Probe:
    """Time the scene itself on ``backend``: each method over its first steps, then one
    method as far as ``PROBE_SECONDS`` of wall time take it (or to the end), and the
    DOP853 reference's first solve the same way when the reference will be one.

    Every method runs once before it is timed, so numba's compiling (reported as
    ``compile_seconds``, never estimated) and NumPy's warm-up are not counted.
    """

    budget = PROBE_SECONDS if seconds is None else seconds
    began = time.perf_counter()
    scene = scene.model_copy(update={"integrator": scene.integrator_name})
    dt = scene.dt
    first_steps = min(PROBE_STEPS, Clock.make(scene.duration, dt).steps)
    short = min(scene.duration, first_steps * dt)
    method = scene.integrator_name if scene.integrator_name in integrators else integrators[0]
    base = record_at(scene, name, method, dt, np.array([0.0, scene.duration]), "numpy")
    kind = _reference_kind(base, reference, name)
    extra = ["rk4"] if kind == "RK4" else []  # what the RK4 reference's steps cost
    methods = list(dict.fromkeys([*integrators, *extra]))
    compile_seconds = 0.0
    per_step: dict[str, float] = {}
    chosen = "numpy"
    setups = []
    overheads: list[float] = []
    for integ in methods:
        probe_scene = with_overrides(scene, integrator=integ, dt=dt, duration=short)
        t0 = time.perf_counter()
        compiled = record_at(probe_scene, name, integ, dt, np.array([0.0, short]), backend)
        setups.append(time.perf_counter() - t0)
        chosen = compiled.backend if compiled.backend != "numpy" else chosen
        with np.errstate(all="ignore"):
            # One stretch, to compile: all of its time counts as compiling, since
            # some kernels compile on their first call, inside the loop's time.
            t0 = time.perf_counter()
            warm = run(compiled, [], notice=notice, stop=lambda: True)
            compile_seconds += max(time.perf_counter() - t0, float(warm.meta.get("compile_time", 0.0)))
            # The fastest of at least two runs: a kernel that compiles on its first
            # call later on (the first birth, the first contact) lands in the first.
            until = time.perf_counter() + PROBE_METHOD_SECONDS
            runs: list[tuple[float, int]] = []
            while len(runs) < 2 or time.perf_counter() < until:
                deadline = time.perf_counter() + PROBE_METHOD_SECONDS
                t0 = time.perf_counter()
                result = run(compiled, [], stop=lambda d=deadline: time.perf_counter() > d)
                overheads.append(max(0.0, time.perf_counter() - t0 - result.wall_time))
                runs.append((result.wall_time, max(result.steps_taken, 1)))
        per_step[integ] = min(wall / steps for wall, steps in runs)
        wall, steps = runs[0]
        compile_seconds += max(0.0, wall - per_step[integ] * steps)  # what the first run paid extra

    # One method through as much of the scene as the probe's time allows. A run
    # that reaches the end quickly is repeated and the fastest kept: on a busy
    # machine a run of a few milliseconds can lose a whole time slice.
    full = compile_scene(with_overrides(scene, integrator=method), name, backend=backend)
    # Recording frames can take code paths the bare runs above did not (some
    # compile on their first call): one stretch first, counted as compiling.
    t0 = time.perf_counter()
    with np.errstate(all="ignore"):
        run(full, [MemorySink()], stop=lambda: True)
    compile_seconds += time.perf_counter() - t0
    curve_start = time.perf_counter()
    deadline = curve_start + budget
    best: tuple[np.ndarray, np.ndarray] | None = None
    while True:
        t, w, finished = _curve(full, deadline, run, MemorySink)
        if best is None or (len(t) == len(best[0]) and w[-1] < best[1][-1]):
            best = (t, w)
        if not finished or time.perf_counter() > curve_start + budget / 3 or len(t) < 2:
            break
    t, w = best
    if len(t) < 2 or t[-1] <= 0:  # nothing ran (a zero-step scene): the short probe's rate stands in
        t = np.array([0.0, short])
        w = np.array([0.0, per_step[method] * first_steps])

    dop = None
    if kind == "DOP853":
        dop = dop853_rate(base, PROBE_REFERENCE_SECONDS)
        # a reference of minutes is timed longer: DOP853's pace settles over seconds as its
        # step shrinks to the scene's stiffness (a few per cent of what it predicts, at most
        # LONG_REFERENCE_PROBE s)
        whole = scene.duration * dop[1] / max(dop[0], 1e-300)
        if whole > LONG_REFERENCE:
            dop = dop853_rate(base, min(LONG_REFERENCE_PROBE, LONG_REFERENCE_SHARE * whole))
    return Probe(
        backend=chosen,
        method=method,
        dt=full.clock.dt,
        duration=scene.duration,
        curve_t=t,
        curve_w=w,
        per_step=per_step,
        # the least: the first compiles also pay imports and numba kernels that later ones do not
        setup=min(setups),
        compile_seconds=compile_seconds,
        seconds=time.perf_counter() - began,
        reference_kind=kind,
        dop853=dop,
        grows=full.emitters is not None,
        # the median: the first runs of a method may still load what later ones find ready
        overhead=statistics.median(overheads) if overheads else 0.0,
    )


def estimate_from(
    probe_: Probe,
    integrators: Sequence[str],
    dts: Sequence[float],
    window: float,
    repeat: int,
    jobs: int = 1,
    fine_min_steps: int | None = None,
) -> Estimate:
    """The cost of running ``integrators`` x ``dts`` over ``window`` seconds, as ``probe_`` predicts."""
    rows = sum(
        probe_.run_seconds(integ, d, window) * (1 + repeat) - probe_.setup * repeat
        for integ in integrators
        for d in dts
    )
    rows /= max(1, jobs)
    ref = probe_.reference_seconds(dts, window, fine_min_steps)
    total_steps = sum(Clock.make(window, d).steps for d in dts)
    return Estimate(
        seconds=rows + ref,
        runs=len(integrators) * len(dts) * (1 + repeat),
        steps=total_steps * len(integrators) * (1 + repeat),
        backend=probe_.backend,
        rows=rows,
        reference=ref,
        reference_kind=probe_.reference_kind,
    )


def estimate(
    scene: m.Scene,
    name: str,
    *,
    integrators: Sequence[str],
    dts: Sequence[float],
    repeat: int = DEFAULT_REPEAT,
    backend: str = "numpy",
    reference: str = "auto",
    notice: Callable[[str], None] | None = None,
) -> Estimate:
    """The cost of comparing ``integrators`` at ``dts`` over the whole scene (see :func:`probe`)."""
    found = probe(scene, name, integrators=integrators, reference=reference, backend=backend, notice=notice)
    return estimate_from(found, integrators, dts, scene.duration, repeat)


@dataclass
class Plan:
    """What ``compare`` will run, why, and what it should cost."""

    integrators: list[str]
    dts: list[float]
    window: float  # the compared stretch from t = 0, s
    duration: float  # the scene's, s
    repeat: int
    estimate: Estimate | None  # None when nobody asked (no budget, nothing to announce)
    probe: Probe | None
    budget: float | None
    #: what was left out of the default plan to fit the budget, in words
    cuts: list[str] = field(default_factory=list)
    #: the RK4 reference's least step allowance (None: its own, FINE_MIN_STEPS)
    fine_min_steps: int | None = None

    @property
    def run_budget(self) -> float | None:
        """What the budget leaves for the runs: the probe's own time (compiling aside) is spent."""
        if self.budget is None:
            return None
        spent = 0.0 if self.probe is None else self.probe.seconds - self.probe.compile_seconds
        return max(self.budget - spent, MIN_RUN_BUDGET * self.budget)

    @property
    def over_budget(self) -> bool:
        budget = self.run_budget
        return budget is not None and self.estimate is not None and self.estimate.seconds > budget

    def lines(self) -> list[str]:
        """What ``animsim compare`` says before it starts."""
        over = (
            ""
            if self.window >= self.duration
            else f" over the first {self.window:g} s of {self.duration:g} s"
        )
        head = f"comparing {len(self.integrators)} methods at {len(self.dts)} step sizes{over}"
        if self.estimate is None or self.probe is None:
            return [head]
        out = [f"{head}: {self.estimate.describe()}"]
        probe_ = self.probe
        compiled = (
            f", numba compiling {probe_.compile_seconds:.1f} s wall" if probe_.backend == "numba" else ""
        )
        out.append(
            f"  (from a probe of this scene: {probe_.seconds:.1f} s wall{compiled}, not in the estimate)"
        )
        if self.cuts:
            out.append(
                f"  to fit the time budget of {self.budget:g} s (--budget; the probe's time counts), "
                "the default plan was cut: " + "; ".join(self.cuts)
            )
            if self.over_budget:
                out.append(
                    "  even so it is over the budget: this is the smallest plan compare makes by itself"
                )
            out.append(
                "  --integrators, --dt and --duration choose these yourself; --budget 0 runs everything"
            )
        elif self.over_budget:
            out.append(
                f"  note: that is longer than the time budget of {self.budget:g} s (--budget); "
                "the options given are run as given"
            )
        return out


def _core_methods(scene: m.Scene, available: Sequence[str]) -> list[str]:
    """CORE_INTEGRATORS, plus the scene's own method (the one a user cares about first)."""
    core = [name for name in CORE_INTEGRATORS if name in available]
    own = scene.integrator_name
    if own in available and own not in core:
        core.append(own)
    return [name for name in available if name in core]


def make_plan(
    scene: m.Scene,
    name: str,
    *,
    integrators: Sequence[str] | None = None,
    dts: Sequence[float] | None = None,
    duration: float | None = None,
    repeat: int = DEFAULT_REPEAT,
    reference: str = "auto",
    budget: float | None = DEFAULT_BUDGET,
    backend: str = "numpy",
    jobs: int = 1,
    max_steps: int = DEFAULT_MAX_STEPS,
    notice: Callable[[str], None] | None = None,
    estimate: bool = True,
) -> Plan:
    """Probe the scene and choose what to run.

    What the caller names (``integrators``, ``dts``, ``duration``) is run as
    named. What is left to the default is cut, in this order, until the
    estimate fits ``budget`` seconds (None or 0: no budget): the finest of the
    four default step sizes; then the compared window, down to half the
    scene; then the methods, to CORE_INTEGRATORS and the scene's own; then the
    window again, down to MIN_WINDOW_STEPS steps of the largest dt.
    """
    if repeat < 0:
        raise UsageError(f"--repeat: must be >= 0, not {repeat}")
    if budget is not None and not (math.isfinite(budget) and budget >= 0):
        raise UsageError(f"--budget: must be a number of seconds >= 0, not {budget!r}")
    budget = budget or None
    total = scene.duration
    if duration is not None:
        if not (math.isfinite(duration) and duration > 0):
            raise UsageError(f"--duration: must be a finite number > 0, not {duration!r}")
        if duration > total:
            raise UsageError(f"--duration: {duration:g} is longer than the scene ({total:g} s)")
    window_given = duration is not None
    window = duration if duration is not None else total
    for v in dts or ():
        if v > window:
            raise UsageError(f"--dt: {v:g} is longer than the duration {window!r}")
    if dts:  # refused before the probe runs
        common_times(window_scene(scene, window), dts, max_steps)
    all_methods = list(integrators) if integrators else parse_integrators(None)
    method_sets = [all_methods]
    if not integrators:
        core = _core_methods(scene, all_methods)
        if core != all_methods:
            method_sets.append(core)
    if dts:
        dt_sets = [sorted(set(dts), reverse=True)]
    else:
        full_dts = default_dts(scene.dt, window)
        dt_sets = [full_dts, full_dts[:-1]]
    if budget is None and not estimate:  # nothing to fit and nobody to tell: no probe
        common_times(window_scene(scene, window), dt_sets[0], max_steps)
        return Plan(all_methods, dt_sets[0], window, total, repeat, None, None, None)
    found = probe(scene, name, integrators=all_methods, reference=reference, backend=backend, notice=notice)
    asked = budget
    if budget is not None:  # the probe has spent part of it
        budget = Plan([], [], 0.0, 0.0, 0, None, found, budget).run_budget
    floors: list[int | None] = [None]
    if found.reference_kind == "RK4" and not (integrators and dts):
        floors.append(0)  # the RK4 reference held to FINE_MAX_FACTOR times the finest run's steps

    def cost(methods: Sequence[str], steps: Sequence[float], w: float, floor: int | None) -> Estimate:
        return estimate_from(found, methods, steps, w, repeat, jobs, floor)

    def fits(level: tuple[list[str], list[float], int | None], w: float) -> bool:
        return budget is None or cost(*level[:2], w, level[2]).seconds <= budget

    def plan(level: tuple[list[str], list[float], int | None], w: float) -> Plan:
        methods, steps, floor = level
        common_times(window_scene(scene, w), steps, max_steps)  # refuses too many steps now
        cuts = []
        if floor is not None:
            cuts.append(
                f"the RK4 reference may take at most {FINE_MAX_FACTOR} times the finest run's steps "
                "(a note says so if it has not converged by then)"
            )
        if len(steps) < len(dt_sets[0]):
            sizes = ", ".join(f"{d:g}" for d in steps)
            cuts.append(f"{len(steps)} step sizes ({sizes} s) instead of {len(dt_sets[0])}")
        if len(methods) < len(all_methods):
            cuts.append(f"the methods {', '.join(methods)} instead of all {len(all_methods)}")
        if w < total and not window_given:
            events = _events(scene)
            cuts.append(
                f"compared over the first {w:g} s of {total:g} s"
                + (
                    f" (the {', '.join(events)} after it are not compared; --duration sets the window)"
                    if events
                    else ""
                )
            )
        return Plan(
            list(methods),
            list(steps),
            w,
            total,
            repeat,
            cost(methods, steps, w, floor),
            found,
            asked,
            cuts,
            floor,
        )

    def longest_window(level: tuple[list[str], list[float], int | None], shortest: float) -> float | None:
        """The longest window on the ladder (window_ladder), >= shortest, whose plan fits (None: none).

        The rungs are a factor of 2 apart, so the probe's timing noise cannot move the window
        a little on every rerun: a rerun gives the same window unless the estimate crosses
        the budget at a rung."""
        times, _ = common_times(scene, level[1], DEFAULT_MAX_STEPS * 1000)
        for w in window_ladder(times, total, shortest):
            if fits(level, w):
                return w
        return None

    first = (method_sets[0], dt_sets[0], None)
    # Everything named, or no budget: run as asked (the estimate says what it costs).
    if budget is None or (integrators and dts and window_given):
        return plan(first, window)
    # 1. the whole window, cutting as little as possible: the reference's floor,
    #    the finest step size, the methods
    levels = [first]
    levels += [(method_sets[0], dt_sets[0], f) for f in floors[1:]]
    levels += [(method_sets[0], ds, floors[-1]) for ds in dt_sets[1:]]
    levels += [(ms, dt_sets[-1], floors[-1]) for ms in method_sets[1:]]
    for level in levels:
        if fits(level, window):
            return plan(level, window)
    if window_given:  # the window was named: it stays, and the plan says it is over budget
        return plan(levels[-1], window)
    # 2. every method still, the fewest step sizes, over at least half the scene
    coarse = max(dt_sets[-1])
    shortest = min(total, MIN_WINDOW_STEPS * coarse)
    level = (method_sets[0], dt_sets[-1], floors[-1])
    w = longest_window(level, max(shortest, 0.5 * total))
    if w is not None:
        return plan(level, w)
    # 3. the fewest methods too, over as much of the scene as fits
    level = levels[-1]
    w = longest_window(level, shortest)
    if w is None:  # nothing fits: the smallest plan, which says it is over budget
        times, _ = common_times(scene, level[1], DEFAULT_MAX_STEPS * 1000)
        w = next((float(t) for t in times if t >= shortest - 1e-12 and t > 0), total)
    return plan(level, w)


def _events(scene: m.Scene) -> list[str]:
    """What a scene does at moments of its own that a window cut short may leave out."""
    out = []
    if scene.planes or scene.colliders or scene.particle_collisions is not None or scene.bodies:
        out.append("contacts")
    if scene.emitters:
        out.append("births")
    if any(sp.max_strain is not None for sp in scene.springs) or any(
        getattr(s, "max_strain", None) is not None
        or any(
            getattr(f, "max_strain", None) is not None
            for f in vars(s).values()
            if isinstance(f, m.SpringFamily)
        )
        for s in scene.structures
    ):
        out.append("tearing")
    return out


def window_ladder(times: np.ndarray, total: float, shortest: float) -> list[float]:
    """The windows a budget may cut the comparison to, longest first: total / 2^k, each
    taken down to the record time at or before it, none shorter than ``shortest``."""
    record = np.asarray([t for t in times if t > 0], dtype=np.float64)
    out: list[float] = []
    w = total
    while record.size:
        at = record[record <= w * (1 + 1e-12)]
        if not at.size or at[-1] < shortest - 1e-12:
            break
        if not out or at[-1] < out[-1]:
            out.append(float(at[-1]))
        w /= 2
    if not out or out[-1] > shortest + 1e-12:  # the shortest window itself is the last rung
        first = record[record >= shortest - 1e-12]
        if first.size and (not out or first[0] < out[-1]):
            out.append(float(first[0]))
    return out


def window_scene(scene: m.Scene, duration: float) -> m.Scene:
    """The scene cut to its first ``duration`` seconds (itself when that is all of it)."""
    if duration >= scene.duration:
        return scene
    return with_overrides(scene, duration=duration)


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
    plan = comparison.plan
    if plan is not None:
        for cut in plan.cuts:
            lines.append(f"note: to fit the time budget of {plan.budget:g} s: {cut}")
        est = plan.estimate
        if comparison.seconds is not None and est is not None and plan.probe is not None:
            ref = ""
            if est.reference_kind != "analytic":
                ref = (
                    f" (the reference {comparison.reference_seconds:.1f} s wall, "
                    f"estimated about {_duration(est.reference)})"
                )
            lines.append(
                f"took {comparison.seconds:.1f} s wall, estimated about {_duration(est.seconds)}{ref}; "
                f"the probe before it {plan.probe.seconds:.1f} s wall"
            )
    return lines


def run_planned(
    scene: m.Scene,
    name: str,
    *,
    integrators: Sequence[str] | None = None,
    dts: Sequence[float] | None = None,
    duration: float | None = None,
    reference: str = "auto",
    repeat: int = DEFAULT_REPEAT,
    budget: float | None = DEFAULT_BUDGET,
    backend: str = "numpy",
    jobs: int = 1,
    scheduler: Any = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    progress: Callable[[str], None] | None = None,
    notice: Callable[[str], None] | None = None,
    on_plan: Callable[[Plan], None] | None = None,
) -> Comparison:
    """Plan (:func:`make_plan`: probe the scene, fit ``budget``), tell ``on_plan``, then
    :func:`compare` what the plan chose; the result holds the plan and the time taken."""

    if reference not in REFERENCE_KINDS:
        raise UsageError(f"--reference: {reference!r} is not one of {', '.join(REFERENCE_KINDS)}")
    plan = make_plan(
        scene,
        name,
        integrators=integrators,
        dts=dts,
        duration=duration,
        repeat=repeat,
        reference=reference,
        budget=budget,
        backend=backend,
        jobs=jobs,
        max_steps=max_steps,
        notice=notice,
        estimate=budget is not None or on_plan is not None,
    )
    if on_plan is not None:
        on_plan(plan)
    start = time.perf_counter()
    result = compare(
        window_scene(scene, plan.window),
        name,
        integrators=plan.integrators,
        dts=plan.dts,
        reference=reference,
        repeat=repeat,
        progress=progress,
        max_steps=max_steps,
        jobs=jobs,
        scheduler=scheduler,
        backend=backend,
        fine_min_steps=plan.fine_min_steps,
    )
    result.seconds = time.perf_counter() - start
    result.plan = plan
    return result
