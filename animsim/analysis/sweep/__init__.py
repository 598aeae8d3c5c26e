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

The package keeps: :mod:`~.cases` (axes, keys and cases), :mod:`~.runs`
(references, rows, running the cases into a table) and :mod:`~.output` (CSV,
the printed table, plot columns). Every name is importable from this package,
as it was when it was one module.
"""

from __future__ import annotations

# Every name the one-module sweep had (Trajectory too: tests reach it here).
from animsim.analysis.references import Trajectory
from animsim.analysis.sweep.cases import (
    INTEGRATOR_KEY,
    SEED_KEY,
    SEED_SHIFT,
    Axis,
    Case,
    CaseInvalid,
    KeyPathError,
    build_cases,
    case_scene,
    case_seed,
    check_axes,
    check_keys_exist,
    integrators_axis,
    parse_set,
    parse_value,
    set_path,
    split_values,
    validate_case_data,
)
from animsim.analysis.sweep.output import (
    NARROW_DROP_ORDER,
    PLOT_COLUMNS,
    PRINT_HIDDEN,
    csv_cell,
    display_cell,
    print_table,
    printed_columns,
    to_csv,
    write_csv,
)
from animsim.analysis.sweep.runs import (
    ERROR_COLUMN,
    FINE_CACHE_SIZE,
    FINE_DT_DIVISOR,
    FINE_INTEGRATOR,
    REFERENCE_CHOICES,
    REFERENCES,
    STAT_COLUMNS,
    STATUS_ERROR,
    STATUS_INVALID,
    TAIL_COLUMNS,
    TIME_MATCH_RTOL,
    ReferenceFailed,
    Row,
    SweepTable,
    error_row,
    fine_reference,
    position_error,
    reference_function,
    run_case,
    sweep,
)

__all__ = [
    "ERROR_COLUMN",
    "FINE_CACHE_SIZE",
    "FINE_DT_DIVISOR",
    "FINE_INTEGRATOR",
    "INTEGRATOR_KEY",
    "NARROW_DROP_ORDER",
    "PLOT_COLUMNS",
    "PRINT_HIDDEN",
    "REFERENCES",
    "REFERENCE_CHOICES",
    "SEED_KEY",
    "SEED_SHIFT",
    "STATUS_ERROR",
    "STATUS_INVALID",
    "STAT_COLUMNS",
    "TAIL_COLUMNS",
    "TIME_MATCH_RTOL",
    "Axis",
    "Case",
    "CaseInvalid",
    "KeyPathError",
    "ReferenceFailed",
    "Row",
    "SweepTable",
    "Trajectory",
    "build_cases",
    "case_scene",
    "case_seed",
    "check_axes",
    "check_keys_exist",
    "csv_cell",
    "display_cell",
    "error_row",
    "fine_reference",
    "integrators_axis",
    "parse_set",
    "parse_value",
    "position_error",
    "print_table",
    "printed_columns",
    "reference_function",
    "run_case",
    "set_path",
    "split_values",
    "sweep",
    "to_csv",
    "validate_case_data",
    "write_csv",
]
