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

The package's modules, each named for what it holds: ``options`` (the command's
options and their defaults), ``results`` (rows, order fits and the error measures),
``runs`` (the comparison itself), ``costs`` (the probe and the estimate), ``planning``
(what to run within the time budget) and ``tables`` (the CSV, the table and the lines
under it). Every public name of theirs is here too.
"""

from __future__ import annotations

from animsim.analysis.compare.costs import (
    LONG_REFERENCE,
    LONG_REFERENCE_PROBE,
    LONG_REFERENCE_SHARE,
    PROBE_METHOD_SECONDS,
    PROBE_REFERENCE_SECONDS,
    PROBE_SECONDS,
    PROBE_STEPS,
    Estimate,
    Probe,
    duration_text,
    estimate,
    estimate_from,
    probe,
    rk4_reference_dts,
)
from animsim.analysis.compare.options import (
    CLOSED_FORM_FAMILIES,
    DEFAULT_MAX_STEPS,
    DEFAULT_REPEAT,
    DEFAULT_STEP_FACTORS,
    REFERENCE_KINDS,
    default_dts,
    integrator_names,
    no_closed_form,
    parse_dt_option,
    parse_dts,
    parse_integrators,
)
from animsim.analysis.compare.plan import MIN_RUN_BUDGET, Plan
from animsim.analysis.compare.planning import (
    CORE_INTEGRATORS,
    DEFAULT_BUDGET,
    MIN_WINDOW_STEPS,
    make_plan,
    run_planned,
    window_ladder,
    window_scene,
)
from animsim.analysis.compare.results import (
    COLUMNS,
    ENERGY_FLOOR,
    ROUNDOFF_SAFETY,
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
from animsim.analysis.compare.runs import (
    ASYMPTOTIC_LIMIT,
    EMITTER_ORDER_CAP,
    REFERENCE_MARGIN,
    common_times,
    compare,
)
from animsim.analysis.compare.tables import left_out, summary_lines, table, table_columns, write_csv

__all__ = [
    "ASYMPTOTIC_LIMIT",
    "CLOSED_FORM_FAMILIES",
    "COLUMNS",
    "CORE_INTEGRATORS",
    "DEFAULT_BUDGET",
    "DEFAULT_MAX_STEPS",
    "DEFAULT_REPEAT",
    "DEFAULT_STEP_FACTORS",
    "EMITTER_ORDER_CAP",
    "ENERGY_FLOOR",
    "LONG_REFERENCE",
    "LONG_REFERENCE_PROBE",
    "LONG_REFERENCE_SHARE",
    "MIN_RUN_BUDGET",
    "MIN_WINDOW_STEPS",
    "PROBE_METHOD_SECONDS",
    "PROBE_REFERENCE_SECONDS",
    "PROBE_SECONDS",
    "PROBE_STEPS",
    "REFERENCE_KINDS",
    "REFERENCE_MARGIN",
    "ROUNDOFF_SAFETY",
    "STATUS_OK",
    "STATUS_UNSTABLE",
    "Comparison",
    "Estimate",
    "OrderFit",
    "Plan",
    "Probe",
    "Row",
    "common_times",
    "compare",
    "default_dts",
    "duration_text",
    "energy_error",
    "errors",
    "estimate",
    "estimate_from",
    "integrator_names",
    "left_out",
    "make_plan",
    "motion_scale",
    "no_closed_form",
    "observed_order",
    "parse_dt_option",
    "parse_dts",
    "parse_integrators",
    "probe",
    "rk4_reference_dts",
    "roundoff_floor",
    "run_planned",
    "summary_lines",
    "table",
    "table_columns",
    "window_ladder",
    "window_scene",
    "write_csv",
]
