"""A sweep's table as output: the CSV (every column, floats that round-trip,
written atomically) and the table printed at the terminal's width (short
numbers, the least useful columns left out first when the screen is narrow,
each case's message under it), and the columns a plot may put on its y axis.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from animsim.analysis.sweep.runs import STATUS_ERROR, STATUS_INVALID, SweepTable
from animsim.atomic import AtomicFile

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
