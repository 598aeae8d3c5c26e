"""``animsim compare`` as one call: the scene (a file is checked by its limits), the
outputs checked before any run, the planned comparison, then the CSV and the plot.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from animsim.analysis import compare as cmp
from animsim.commands.inputs import check_output, prepare_file
from animsim.export.plots import plot_format, write_compare_plot
from animsim.scene.models import Scene


def compare_command(
    scene: Scene | str | Path,
    integrators: str | Sequence[str] | None = None,
    dts: str | Sequence[float] | None = None,
    *,
    output: str | Path | None = None,
    plot: str | Path | None = None,
    limits: Any = None,
    reference: str = "auto",
    repeat: int = 1,
    comparison: bool = False,
    duration: float | None = None,
    budget: float | None = None,
    backend: str = "auto",
    name: str | None = None,
    jobs: int = 1,
    scheduler: Any = None,
    max_steps: int | None = None,
    progress: Any = None,
    notice: Any = None,
    on_plan: Any = None,
) -> Any:
    """The work of :func:`animsim.api.compare`."""
    from dataclasses import asdict

    source = scene  # what the outputs must not overwrite (a file), see check_output
    if not isinstance(scene, Scene):
        loaded, _, _ = prepare_file(Path(scene), limits, consumer="compare")  # the file's limits
        scene, name = loaded.scene, name or loaded.name
    for path in (output, plot):
        if path is not None:
            check_output(Path(path), source)
    if plot is not None:
        plot_format(Path(plot))
    if isinstance(integrators, str):
        integrators = cmp.parse_integrators(integrators)
    if isinstance(dts, str):
        dts = cmp.parse_dt_option(dts)
    if max_steps is None and limits is not None:
        max_steps = limits.max_steps
    result = cmp.run_planned(
        scene,
        name or scene.name or "scene",
        integrators=list(integrators) if integrators else None,
        dts=list(dts) if dts else None,
        duration=duration,
        reference=reference,
        repeat=repeat,
        budget=budget,
        backend=backend,
        jobs=jobs,
        scheduler=scheduler,
        max_steps=max_steps if max_steps is not None else cmp.DEFAULT_MAX_STEPS,
        progress=progress,
        notice=notice,
        on_plan=on_plan,
    )
    if output is not None:
        cmp.write_csv(result, Path(output))
    if plot is not None:
        write_compare_plot(result, Path(plot))
    return result if comparison else [asdict(row) for row in result.rows]
