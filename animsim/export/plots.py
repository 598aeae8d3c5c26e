"""Figures for ``animsim compare``: a work-precision diagram beside a convergence diagram.

Left: log error against log run time, one line per integrator, the way SciML's
DiffEqDevTools draws a ``WorkPrecisionSet``: the lower left is cheap and
accurate, so the best method for a wanted accuracy is the leftmost line at
that height. Right: log error against log dt, with dashed guides of slope 1,
2 and 4 and each integrator's observed order in its legend entry (Hairer,
Norsett and Wanner, "Solving ODEs I", II.1: global error ~ C dt^p).

matplotlib is imported inside the functions (``animsim run`` starts fast) and
only through ``matplotlib.figure.Figure`` with the Agg-based canvases, never
pyplot, so no display or global state is touched. The files carry no date or
software version, so the same input gives the same bytes where the backend
allows it (PNG, PDF; SVG with a fixed hash salt).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from animsim.atomic import write_bytes_atomic
from animsim.errors import UsageError

#: suffix -> (matplotlib format, metadata that removes dates and versions)
FORMATS: dict[str, tuple[str, dict[str, Any]]] = {
    ".png": ("png", {"Software": None}),
    ".svg": ("svg", {"Date": None, "Creator": None}),
    ".pdf": ("pdf", {"CreationDate": None, "ModDate": None, "Creator": None, "Producer": None}),
}
#: the slopes drawn as dashed guides on the convergence panel
GUIDE_SLOPES = (1, 2, 4)
FIGURE_SIZE = (13.0, 5.6)  # inches
DPI = 120
#: markers cycle so lines stay distinguishable in grey print
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
#: a fixed salt makes SVG element ids reproducible
SVG_SALT = "animsim"
#: characters per line of the "unstable, not drawn" note inside the convergence panel
UNSTABLE_TEXT_WIDTH = 60
#: an axis spanning fewer decades than this gets ticks at 1, 2 and 5 per decade
SHORT_AXIS_DECADES = 2.5
#: guides sit this factor below the line they follow, parallel to it
GUIDE_OFFSET = 0.3


def plot_format(path: str | Path) -> str:
    """The format for ``path`` from its suffix; UsageError for anything else."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise UsageError(f"--plot {path}: unknown image type {suffix or '(none)'!r}; use .png, .svg or .pdf")
    return FORMATS[suffix][0]


def _series(comparison: Any) -> list[tuple[str, list[Any], Any]]:
    out = []
    for fit in comparison.orders:
        rows = [r for r in comparison.rows if r.integrator == fit.integrator and r.status == "ok" and r.error]
        out.append((fit.integrator, sorted(rows, key=lambda r: r.dt), fit))
    return out


def compare_figure(comparison: Any) -> Any:
    """The two-panel figure for a :class:`~animsim.analysis.compare.Comparison`."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=FIGURE_SIZE, dpi=DPI, layout="constrained")
    work, conv = fig.subplots(1, 2)
    colours = matplotlib.colormaps["tab10"].colors
    handles: list[Any] = []
    labels: list[str] = []
    for k, (name, rows, fit) in enumerate(_series(comparison)):
        colour, marker = colours[k % len(colours)], MARKERS[k % len(MARKERS)]
        if not rows:
            continue
        err = [r.error for r in rows]
        work.plot([r.seconds for r in rows], err, marker=marker, color=colour, lw=1.6, ms=6)
        order = "n/a" if fit.order is None else f"{fit.order:.2f}"
        (line,) = conv.plot([r.dt for r in rows], err, marker=marker, color=colour, lw=1.6, ms=6)
        handles.append(line)
        labels.append(f"{name}: observed order {order} (expected {fit.expected})")
        # Points left out of the order fit (round-off, reference accuracy, not yet
        # asymptotic) are drawn hollow, so the fit's basis is visible.
        out = [r for r in rows if not r.in_fit]
        if out:
            conv.plot(
                [r.dt for r in out],
                [r.error for r in out],
                ls="none",
                marker=marker,
                ms=9,
                mfc="white",
                mec=colour,
                zorder=3,
            )
    drawn = [item for item in _series(comparison) if item[1]]
    if drawn:  # the guides span the drawn points only
        drawn_dts = [r.dt for _, rows, _ in drawn for r in rows]
        notes = _guides(conv, drawn, min(drawn_dts), max(drawn_dts))
    else:
        notes = []
    for ax in (work, conv):
        ax.set_xscale("log")
        ax.set_yscale("log")
        _log_ticks(ax.xaxis, *ax.get_xlim())
        _log_ticks(ax.yaxis, *ax.get_ylim())
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.12)
    work.set_xlabel(f"run time per simulation, s (median of {comparison.repeat}; simulation loop only)")
    work.set_ylabel("largest position error, m")
    work.set_title("work-precision: lower left is better")
    conv.set_xlabel("step size dt, s")
    conv.set_ylabel("largest position error, m")
    conv.set_title(r"convergence: error $\propto$ dt$^{\,order}$")
    if any(not r.in_fit for _, rows, _ in _series(comparison) for r in rows):
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], ls="none", marker="o", ms=8, mfc="white", mec="0.3"))
        labels.append("hollow: left out of the order fit")
    # One legend for both panels (the colours match), below them, so it never hides a line.
    fig.legend(
        handles, labels, loc="outside lower center", ncols=min(3, max(len(handles), 1)), fontsize="small"
    )
    ref = comparison.reference
    fig.suptitle(
        f"{comparison.scene_name}: error against cost and step size\nreference: {ref.kind}: {ref.description}",
        fontsize="medium",
    )
    unstable = [r for r in comparison.rows if r.status != "ok"]
    if unstable:
        conv.text(
            0.02,
            0.98,
            _unstable_text(comparison.rows, unstable),
            transform=conv.transAxes,
            ha="left",
            va="top",
            fontsize="small",
            color="firebrick",
        )
    _spread_labels(fig, notes)
    return fig


def _spread_labels(fig: Any, notes: list[Any]) -> None:
    """Move guide labels down until none overlaps the one above it (two guides can end at
    nearly the same height, and their labels were drawn over each other)."""
    if len(notes) < 2:
        return
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()  # the final layout (constrained), so the extents are the saved ones
    renderer = canvas.get_renderer()
    above = None
    for note in sorted(notes, key=lambda a: -a.get_window_extent(renderer).y1):
        box = note.get_window_extent(renderer)
        if above is not None and box.y1 > above.y0 and box.x0 < above.x1 and above.x0 < box.x1:
            dx, dy = note.xyann
            note.xyann = (dx, dy - (box.y1 - above.y0 + 1.0) * 72.0 / fig.dpi)  # pixels -> points
            box = note.get_window_extent(renderer)
        above = box


def _unstable_text(rows: list[Any], unstable: list[Any]) -> str:
    """'unstable, not drawn: euler (every dt); rk4 dt 0.01', wrapped to fit inside a panel."""
    import textwrap

    parts = []
    for name in dict.fromkeys(r.integrator for r in unstable):
        bad = [r for r in unstable if r.integrator == name]
        if len(bad) == sum(1 for r in rows if r.integrator == name):
            parts.append(f"{name} (every dt)")
        else:
            parts.append(f"{name} dt " + ", ".join(f"{r.dt:g}" for r in bad))
    return textwrap.fill("unstable, not drawn: " + "; ".join(parts), width=UNSTABLE_TEXT_WIDTH)


def _log_ticks(axis: Any, lo: float, hi: float) -> None:
    """Readable log ticks: 1, 2, 5 per decade on a short axis, decades on a long one.

    matplotlib labels minor ticks when an axis spans less than about a decade,
    and those labels overlap; here only major ticks carry labels.
    """
    import math

    from matplotlib.ticker import LogFormatterSciNotation, LogLocator, NullFormatter

    decades = math.log10(hi / lo) if lo > 0 and hi > lo else 0.0
    subs = (1.0, 2.0, 5.0) if decades < SHORT_AXIS_DECADES else (1.0,)
    axis.set_major_locator(LogLocator(base=10, subs=subs))
    # minor_thresholds: label every major tick whatever the span (the locator chose them).
    axis.set_major_formatter(
        LogFormatterSciNotation(labelOnlyBase=False, minor_thresholds=(math.inf, math.inf))
    )
    axis.set_minor_formatter(NullFormatter())


def _guides(ax: Any, series: list[tuple[str, list[Any], Any]], dt_lo: float, dt_hi: float) -> list[Any]:
    """Dashed lines of slope 1, 2 and 4 across the whole dt range.

    Each guide runs parallel just below the first integrator whose expected
    order is its slope (anchored at that integrator's smallest-dt point), so a
    line that follows its guide has the order it should. A slope no compared
    method claims is anchored below the lowest line. Returns the labels' annotations.
    """
    import numpy as np

    lowest = min(r.error for _, rows, _ in series for r in rows)
    x = np.geomspace(dt_lo, dt_hi, 20)
    notes: list[Any] = []
    for p in GUIDE_SLOPES:
        match = next((rows for _, rows, fit in series if fit.expected == p and rows), None)
        anchor = GUIDE_OFFSET * (match[0].error if match else lowest)
        y = anchor * (x / (match[0].dt if match else dt_lo)) ** p
        ax.plot(x, y, ls="--", color="0.45", lw=1.0, zorder=1)
        notes.append(
            ax.annotate(
                f"slope {p}",
                (x[-1], y[-1]),
                textcoords="offset points",
                xytext=(-2, -3),
                ha="right",
                va="top",
                fontsize="small",
                color="0.35",
            )
        )
    return notes


def write_compare_plot(comparison: Any, path: str | Path) -> None:
    """Draw the figure and write it atomically; the type follows the suffix."""
    import matplotlib

    fmt = plot_format(path)
    metadata = FORMATS[Path(path).suffix.lower()][1]
    with matplotlib.rc_context({"svg.hashsalt": SVG_SALT}):
        fig = compare_figure(comparison)
        buf = io.BytesIO()
        fig.savefig(buf, format=fmt, metadata=metadata)
    write_bytes_atomic(path, buf.getvalue())
