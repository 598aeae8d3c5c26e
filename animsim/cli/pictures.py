"""The commands that make pictures of a run: ``render`` writes an animated
GIF or MP4, ``view`` one self-contained HTML page that plays the animation.
"""

from __future__ import annotations

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
    complete_render_view,
    complete_viewer_view,
    limit_options,
)
from animsim.cli.terminal import compiling, err, graceful_stop, progress_bar
from animsim.errors import EXIT_FAILED, EXIT_INTERRUPTED


@limit_options
def render(
    source: SourceArg,
    gif: Annotated[Path | None, typer.Option("--gif", help="Write an animated GIF here.")] = None,
    mp4: Annotated[
        Path | None, typer.Option("--mp4", help="Write an MP4 here (needs the mp4 extra: imageio-ffmpeg).")
    ] = None,
    fps: Annotated[
        float, typer.Option("--fps", help="Frames per second; GIF delays come in 10 ms steps.")
    ] = 25.0,
    view: Annotated[
        str | None,
        typer.Option(
            "--view",
            help="xy, xz, yz, zy (orthographic: the across axis, then the up one) or 3d "
            "(perspective); default: from the side, up drawn upward, when gravity points down y or z "
            "(from above when the motion is flat), else the two axes along which it is widest.",
            autocompletion=complete_render_view,
        ),
    ] = None,
    size: Annotated[
        str | None,
        typer.Option(
            "--size",
            help="WIDTHxHEIGHT in pixels; default 480 on the longer side, shaped like the motion (16:9 at most).",
        ),
    ] = None,
    scene: Annotated[
        Path | None,
        typer.Option("--scene", help="The scene of a trajectory, to draw its springs and planes."),
    ] = None,
    azimuth: Annotated[float | None, typer.Option(help="3d camera: degrees around the up axis.")] = None,
    elevation: Annotated[float | None, typer.Option(help="3d camera: degrees above the horizon.")] = None,
    distance: Annotated[
        float | None, typer.Option(help="3d camera: distance from the centre (m); default fits the bounds.")
    ] = None,
    dot_radius: Annotated[
        float, typer.Option("--dot-radius", help="Radius in pixels of particles that have no size.")
    ] = 3.0,
    integrator: IntegratorOpt = None,
    dt: DtOpt = None,
    duration: DurationOpt = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="Comma-separated methods: the scene once per method, panels side by side.",
            autocompletion=complete_integrators,
        ),
    ] = None,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Render an animation: particles as dots (size and colour over life), springs as lines, planes as the ground."""
    from animsim import api

    with (
        graceful_stop() as stop,
        progress_bar(quiet, "rendering", at_least=50) as progress,
        compiling(quiet, checked_backend(backend)),
    ):
        result = api.render(
            source,
            gif,
            mp4,
            fps=fps,
            view=view,
            size=size,
            azimuth=azimuth,
            elevation=elevation,
            distance=distance,
            dot_radius=dot_radius,
            scene=scene,
            integrator=integrator,
            dt=dt,
            duration=duration,
            integrators=integrators,
            limits=limits,
            stop=stop,
            progress=progress,
            backend=checked_backend(backend),
        )
    _report(source, result, quiet, fps)


def _report(source: Path, result: Any, quiet: bool, fps: float) -> None:
    """What :func:`render` says of its result (an :class:`animsim.render.RenderResult`), and its
    exit on an interruption or a failure."""
    outs = " and ".join(str(p) for p in result.outputs)
    if result.status == "interrupted":
        if result.outputs:
            err(f"{source}: interrupted; {outs} has the {result.frames} frames drawn so far")
        else:
            err(f"{source}: interrupted before the first frame was drawn; nothing written")
        raise typer.Exit(EXIT_INTERRUPTED)
    if not quiet:
        if result.panels:
            typer.echo(
                f"wrote {outs}: {len(result.panels)} panels ({', '.join(result.panels)}), "
                f"{result.frames} frames at {fps:g} fps"
            )
        else:
            typer.echo(
                f"wrote {outs}: {result.frames} frames at {fps:g} fps, view {result.view}, {result.size}"
            )
    if result.status == "unstable":
        if result.panels:
            # A method that blows up is what the picture is there to show, not a failure of the command.
            err(f"{source}: a panel is marked: {result.failure.describe()}")
            return
        err(f"{source}: {result.failure.describe()}")
        raise typer.Exit(EXIT_FAILED)


@limit_options
def view(
    source: SourceArg,
    output: Annotated[Path, typer.Option("-o", "--output", help="The HTML file to write.")],
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="Comma-separated methods: one panel per method, played in step.",
            autocompletion=complete_integrators,
        ),
    ] = None,
    fps: Annotated[float, typer.Option("--fps", help="Frames per second recorded for playback.")] = 25.0,
    view: Annotated[
        str,
        typer.Option(
            "--view",
            help="The view it opens with: 3d, xy, xz, yz or zy.",
            autocompletion=complete_viewer_view,
        ),
    ] = "3d",
    scene: Annotated[
        Path | None,
        typer.Option("--scene", help="The scene of a trajectory, for springs, pins, planes and energy."),
    ] = None,
    integrator: IntegratorOpt = None,
    dt: DtOpt = None,
    duration: DurationOpt = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Write one self-contained HTML page that plays the animation (opens offline, in any current browser).

    Play and pause, a time slider, playback speed, a 3D view to orbit, pan and
    zoom (and xy, xz, yz, zy views), springs, planes, pinned particles, colour and
    size over life, and an energy plot whose cursor follows the time. With
    --integrators the scene runs once per method, the panels side by side.
    """
    from animsim import api

    with graceful_stop() as stop, compiling(quiet, checked_backend(backend)):
        summary = api.view(
            source,
            output,
            integrators=integrators,
            fps=fps,
            view=view,
            scene=scene,
            integrator=integrator,
            dt=dt,
            duration=duration,
            limits=limits,
            stop=stop,
            backend=checked_backend(backend),
        )
    if summary.interrupted:
        err(f"{source}: interrupted; {output} was not written")
        raise typer.Exit(EXIT_INTERRUPTED)
    if not quiet:
        typer.echo(summary.text)
    for note in summary.notes:
        err(f"{source}: {note}")
