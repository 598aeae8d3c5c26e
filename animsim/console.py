"""What the command line prints around the work: table widths, one-off notices, number formats.

Kept apart from :mod:`animsim.cli` so the library's table builders (compare,
sweep) and the CLI share one idea of how wide the screen is and how a number
is written, and so tests can render any table at a chosen width.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:  # types only: rich loads when a table is printed
    from rich.console import Console

#: Width of a printed table when stdout is not a terminal and COLUMNS is not set
#: (a file or a pipe): wide, so a log keeps whole rows.
PIPE_TABLE_WIDTH = 200


def table_width(stream: TextIO | None = None) -> int | None:
    """Columns to lay tables out in: COLUMNS when set, the terminal's width, else PIPE_TABLE_WIDTH.

    None means "let rich measure the terminal". COLUMNS wins over the pipe
    default so ``COLUMNS=80 animsim compare ... | less`` is laid out for 80.
    """
    stream = stream or sys.stdout
    columns = os.environ.get("COLUMNS", "")
    if columns.isdigit() and int(columns) > 0:
        return int(columns)
    return None if stream.isatty() else PIPE_TABLE_WIDTH


def stdout_console(width: int | None = None) -> Console:
    """A rich Console on stdout at :func:`table_width` (or ``width``)."""
    from rich.console import Console

    return Console(width=width or table_width(sys.stdout))


def sig(value: float | None, digits: int = 3) -> str:
    """A number in ``digits`` significant digits, short enough for a narrow column: 2.41e-05, 0.125, 1.2e+03.

    None (no value: an unstable run) prints as an em dash.
    """
    if value is None:
        return "—"
    if not math.isfinite(value):
        return str(value)
    return f"{value:.{digits}g}"


def terminal_notice(stream: TextIO | None = None) -> Callable[[str], None] | None:
    """A ``notice`` for the engine (e.g. "compiling numba kernels (first run only...)") on a terminal.

    The first numba run compiles for seconds; without a word it looks hung.
    None when ``stream`` (stderr by default) is a pipe or a file: logs stay clean.
    """
    stream = stream or sys.stderr
    if not stream.isatty():
        return None

    def notice(text: str) -> None:
        print(text, file=stream, flush=True)

    return notice


# compiled: animsim.compile.Compiled, result: animsim.engine.RunResult, system: animsim.system.System;
# Any because this module sits below them in the layers (docs/architecture.md), even for types
def steps_text(compiled: Any, result: Any) -> str:
    """How many steps a run took, in words that fit fixed and adaptive runs.

    Fixed: ``2500 steps of 0.002 s`` (``1200 of 2500 steps of 0.002 s`` when it
    stopped early). Adaptive: the step count is the controller's, so it is
    never shown as a fraction of the fixed plan (``376/300`` read as 125 %).
    """
    adaptive = getattr(compiled.scene, "adaptive", None)
    taken, planned = result.steps_taken, compiled.clock.steps
    if adaptive is not None:
        return (
            f"{taken} adaptive steps (tolerance {adaptive.tolerance:g}, "
            f"dt {adaptive.dt_min:g} to {adaptive.dt_max:g} s)"
        )
    if taken < planned:
        return f"{taken} of {planned} steps of {compiled.clock.dt:g} s"
    return f"{planned} steps of {compiled.clock.dt:g} s"


def count_text(n: int, word: str, plural: str | None = None) -> str:
    """``1 rigid body``, ``2 rigid bodies``."""
    return f"{n} {word if n == 1 else (plural or word + 's')}"


def point_particles(system: Any) -> tuple[int, int]:
    """(particles, pinned ones) without the rows that hold rigid bodies' centres of mass:
    a scene of one die has no particle, though the engine keeps its centre in a row."""
    import numpy as np

    n = system.particle_count - system.body_count
    pinned = np.asarray(system.particle_pinned, dtype=bool).copy()
    pinned[system.body_first : system.body_first + system.body_count] = False
    return n, int(pinned.sum())


def format_bytes(n: float) -> str:
    """A size in bytes as people read it: 3 significant digits of GiB, MiB or KiB."""
    for unit, size in (("GiB", 1024**3), ("MiB", 1024**2), ("KiB", 1024)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"
