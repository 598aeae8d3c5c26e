"""The plot of a parameter sweep: a result column over one swept key (``animsim sweep --plot``)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from animsim.analysis.sweep import INTEGRATOR_KEY, Axis, Row, SweepTable

PLOT_SIZE = (7.0, 4.5)  # inches
PLOT_DPI = 120
# A log axis when every value is positive and they span at least this ratio.
LOG_SPAN = 10.0
UNSTABLE_MARKER = "x"


def _numbers(values: Sequence[Any]) -> np.ndarray | None:
    try:
        return np.array([float(v) for v in values])
    except (TypeError, ValueError):
        return None


def plot_table(table: SweepTable, path: Path, x: str, y: str) -> None:
    """``y`` over the swept key ``x``; one line per combination of the other axes.

    Cases that did not finish ``ok`` have no point on their line; they are
    marked with an ``x`` at the bottom of the plot so the stability edge shows.
    ``drift`` is plotted as its absolute value (log scale when it spans decades).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.transforms import blended_transform_factory

    others = [a.key for a in table.axes if a.key != x]
    groups: dict[tuple[str, ...], list[Row]] = {}
    for r in table.rows:
        groups.setdefault(tuple(repr(r.overrides[k]) for k in others), []).append(r)
    x_numeric = _numbers([r.overrides[x] for r in table.rows])
    x_labels = [str(v) for v in dict.fromkeys(repr(r.overrides[x]) for r in table.rows)]
    fig, ax = plt.subplots(figsize=PLOT_SIZE, dpi=PLOT_DPI)
    try:
        # x in data coordinates, y in axes coordinates: marks at the bottom edge.
        bottom = blended_transform_factory(ax.transData, ax.transAxes)
        plotted: list[float] = []
        for rows in groups.values():
            label = ", ".join(f"{k}={rows[0].overrides[k]}" for k in others) or y
            if x_numeric is not None:
                xp = np.array([float(r.overrides[x]) for r in rows])
            else:
                xp = np.array([x_labels.index(repr(r.overrides[x])) for r in rows], dtype=float)
            yp = np.array([_y_value(r, y) for r in rows])
            plotted += [v for v in yp if math.isfinite(v)]
            color, style = _line_look(rows[0], others, table.axes)
            (line,) = ax.plot(xp, yp, marker="o", label=label, color=color, linestyle=style)
            bad = [i for i, r in enumerate(rows) if r.status != "ok"]
            if bad:
                ax.plot(
                    xp[bad],
                    np.full(len(bad), BOTTOM_MARK_Y),
                    UNSTABLE_MARKER,
                    color=line.get_color(),
                    transform=bottom,
                    markersize=9,
                    clip_on=False,
                )
        if x_numeric is None:
            ax.set_xticks(range(len(x_labels)), x_labels)
        elif _spans_decades(x_numeric):
            ax.set_xscale("log")
        if plotted and _spans_decades(np.array(plotted)):
            ax.set_yscale("log")
        ax.set_xlabel(x)
        ax.set_ylabel("|drift|" if y == "drift" else y)
        ax.set_title(f"{y} over {x}  ({UNSTABLE_MARKER} on the axis: run not ok)")
        ax.grid(True, which="both", alpha=0.3)
        if others:
            ax.legend(fontsize="small")
        fig.tight_layout()
        fig.savefig(path)
    finally:
        plt.close(fig)


BOTTOM_MARK_Y = 0.02  # axes fraction
LINE_STYLES = ("-", "--", ":", "-.")


def _line_look(row: Row, others: list[str], axes: Sequence[Axis]) -> tuple[str | None, str]:
    """Colour by integrator and line style by the other keys, when the integrator is swept,
    so that "which method" reads at a glance; otherwise matplotlib's colour cycle."""
    if INTEGRATOR_KEY not in others:
        return None, LINE_STYLES[0]
    by_key = {a.key: a for a in axes}
    color = f"C{by_key[INTEGRATOR_KEY].values.index(row.overrides[INTEGRATOR_KEY]) % 10}"
    rest = [k for k in others if k != INTEGRATOR_KEY]
    combos = list(itertools.product(*(range(len(by_key[k].values)) for k in rest)))
    mine = tuple(
        next(i for i, v in enumerate(by_key[k].values) if repr(v) == repr(row.overrides[k])) for k in rest
    )
    return color, LINE_STYLES[combos.index(mine) % len(LINE_STYLES)]


def _y_value(row: Row, column: str) -> float:
    v = row.value(column)
    if row.status != "ok" or v is None:
        return math.nan
    v = float(v)
    return abs(v) if column == "drift" else v


def _spans_decades(values: np.ndarray) -> bool:
    values = values[np.isfinite(values)]
    return bool(len(values)) and bool(np.all(values > 0)) and values.max() / values.min() >= LOG_SPAN
