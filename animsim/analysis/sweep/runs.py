"""Running a sweep: :func:`run_case` turns one case into a :class:`Row` (a bad
value or an instability is a row, never a raise), measuring its error against
a reference when asked (the fine RK4 reference, cached per process, or the
closed forms of :mod:`animsim.analysis.references`); :func:`sweep` checks the
keys, builds the cases and runs them serially, on processes or on Dask, into
a :class:`SweepTable`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.analysis.check import energy_drift
from animsim.analysis.references import NoClosedForm, Trajectory, analytic_reference, run_trajectory
from animsim.analysis.sweep.cases import (
    INTEGRATOR_KEY,
    SEED_KEY,
    Axis,
    Case,
    CaseInvalid,
    build_cases,
    case_scene,
    check_axes,
    check_keys_exist,
)
from animsim.compile import compile_scene
from animsim.engine import STATUS_OK, STATUS_UNSTABLE, run
from animsim.errors import AnimsimError, UsageError
from animsim.parallel import map_cases
from animsim.record import Clock, MemorySink, landing_steps
from animsim.scene.models import DEFAULT_INTEGRATOR

STATUS_INVALID = "invalid"
STATUS_ERROR = "error"
# The fine reference: RK4 at the case's dt divided by this. RK4's error falls
# as dt^4, so 16x finer is ~65000x more accurate than an RK4 case at that dt,
# and far more than any first- or second-order case.
FINE_DT_DIVISOR = 16
FINE_INTEGRATOR = "rk4"
# Two record times are the same instant when they differ by less than this
# fraction of the run's duration (the fine clock's times land on the case's
# bit for bit when dt divides the duration; this covers the shortened last step).
TIME_MATCH_RTOL = 1e-9

STAT_COLUMNS = ("status", "steps", "force_evals", "energy_end", "drift")
TAIL_COLUMNS = ("wall_time", "at_step", "at_time", "particle", "message")
ERROR_COLUMN = "error"

# --- references ------------------------------------------------------------------------


class ReferenceFailed(Exception):
    """The reference itself could not be computed (the row says so; the case stands)."""


# Fine references already computed in this process, by (fine scene, record times):
# cases that differ only in their integrator share one (serially, or per worker).
_FINE_CACHE: dict[tuple[str, str, bytes], Trajectory] = {}
FINE_CACHE_SIZE = 16


def _landed(compiled: Any, times: np.ndarray, fine_dt: float) -> np.ndarray:
    """The ``times`` that a clock of ``fine_dt`` steps lands on."""
    fine_clock = Clock.make(compiled.clock.duration, fine_dt)
    times = np.asarray(times, dtype=np.float64)
    hit = [s is not None for s in landing_steps(fine_clock, times)]
    return times[np.array(hit, dtype=bool)] if len(times) else times


def fine_reference(compiled: Any, times: np.ndarray) -> Trajectory:
    """RK4 at the case's dt / :data:`FINE_DT_DIVISOR` on the case's own scene, at ``times``."""
    fine_dt = compiled.clock.dt / FINE_DT_DIVISOR
    scene = compiled.scene.model_copy(update={"integrator": FINE_INTEGRATOR, "dt": fine_dt})
    # repr of a frozen pydantic model names every field: equal reprs, equal scenes.
    key = (repr(scene), compiled.name, np.asarray(times, dtype=np.float64).tobytes())
    if key in _FINE_CACHE:
        return _FINE_CACHE[key]
    # Record only the fine steps that land on the case's record times.
    fine = compile_scene(
        scene, compiled.name, backend=compiled.backend, record_times=_landed(compiled, times, fine_dt)
    )
    trajectory, status = run_trajectory(fine)
    if status != STATUS_OK:
        raise ReferenceFailed(f"the RK4 reference at dt = {fine_dt:.3g} s was {status}")
    if len(_FINE_CACHE) >= FINE_CACHE_SIZE:
        _FINE_CACHE.pop(next(iter(_FINE_CACHE)))
    _FINE_CACHE[key] = trajectory
    return trajectory


def _closed_form(kind: str) -> Callable[[Any, np.ndarray], Trajectory]:
    """The closed forms of :mod:`animsim.analysis.references` (shared with compare).

    ``auto`` falls back to the fine RK4 reference when the scene has none;
    ``analytic`` makes that case's row say why.
    """

    def reference(compiled: Any, times: np.ndarray) -> Trajectory:
        try:
            ref = analytic_reference(compiled, times)
        except NoClosedForm as exc:
            if kind == "auto":
                return fine_reference(compiled, times)
            raise ReferenceFailed(f"no closed form: {exc}") from None
        return ref.trajectory

    return reference


REFERENCES: dict[str, Callable[[Any, np.ndarray], Trajectory]] = {"fine": fine_reference}
REFERENCE_CHOICES = ("auto", "analytic", "fine")


def reference_function(name: str) -> Callable[[Any, np.ndarray], Trajectory]:
    """The reference called ``name``; usage error when this build does not have it."""
    if name in REFERENCES:
        return REFERENCES[name]
    if name in ("analytic", "auto"):
        return _closed_form(name)
    raise UsageError(f"--reference: unknown {name!r} (valid: {', '.join(REFERENCE_CHOICES)})")


def position_error(run: Trajectory, ref: Trajectory, duration: float) -> float:
    """Largest particle distance (m) over the common record times (NaN when none)."""
    tol = TIME_MATCH_RTOL * duration
    worst = math.nan
    for k, t in enumerate(run.times):
        j = np.flatnonzero(np.abs(ref.times - t) <= tol)
        if not len(j):
            continue
        a, b = run.position[k], ref.position[int(j[0])]
        if run.ids is None and ref.ids is None:
            if a.shape != b.shape:
                continue
            d = a - b
        else:
            ia = run.ids[k] if run.ids is not None else np.arange(len(a)).astype(str)
            ib = ref.ids[int(j[0])] if ref.ids is not None else np.arange(len(b)).astype(str)
            _, xa, xb = np.intersect1d(ia.astype(str), ib.astype(str), return_indices=True)
            d = a[xa] - b[xb]
        if len(d):
            e = float(np.sqrt(np.einsum("ij,ij->i", d, d)).max())
            worst = e if math.isnan(worst) else max(worst, e)
    return worst


# --- running one case ---------------------------------------------------------------------


@dataclass
class Row:
    """One case's outcome (see the package docstring for the columns)."""

    case: int
    overrides: dict[str, Any]
    integrator: str | None
    seed: int
    status: str
    steps: int | None = None
    force_evals: int | None = None
    energy_end: float | None = None
    drift: float | None = None
    error: float | None = None
    wall_time: float | None = None
    at_step: int | None = None
    at_time: float | None = None
    particle: str | None = None
    message: str = ""

    def value(self, column: str) -> Any:
        if column in self.overrides:
            return self.overrides[column]
        if column == INTEGRATOR_KEY:
            return self.integrator
        return getattr(self, column)


def _integrator_of(case: Case) -> str | None:
    """The integrator a case asks for, from its data and overrides (for invalid rows)."""
    over = dict(case.overrides)
    if INTEGRATOR_KEY in over:
        v = over[INTEGRATOR_KEY]
        return v if isinstance(v, str) else None
    v = case.data.get(INTEGRATOR_KEY, DEFAULT_INTEGRATOR)
    return v.get("method") if isinstance(v, dict) else v


def run_case(case: Case) -> Row:
    """Run one case to a :class:`Row`; a bad value or an instability is a row, never a raise.

    Module level and fed plain data, so process pools and Dask can ship it.
    """
    row = Row(case.index, dict(case.overrides), _integrator_of(case), case.seed, STATUS_INVALID)
    try:
        scene = case_scene(case)
        compiled = compile_scene(scene, case.name, backend=case.backend)
    except (CaseInvalid, AnimsimError) as exc:
        row.message = str(exc)
        return row
    row.integrator = compiled.integrator_name
    times = compiled.clock.time
    record_times = np.array([times(int(s)) for s in compiled.record_steps])
    sink = MemorySink() if case.reference else None
    # Overflow in a blowing-up run is a result (status unstable), not a warning to print.
    with np.errstate(all="ignore"):
        result = run(compiled, [sink] if sink is not None else [])
    row.status = result.status
    row.steps = result.steps_taken
    row.force_evals = result.force_evals
    row.energy_end = float(result.energy_end)
    with np.errstate(all="ignore"):
        row.drift = float(energy_drift(result.energy_start, result.energy_end))
    row.wall_time = result.wall_time
    if result.status == STATUS_UNSTABLE and result.failure is not None:
        f = result.failure
        row.at_step, row.at_time, row.particle = f.step, f.time, f.particle
        row.message = f.reason
    if case.reference and sink is not None and result.status == STATUS_OK:
        try:
            ref = reference_function(case.reference)(compiled, record_times)
            run_traj = Trajectory.from_sink(sink, compiled.emitters is None)
            row.error = position_error(run_traj, ref, scene.duration)
        except (ReferenceFailed, AnimsimError) as exc:
            row.message = f"reference: {exc}"
    return row


def error_row(case: Case, exc: BaseException) -> Row:
    """The row of a case whose run raised (a bug or a lost worker): status ``error``."""
    return Row(
        case.index,
        dict(case.overrides),
        _integrator_of(case),
        case.seed,
        STATUS_ERROR,
        message=f"{type(exc).__name__}: {exc}",
    )


# --- the table -------------------------------------------------------------------------------


@dataclass
class SweepTable:
    axes: list[Axis]
    rows: list[Row]
    reference: str | None

    @property
    def columns(self) -> list[str]:
        keys = [a.key for a in self.axes]
        cols = ["case", *keys]
        if INTEGRATOR_KEY not in keys:
            cols.append(INTEGRATOR_KEY)
        cols += [SEED_KEY, *STAT_COLUMNS]
        if self.reference:
            cols.append(ERROR_COLUMN)
        cols += list(TAIL_COLUMNS)
        return cols

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for r in self.rows:
            out[r.status] = out.get(r.status, 0) + 1
        return out


def sweep(
    data: dict[str, Any],
    name: str,
    file: str,
    axes: Sequence[Axis],
    *,
    reference: str | None = None,
    jobs: int = 1,
    scheduler: Any = None,
    progress: Callable[[int, int], None] | None = None,
    backend: str = "auto",
    mesh_dirs: tuple[str, ...] = (),
) -> SweepTable:
    """Check the keys, build the cases and run them on ``backend`` (serially, on processes or on Dask)."""
    check_axes(axes)
    check_keys_exist(data, axes, file, mesh_dirs)
    if reference is not None:
        reference_function(reference)  # an unknown or unavailable reference: exit 2 now
    cases = build_cases(data, name, file, axes, reference, backend, mesh_dirs)
    rows = map_cases(run_case, cases, jobs=jobs, scheduler=scheduler, on_error=error_row, progress=progress)
    return SweepTable(list(axes), rows, reference)
