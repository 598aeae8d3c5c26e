"""The ``plot`` command: particle paths, the energy of a run split into its
parts, or phase portraits, drawn to a PNG, SVG or PDF (:class:`PlotKind`
names the three).
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from animsim.cli.options import (
    BackendOpt,
    DtOpt,
    DurationOpt,
    IntegratorOpt,
    SourceArg,
    checked_backend,
    complete_integrators,
    complete_plot_view,
    limit_options,
)
from animsim.cli.terminal import compiling


class PlotKind(StrEnum):
    trajectory = "trajectory"
    energy = "energy"
    phase = "phase"


@limit_options
def plot(
    source: SourceArg,
    output: Annotated[Path, typer.Option("-o", "--output", help="Picture file: .png, .svg or .pdf.")],
    kind: Annotated[
        PlotKind,
        typer.Option(
            "--kind",
            help="Paths of particles; energy against time (kinetic, gravitational, spring, ...); "
            "or phase: position against velocity per particle and axis.",
        ),
    ] = PlotKind.trajectory,
    scene: Annotated[
        Path | None, typer.Option("--scene", help="The scene of a trajectory (needed for --kind energy).")
    ] = None,
    view: Annotated[
        str | None,
        typer.Option(
            "--view",
            help="xy, xz, yz or zy; default: chosen as render chooses it.",
            autocompletion=complete_plot_view,
        ),
    ] = None,
    integrator: IntegratorOpt = None,
    dt: DtOpt = None,
    duration: DurationOpt = None,
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="--kind phase: comma-separated methods, overlaid.",
            autocompletion=complete_integrators,
        ),
    ] = None,
    particles: Annotated[
        str | None,
        typer.Option("--particles", help="--kind phase: comma-separated particle ids; default up to 3."),
    ] = None,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Draw particle paths, the energy of a run split into its parts (and its drift), or phase portraits."""
    from animsim import api

    with compiling(False, checked_backend(backend)):
        api.plot(
            source,
            output,
            kind=kind.value,
            scene=scene,
            view=view,
            integrator=integrator,
            dt=dt,
            duration=duration,
            integrators=integrators,
            particles=particles,
            limits=limits,
            backend=checked_backend(backend),
        )
    typer.echo(f"wrote {output}")
