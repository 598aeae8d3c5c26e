"""What a comparison will cost on this machine: a short timed probe of the scene, and
the estimate of every run and the reference drawn from it.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.analysis.compare.options import DEFAULT_REPEAT, no_closed_form
from animsim.analysis.references import (
    FINE_MAX_FACTOR,
    FINE_MAX_STEPS,
    FINE_MIN_STEPS,
    FINE_START_DIVISOR,
    NoClosedForm,
    analytic_reference,
    dop853_rate,
    record_at,
    smooth,
)
from animsim.compile import Compiled, compile_scene, with_overrides
from animsim.engine import run
from animsim.record import Clock, MemorySink
from animsim.scene import models as m

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
            f"; the {self.reference_kind} reference about {duration_text(self.reference)}"
            if self.reference_kind and self.reference_kind != "analytic"
            else ""
        )
        return (
            f"{self.runs} runs, {self.steps:,} steps on {self.backend}: "
            f"about {duration_text(self.seconds)} in all{ref}"
        )


def duration_text(seconds: float) -> str:
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
                raise no_closed_form(name, exc) from None
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
        compiling, runs = _time_method(compiled, notice, overheads)
        compile_seconds += compiling
        per_step[integ] = min(wall / steps for wall, steps in runs)
        wall, steps = runs[0]
        compile_seconds += max(0.0, wall - per_step[integ] * steps)  # what the first run paid extra

    full = compile_scene(with_overrides(scene, integrator=method), name, backend=backend)
    compiling, t, w = _scene_curve(full, budget)
    compile_seconds += compiling
    if len(t) < 2 or t[-1] <= 0:  # nothing ran (a zero-step scene): the short probe's rate stands in
        t = np.array([0.0, short])
        w = np.array([0.0, per_step[method] * first_steps])

    dop = _dop853_pace(base, scene.duration) if kind == "DOP853" else None
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


def _time_method(
    compiled: Compiled, notice: Callable[[str], None] | None, overheads: list[float]
) -> tuple[float, list[tuple[float, int]]]:
    """One run to compile, then timed runs of ``compiled`` (each up to PROBE_METHOD_SECONDS);
    returns the seconds of the compiling run and (wall time, steps) of the timed ones, and
    appends what each timed run spent outside its loop to ``overheads``."""
    with np.errstate(all="ignore"):
        # One stretch, to compile: all of its time counts as compiling, since
        # some kernels compile on their first call, inside the loop's time.
        t0 = time.perf_counter()
        warm = run(compiled, [], notice=notice, stop=lambda: True)
        compiling = max(time.perf_counter() - t0, float(warm.meta.get("compile_time", 0.0)))
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
    return compiling, runs


def _scene_curve(full: Compiled, budget: float) -> tuple[float, np.ndarray, np.ndarray]:
    """(seconds spent compiling, simulated times, loop wall times) of ``full`` run for about
    ``budget`` seconds (:func:`_curve`)."""
    # One method through as much of the scene as the probe's time allows. A run
    # that reaches the end quickly is repeated and the fastest kept: on a busy
    # machine a run of a few milliseconds can lose a whole time slice.
    # Recording frames can take code paths the bare runs above did not (some
    # compile on their first call): one stretch first, counted as compiling.
    t0 = time.perf_counter()
    with np.errstate(all="ignore"):
        run(full, [MemorySink()], stop=lambda: True)
    compiling = time.perf_counter() - t0
    curve_start = time.perf_counter()
    deadline = curve_start + budget
    best: tuple[np.ndarray, np.ndarray] | None = None
    while True:
        t, w, finished = _curve(full, deadline, run, MemorySink)
        if best is None or (len(t) == len(best[0]) and w[-1] < best[1][-1]):
            best = (t, w)
        if not finished or time.perf_counter() > curve_start + budget / 3 or len(t) < 2:
            break
    return compiling, best[0], best[1]


def _dop853_pace(base: Compiled, duration: float) -> tuple[float, float]:
    """(simulated s reached, wall s) of the DOP853 reference's first solve (:func:`dop853_rate`)."""
    dop = dop853_rate(base, PROBE_REFERENCE_SECONDS)
    # a reference of minutes is timed longer: DOP853's pace settles over seconds as its
    # step shrinks to the scene's stiffness (a few per cent of what it predicts, at most
    # LONG_REFERENCE_PROBE s)
    whole = duration * dop[1] / max(dop[0], 1e-300)
    if whole > LONG_REFERENCE:
        dop = dop853_rate(base, min(LONG_REFERENCE_PROBE, LONG_REFERENCE_SHARE * whole))
    return dop


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
