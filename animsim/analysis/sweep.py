"""``animsim sweep``: one scene, the Cartesian product of overrides, one table.

What a sweep is
---------------
Each ``--set KEY=V1,V2,...`` is an axis: ``KEY`` is a dotted path into the
scene's data as written in the file (``springs.0.ks``,
``structures.0.structural.ks``, ``dt``, ``integrator``, ``record.fps``; a
number segment indexes a list), and the values are read by the same YAML 1.2
rules as the file (``1e4`` is a number, ``auto`` a string, ``[0, 1]`` a
list; commas inside brackets or quotes do not split values).
``--integrators a,b`` is the axis ``integrator``. The cases are the product
of the axes, the first axis outermost, numbered from 0 in that order.

Every case is the scene's data with its values put in and then validated
again by the very models and cross-field rules that validate a file, so a
sweep cannot run a scene the file format would refuse:

* a key that does not exist at all (a list index past the end, an unknown
  key name, a path through a number) is a usage error before anything runs
  (exit 2, with a did-you-mean): it would be wrong in every case;
* a value that the rules refuse (``dt`` longer than ``duration``, a negative
  ``ks``) makes that case a row with status ``invalid`` and the message; the
  other cases run.

Missing sections on the way are created (``record.fps`` on a scene without
``record``, ``structures.0.shear.ks`` adds the shear family). ``integrator``
on a scene whose integrator is a mapping (``{method, adaptive}``) replaces
its ``method`` and keeps the adaptive settings.

Random streams
--------------
Each case's ``seed`` is drawn from the scene's seed and the case's index:
``SeedSequence(scene_seed, spawn_key=(index,))``, its first 64-bit word
shifted right by one (seeds are < 2**63). The case runs exactly as
``animsim run --seed <that seed>`` with its overrides would, wherever it runs,
so a serial sweep, ``--jobs N`` and a Dask cluster give the same rows. A swept
``seed`` axis wins: its value is used as given. (The seed follows the case's
place in the grid, so adding a value to an axis renumbers the cases.)

The row
-------
``case``, one column per axis, ``integrator`` (when not swept), ``seed``,
``status`` (``ok``, ``unstable``, ``invalid``, ``error``: an unexpected
exception), ``steps`` taken, ``force_evals``, ``energy_end`` (J),
``drift`` ((E_end - E_start)/|E_start|, the ``check`` definition), ``error``
(with a reference), ``wall_time`` (s, simulation loop only), and for an
unstable run where it failed: ``at_step``, ``at_time``, ``particle``; and
``message``. ``error`` is the largest distance (m) between the case's and the
reference's particle positions over their common record times; it is left
empty for a case that did not finish ``ok`` (an unstable run has no
meaningful error).

References
----------
:data:`REFERENCES` maps a name to a function ``(compiled case, record
times) -> Trajectory``; ``fine`` (RK4 at the case's dt / 16, recording every
step and keeping the case's record times) is built in. When issue 4's
``animsim.analysis.references`` is present, ``analytic`` uses its closed
forms and ``auto`` tries them first; otherwise ``auto`` means ``fine``.
"""

from __future__ import annotations

import copy
import csv
import io
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from animsim.analysis.check import energy_drift
from animsim.analysis.references import NoClosedForm, Trajectory, analytic_reference, run_trajectory
from animsim.atomic import AtomicFile
from animsim.compile import compile_scene
from animsim.engine import STATUS_OK, STATUS_UNSTABLE, run
from animsim.errors import AnimsimError, UsageError
from animsim.parallel import map_cases
from animsim.record import Clock, MemorySink, landing_steps
from animsim.scene.loader import mesh_problems
from animsim.scene.messages import diagnostics, method_from_option
from animsim.scene.models import DEFAULT_INTEGRATOR, Scene
from animsim.scene.validate import check_scene
from animsim.scene.yaml_reader import Marks, parse_yaml

# --- names and constants -----------------------------------------------------------

INTEGRATOR_KEY = "integrator"
SEED_KEY = "seed"
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
# Seeds must fit the scene's 0 <= seed <= 2**63 - 1.
SEED_SHIFT = 1

STAT_COLUMNS = ("status", "steps", "force_evals", "energy_end", "drift")
TAIL_COLUMNS = ("wall_time", "at_step", "at_time", "particle", "message")
ERROR_COLUMN = "error"


# --- axes ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Axis:
    """One swept key and its values, in the order given."""

    key: str
    values: tuple[Any, ...]


def split_values(text: str) -> list[str]:
    """Split ``V1,V2,...`` on the commas outside brackets and quotes."""
    parts: list[str] = []
    depth = 0
    quote: str | None = None
    start = 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts]


def parse_value(text: str, where: str) -> Any:
    """One value as the scene file would read it (YAML 1.2, same loader)."""
    if text == "":
        raise UsageError(f"{where}: an empty value")
    value, _ = parse_yaml(text, where)
    return value


def parse_set(text: str) -> Axis:
    """``KEY=V1,V2,...`` as an :class:`Axis` (usage error when malformed)."""
    key, sep, rest = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise UsageError(f"--set {text!r}: expected KEY=V1,V2,... (for example springs.0.ks=100,1000)")
    if any(seg == "" for seg in key.split(".")):
        raise UsageError(f"--set {text!r}: {key!r} is not a dotted key")
    where = f"--set {key}"
    values = tuple(parse_value(v, where) for v in split_values(rest))
    return Axis(key, values)


def integrators_axis(text: str) -> Axis:
    """``--integrators euler,rk4`` as the ``integrator`` axis (names checked up front)."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise UsageError("--integrators: give at least one name")
    return Axis(INTEGRATOR_KEY, tuple(method_from_option(n, "--integrators") for n in names))


def check_axes(axes: Sequence[Axis]) -> None:
    keys = [a.key for a in axes]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise UsageError(f"--set: {', '.join(sorted(dup))} is swept twice; give each key once")
    for a in axes:
        if not a.values:
            raise UsageError(f"--set {a.key}: no values")


# --- putting values into the scene data --------------------------------------------


class KeyPathError(UsageError):
    """A swept key that cannot exist in this scene (exit 2 before any run)."""


def set_path(data: dict[str, Any], key: str, value: Any) -> None:
    """Put ``value`` at the dotted ``key`` of ``data`` (in place; see the module docstring)."""
    path = key.split(".")
    node: Any = data
    for depth, seg in enumerate(path):
        last = depth == len(path) - 1
        here = ".".join(path[: depth + 1])
        if isinstance(node, list):
            if not seg.lstrip("-").isdigit():
                raise KeyPathError(
                    f"--set {key}: {'.'.join(path[:depth]) or 'the scene'} is a list; "
                    f"{seg!r} must be an index"
                )
            i = int(seg)
            if not 0 <= i < len(node):
                raise KeyPathError(
                    f"--set {key}: {here} does not exist ({'.'.join(path[:depth])} has {len(node)} entries)"
                )
            if last:
                node[i] = value
            else:
                node = node[i]
        elif isinstance(node, dict):
            if last:
                if key == INTEGRATOR_KEY and isinstance(node.get(seg), dict) and isinstance(value, str):
                    node[seg] = {**node[seg], "method": value}  # keep {adaptive: ...}
                else:
                    node[seg] = value
            else:
                if seg not in node or node[seg] is None:
                    node[seg] = {}  # a section the file left out
                node = node[seg]
        else:
            where = ".".join(path[:depth])
            raise KeyPathError(f"--set {key}: {where} is {node!r}, which has no key {seg!r}")


def validate_case_data(data: dict[str, Any], file: str, mesh_dirs: tuple[str, ...] = ()) -> Any:
    """The Scene for ``data`` by the file's rules; raises :class:`CaseInvalid`.

    ``mesh_dirs``: the folders besides the scene's own that its mesh files may lie under
    (``--mesh-dir``), as the loader was given them."""
    from pydantic import ValidationError

    try:
        scene = Scene.model_validate(data, context={"marks": True})
    except ValidationError as exc:
        # The loader's own wording (did-you-mean and all); marks are irrelevant
        # here since the values came from the command line.
        diags = diagnostics(exc, data, Marks(), file)
        raise CaseInvalid([(d.path, d.message) for d in diags]) from None
    problems = mesh_problems(scene, file, mesh_dirs) + check_scene(scene)  # meshes read as the loader does
    if problems:
        raise CaseInvalid([(".".join(map(str, p)), msg) for p, msg, _ in problems])
    return scene


class CaseInvalid(Exception):
    """A case whose values the scene rules refuse: ``problems`` is [(key path, message)]."""

    def __init__(self, problems: list[tuple[str, str]]):
        self.problems = problems
        super().__init__("; ".join(f"{p}: {m}" if p else m for p, m in problems))


def check_keys_exist(
    data: dict[str, Any], axes: Sequence[Axis], file: str, mesh_dirs: tuple[str, ...] = ()
) -> None:
    """Refuse, before any run, keys that exist in no case (see the module docstring)."""
    trial = copy.deepcopy(data)
    for a in axes:
        set_path(trial, a.key, a.values[0])
    try:
        validate_case_data(trial, file, mesh_dirs)
    except CaseInvalid as exc:
        # An unknown name anywhere on a swept key's path (springs.0.kss, or
        # structures.0.structual.ks, whose section set_path created) is wrong in every case.
        keys = [a.key for a in axes]
        unknown = [
            f"--set {k}: {m}" if k == p else f"--set {k}: {p}: {m}"
            for p, m in exc.problems
            if m.startswith("unknown key")
            for k in keys
            if k == p or k.startswith(p + ".")
        ]
        if unknown:
            raise KeyPathError("\n".join(unknown)) from None


# --- cases -------------------------------------------------------------------------------


def case_seed(scene_seed: int, index: int) -> int:
    """The seed of case ``index``: its own stream from the scene's seed (module docstring)."""
    word = np.random.SeedSequence(scene_seed, spawn_key=(index,)).generate_state(1, dtype=np.uint64)[0]
    return int(word) >> SEED_SHIFT


@dataclass(frozen=True)
class Case:
    """One run of the sweep: plain data, so it pickles to any worker."""

    index: int
    data: dict[str, Any]  # the scene's data as loaded (shared by every case; copied before use)
    name: str
    file: str
    overrides: tuple[tuple[str, Any], ...]
    seed: int
    reference: str | None = None
    #: the backend the case runs on (its reference too); see animsim.backends
    backend: str = "auto"
    #: folders besides the scene's own that its mesh files may lie under (--mesh-dir)
    mesh_dirs: tuple[str, ...] = ()


def build_cases(
    data: dict[str, Any],
    name: str,
    file: str,
    axes: Sequence[Axis],
    reference: str | None = None,
    backend: str = "auto",
    mesh_dirs: tuple[str, ...] = (),
) -> list[Case]:
    """The Cartesian product of ``axes`` (first outermost), each with its seed."""
    scene_seed = data.get(SEED_KEY, 0)
    scene_seed = scene_seed if isinstance(scene_seed, int) and scene_seed >= 0 else 0
    keys = [a.key for a in axes]
    cases = []
    for index, values in enumerate(itertools.product(*(a.values for a in axes))):
        overrides = tuple(zip(keys, values, strict=True))
        swept_seed = dict(overrides).get(SEED_KEY)
        seed = swept_seed if swept_seed is not None else case_seed(scene_seed, index)
        cases.append(Case(index, data, name, file, overrides, seed, reference, backend, mesh_dirs))
    return cases


def case_scene(case: Case) -> Any:
    """The validated Scene of one case; raises :class:`CaseInvalid`."""
    data = copy.deepcopy(case.data)
    for key, value in case.overrides:
        set_path(data, key, value)
    if SEED_KEY not in dict(case.overrides):
        data[SEED_KEY] = case.seed
    return validate_case_data(data, case.file, case.mesh_dirs)


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
    """One case's outcome (see the module docstring for the columns)."""

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


# --- output -------------------------------------------------------------------------------------


def csv_cell(value: Any) -> str:
    """A CSV cell: floats by repr (round trip), None and NaN empty, lists as YAML-ish text."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def to_csv(table: SweepTable) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = table.columns
    w.writerow(cols)
    for r in table.rows:
        w.writerow([csv_cell(r.value(c)) for c in cols])
    return buf.getvalue()


def write_csv(table: SweepTable, path: Path) -> None:
    f = AtomicFile(path, "w", newline="")
    try:
        f.handle.write(to_csv(table))
    except BaseException:
        f.abort()
        raise
    f.commit()


def display_cell(value: Any, column: str) -> str:
    """Short text for the printed table (the CSV keeps every digit)."""
    if value is None:
        return ""
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        if column == "drift":
            return f"{value:+.3g}"
        if column == "wall_time":
            return f"{value:.3f}"
        return f"{value:.3g}"
    return str(value)


# Columns worth a terminal's width; the CSV has all of them.
PRINT_HIDDEN = ("seed", "force_evals")


#: printed columns left out first when the screen is narrow (the CSV keeps every one)
NARROW_DROP_ORDER = ("particle", "at_time", "wall_time", "energy_end", "at_step", "steps", "case")


def _table(table: SweepTable, cols: Sequence[str]) -> Any:
    from rich import box
    from rich.table import Table

    t = Table(box=box.SIMPLE_HEAD, show_edge=False, header_style="bold", pad_edge=False)
    numeric = {"case", "steps", "energy_end", "drift", "error", "wall_time", "at_step", "at_time"}
    for c in cols:
        # no_wrap: a number is whole or its column is left out (see print_table)
        t.add_column(c, justify="right" if c in numeric else "left", no_wrap=True, overflow="fold")
    style = {"ok": None, "unstable": "red", STATUS_INVALID: "yellow", STATUS_ERROR: "magenta"}
    for r in table.rows:
        t.add_row(*(display_cell(r.value(c), c) for c in cols), style=style.get(r.status))
    return t


def printed_columns(table: SweepTable, width: int | None) -> list[str]:
    """The table's columns that fit ``width`` (None: all the printable ones).

    ``message`` is never a column (it is printed under the table, one line per
    case), and the least useful columns go first (:data:`NARROW_DROP_ORDER`).
    """
    from rich.console import Console

    cols = [c for c in table.columns if c not in PRINT_HIDDEN and c != "message"]
    for c in ("at_step", "at_time", "particle"):
        if all(r.value(c) is None for r in table.rows):
            cols.remove(c)
    if width is None:
        return cols
    measure = Console(width=10_000)
    drop = [c for c in NARROW_DROP_ORDER if c in cols]
    while measure.measure(_table(table, cols)).maximum > width and drop:
        cols.remove(drop.pop(0))
    return cols


def print_table(table: SweepTable, console: Any) -> None:
    """The table at the console's width, then each case's message (why it failed) on its own lines."""
    cols = printed_columns(table, console.width)
    console.print(_table(table, cols))
    hidden = [c for c in printed_columns(table, None) if c not in cols]
    if hidden:
        console.print(
            f"(left out at {console.width} columns: {', '.join(hidden)}; a wider window or -o FILE.csv has them)",
            highlight=False,
            markup=False,
        )
    for r in table.rows:
        if r.message:
            console.print(f"case {r.case}: {r.message}", highlight=False, markup=False)


# --- plot ----------------------------------------------------------------------------------------


# Columns that hold numbers and can go on the y axis of a plot.
PLOT_COLUMNS = ("energy_end", "drift", "error", "wall_time", "steps", "force_evals")
