"""The comparison written out: the CSV of ``-o``, the table and the lines under it
that ``animsim compare`` prints.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from animsim.analysis.compare.costs import duration_text
from animsim.analysis.compare.results import COLUMNS, STATUS_OK, Comparison, Row
from animsim.atomic import write_text_atomic
from animsim.console import sig


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
                    f"estimated about {duration_text(est.reference)})"
                )
            lines.append(
                f"took {comparison.seconds:.1f} s wall, estimated about {duration_text(est.seconds)}{ref}; "
                f"the probe before it {plan.probe.seconds:.1f} s wall"
            )
    return lines
