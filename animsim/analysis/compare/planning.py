"""The plan: what ``compare`` runs so that it finishes within its time budget, and the
comparison run as planned.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.analysis.compare.costs import Estimate, Probe, estimate_from, probe
from animsim.analysis.compare.options import (
    DEFAULT_MAX_STEPS,
    DEFAULT_REPEAT,
    REFERENCE_KINDS,
    default_dts,
    parse_integrators,
)
from animsim.analysis.compare.plan import Plan
from animsim.analysis.compare.results import Comparison
from animsim.analysis.compare.runs import common_times, compare
from animsim.analysis.references import (
    FINE_MAX_FACTOR,
)
from animsim.compile import with_overrides
from animsim.errors import UsageError
from animsim.scene import models as m

#: with default options, compare plans its runs to take about this long (s):
#: with the probe, start-up and numba's compiling it finishes within 30 s
DEFAULT_BUDGET = 20.0
#: the methods kept when not every one fits the budget: first order, first
#: order symplectic, second order, fourth order (and the scene's own method)
CORE_INTEGRATORS = ("euler", "symplectic_euler", "midpoint", "rk4")
#: the compared window is never cut below this many steps of the largest dt
MIN_WINDOW_STEPS = 20


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
    _check_numbers(repeat, budget)
    budget = budget or None
    window = _checked_window(scene, duration, dts, max_steps)
    method_sets, dt_sets = _candidates(scene, integrators, dts, window)
    if budget is None and not estimate:  # nothing to fit and nobody to tell: no probe
        common_times(window_scene(scene, window), dt_sets[0], max_steps)
        return Plan(method_sets[0], dt_sets[0], window, scene.duration, repeat, None, None, None)
    found = probe(
        scene, name, integrators=method_sets[0], reference=reference, backend=backend, notice=notice
    )
    planner = _Planner(
        scene,
        found,
        all_methods=method_sets[0],
        all_dts=dt_sets[0],
        window_given=duration is not None,
        repeat=repeat,
        jobs=jobs,
        max_steps=max_steps,
        asked=budget,
        # the probe has spent part of the budget
        budget=None if budget is None else Plan([], [], 0.0, 0.0, 0, None, found, budget).run_budget,
    )
    floors: list[int | None] = [None]
    if found.reference_kind == "RK4" and not (integrators and dts):
        floors.append(0)  # the RK4 reference held to FINE_MAX_FACTOR times the finest run's steps
    named = bool(integrators and dts and duration is not None)
    return planner.choose(method_sets, dt_sets, floors, window, named=named)


def _check_numbers(repeat: int, budget: float | None) -> None:
    if repeat < 0:
        raise UsageError(f"--repeat: must be >= 0, not {repeat}")
    if budget is not None and not (math.isfinite(budget) and budget >= 0):
        raise UsageError(f"--budget: must be a number of seconds >= 0, not {budget!r}")


def _checked_window(
    scene: m.Scene, duration: float | None, dts: Sequence[float] | None, max_steps: int
) -> float:
    """The compared window (``duration``, else the whole scene), the step sizes named
    checked against it before the probe runs."""
    total = scene.duration
    if duration is not None:
        if not (math.isfinite(duration) and duration > 0):
            raise UsageError(f"--duration: must be a finite number > 0, not {duration!r}")
        if duration > total:
            raise UsageError(f"--duration: {duration:g} is longer than the scene ({total:g} s)")
    window = duration if duration is not None else total
    for v in dts or ():
        if v > window:
            raise UsageError(f"--dt: {v:g} is longer than the duration {window!r}")
    if dts:  # refused before the probe runs
        common_times(window_scene(scene, window), dts, max_steps)
    return window


def _candidates(
    scene: m.Scene, integrators: Sequence[str] | None, dts: Sequence[float] | None, window: float
) -> tuple[list[list[str]], list[list[float]]]:
    """(method sets, step-size sets), each the fullest first: the methods named, else every
    one and then the core ones; the step sizes named, else the four defaults and then three."""
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
    return method_sets, dt_sets


#: a candidate plan but for its window: (methods, step sizes, the RK4 reference's floor)
_Level = tuple[list[str], list[float], int | None]


@dataclass
class _Planner:
    """The probe's estimates weighed against the budget, and the plans they lead to."""

    scene: m.Scene
    found: Probe
    all_methods: list[str]  # the fullest method set
    all_dts: list[float]  # the fullest step-size set
    window_given: bool  # the window was named (--duration)
    repeat: int
    jobs: int
    max_steps: int
    asked: float | None  # the budget asked for
    budget: float | None  # what it leaves for the runs

    def cost(self, methods: Sequence[str], steps: Sequence[float], w: float, floor: int | None) -> Estimate:
        return estimate_from(self.found, methods, steps, w, self.repeat, self.jobs, floor)

    def fits(self, level: _Level, w: float) -> bool:
        return self.budget is None or self.cost(*level[:2], w, level[2]).seconds <= self.budget

    def choose(
        self,
        method_sets: list[list[str]],
        dt_sets: list[list[float]],
        floors: list[int | None],
        window: float,
        *,
        named: bool,
    ) -> Plan:
        """The least cut plan that fits (see make_plan); ``named``: everything was named."""
        first = (method_sets[0], dt_sets[0], None)
        # Everything named, or no budget: run as asked (the estimate says what it costs).
        if self.budget is None or named:
            return self.plan(first, window)
        # 1. the whole window, cutting as little as possible: the reference's floor,
        #    the finest step size, the methods
        levels: list[_Level] = [first]
        levels += [(method_sets[0], dt_sets[0], f) for f in floors[1:]]
        levels += [(method_sets[0], ds, floors[-1]) for ds in dt_sets[1:]]
        levels += [(ms, dt_sets[-1], floors[-1]) for ms in method_sets[1:]]
        for level in levels:
            if self.fits(level, window):
                return self.plan(level, window)
        if self.window_given:  # the window was named: it stays, and the plan says it is over budget
            return self.plan(levels[-1], window)
        # 2. every method still, the fewest step sizes, over at least half the scene
        total = self.scene.duration
        coarse = max(dt_sets[-1])
        shortest = min(total, MIN_WINDOW_STEPS * coarse)
        level = (method_sets[0], dt_sets[-1], floors[-1])
        w = self.longest_window(level, max(shortest, 0.5 * total))
        if w is not None:
            return self.plan(level, w)
        # 3. the fewest methods too, over as much of the scene as fits
        level = levels[-1]
        w = self.longest_window(level, shortest)
        if w is None:  # nothing fits: the smallest plan, which says it is over budget
            times, _ = common_times(self.scene, level[1], DEFAULT_MAX_STEPS * 1000)
            w = next((float(t) for t in times if t >= shortest - 1e-12 and t > 0), total)
        return self.plan(level, w)

    def plan(self, level: _Level, w: float) -> Plan:
        """The plan of ``level`` over the window ``w``, saying what was cut."""
        methods, steps, floor = level
        total = self.scene.duration
        common_times(window_scene(self.scene, w), steps, self.max_steps)  # refuses too many steps now
        cuts = []
        if floor is not None:
            cuts.append(
                f"the RK4 reference may take at most {FINE_MAX_FACTOR} times the finest run's steps "
                "(a note says so if it has not converged by then)"
            )
        if len(steps) < len(self.all_dts):
            sizes = ", ".join(f"{d:g}" for d in steps)
            cuts.append(f"{len(steps)} step sizes ({sizes} s) instead of {len(self.all_dts)}")
        if len(methods) < len(self.all_methods):
            cuts.append(f"the methods {', '.join(methods)} instead of all {len(self.all_methods)}")
        if w < total and not self.window_given:
            events = _events(self.scene)
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
            self.repeat,
            self.cost(methods, steps, w, floor),
            self.found,
            self.asked,
            cuts,
            floor,
        )

    def longest_window(self, level: _Level, shortest: float) -> float | None:
        """The longest window on the ladder (window_ladder), >= shortest, whose plan fits (None: none).

        The rungs are a factor of 2 apart, so the probe's timing noise cannot move the window
        a little on every rerun: a rerun gives the same window unless the estimate crosses
        the budget at a rung."""
        times, _ = common_times(self.scene, level[1], DEFAULT_MAX_STEPS * 1000)
        for w in window_ladder(times, self.scene.duration, shortest):
            if self.fits(level, w):
                return w
        return None


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
