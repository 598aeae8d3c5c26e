"""``animsim sweep`` as one call: a scene file run for every combination of the swept
values and methods, the table written as CSV and plotted when asked.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from animsim import support
from animsim.analysis import sweep as sw
from animsim.commands import sweep_plot
from animsim.commands.inputs import check_output
from animsim.errors import UsageError
from animsim.preflight import RunLimits
from animsim.scene.loader import load_scene


def sweep_command(
    source: str | Path,
    sets: Sequence[str] = (),
    *,
    integrators: str | Sequence[str] | None = None,
    reference: str | None = None,
    output: str | Path | None = None,
    plot: str | Path | None = None,
    x: str | None = None,
    y: str | None = None,
    jobs: int = 1,
    scheduler: str | None = None,
    limits: Any = None,
    progress: Callable[[int, int], None] | None = None,
    backend: str = "auto",
    duration: float | None = None,
) -> Any:
    """The work of :func:`animsim.api.sweep`."""
    src = Path(source)
    # The file limits apply here; each case's step and memory pre-flight would need
    # the sweep's own variants (see docs/limits.md).
    limits = limits or RunLimits()
    loaded = load_scene(src, limits.loader)

    support.check(loaded, loaded.scene, "sweep")  # each case is the file with other values
    axes = [sw.parse_set(text) for text in sets]
    if integrators is not None:
        axes.append(
            sw.integrators_axis(integrators if isinstance(integrators, str) else ",".join(integrators))
        )
    if not axes:
        raise UsageError("sweep: give at least one --set KEY=V1,V2,... or --integrators")
    sw.check_axes(axes)
    keys = [a.key for a in axes]
    data = loaded.data
    if duration is not None:
        if not (math.isfinite(duration) and duration > 0):
            raise UsageError(f"--duration: must be a finite number > 0, not {duration!r}")
        if "duration" in keys:
            raise UsageError("--duration: the duration is swept (--set duration=...); give one or the other")
        data = {**data, "duration": float(duration)}
    x_key = x or keys[0]
    y_col = y or ("error" if reference is not None else "drift")
    if plot is not None:
        if x_key not in keys:
            raise UsageError(f"--x {x_key}: not a swept key (swept: {', '.join(keys)})")
        if y_col not in sw.PLOT_COLUMNS or (y_col == "error" and reference is None):
            cols = [c for c in sw.PLOT_COLUMNS if c != "error" or reference is not None]
            raise UsageError(f"--y {y_col}: not a plottable column (choose from {', '.join(cols)})")
        check_output(Path(plot), src)
    if output is not None:
        check_output(Path(output), src)
    table = sw.sweep(
        data,
        loaded.name,
        str(src),
        axes,
        reference=reference,
        jobs=jobs,
        scheduler=scheduler,
        progress=progress,
        backend=backend,
        mesh_dirs=limits.mesh_dirs,  # every case reads the meshes the file was allowed
    )
    if output is not None:
        sw.write_csv(table, Path(output))
    if plot is not None:
        sweep_plot.plot_table(table, Path(plot), x_key, y_col)
    return table
