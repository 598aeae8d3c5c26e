"""The ``run`` and ``explain`` commands: simulate a scene and write its
trajectory (with the summary printed after it and the energy-drift warning),
or show what a scene compiles to.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from animsim.cli.options import (
    BackendOpt,
    DriftWarnOpt,
    DtOpt,
    DurationOpt,
    IntegratorOpt,
    SceneArg,
    checked_backend,
    complete_integrator,
    format_names,
    limit_options,
)
from animsim.cli.terminal import err, graceful_stop, notice_sink, progress_bar
from animsim.errors import EXIT_FAILED, EXIT_INTERRUPTED


@limit_options
def run(
    scene: SceneArg,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o", "--output", help="Trajectory file; default <scene stem>.csv here; '-' for stdout."
        ),
    ] = None,
    integrator: IntegratorOpt = None,
    dt: DtOpt = None,
    duration: DurationOpt = None,
    seed: Annotated[int | None, typer.Option(help="Override the random seed.")] = None,
    format: Annotated[
        str | None,
        typer.Option(
            "--format",
            help="Trajectory format (csv, npz, ply, usda, usdc, vtp, ...); default from the suffix "
            "(.npz, .ply, .usda, .usdc, .pvd; a folder means ply), else csv.",
            autocompletion=format_names,
        ),
    ] = None,
    extra_columns: Annotated[
        bool, typer.Option("--extra-columns", help="Add age, size, r, g, b, a columns (particle systems).")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    backend: BackendOpt = "auto",
    drift_warn: DriftWarnOpt = 10.0,
    *,
    limits: Any = None,
) -> None:
    """Simulate SCENE and write its trajectory and a .meta.json beside it.

    Formats: CSV; NPZ; PLY (one binary file per frame, for Blender, Houdini,
    ParaView: -o out/frames.ply gives out/frames_0000.ply, ...; an existing
    folder gives <folder>/frames_0000.ply, ...); USD ASCII (-o anim.usda) or
    binary (-o anim.usdc); VTK for ParaView (-o run.pvd gives run_0000.vtp, ...).
    The output folder must exist.
    """
    from animsim import api

    with graceful_stop() as stop, progress_bar(quiet) as progress:
        outcome = api.run(
            scene,
            output,
            fmt=format,
            integrator=integrator,
            dt=dt,
            duration=duration,
            seed=seed,
            backend=checked_backend(backend),
            extra_columns=extra_columns,
            drift_warn=drift_warn,
            limits=limits,
            stop=stop,
            progress=progress,
            notice=notice_sink(quiet),
            warn=lambda text: err(f"{scene}: {text}"),
        )
    compiled, result, out = outcome.compiled, outcome.result, outcome.output
    if not quiet:
        _summary(compiled, result, outcome.wrote)
    _drift_warning(scene, compiled, result)
    if result.status == "unstable":
        assert result.failure is not None
        err(f"{scene}: {result.failure.describe()}")
        err(f"the frames before the failure are in {out}")
        raise typer.Exit(EXIT_FAILED)
    if result.status == "interrupted":
        err(
            f"{scene}: interrupted at step {result.steps_taken} (t = {result.final_state.time:.6g} s); frames so far in {out}"
        )
        raise typer.Exit(EXIT_INTERRUPTED)


def _summary(compiled: Any, result: Any, wrote: str | None) -> None:
    """Print the run summary; ``wrote`` names the files written (None: the trajectory went to stdout)."""
    from animsim.bodies.build import counts_text
    from animsim.console import steps_text

    stream_err = wrote is None  # trajectory went to stdout: keep stdout clean
    lines = [
        f"{compiled.name}: {counts_text(compiled.system, compiled.dynamics.bodies)}, {steps_text(compiled, result)} with {compiled.integrator_name}",
        f"  wall time {result.wall_time:.3f} s, {result.frames} frames, {result.force_evals} force evaluations",
        f"  energy {result.energy_start:.6g} J -> {result.energy_end:.6g} J, status {result.status}, "
        + _drift_of(compiled, result).text(),
    ]
    lines.extend(_summary_notes(compiled, result))
    if "springs_broken" in result.meta:
        first = result.meta.get("first_break_time")
        lines.append(
            f"  springs broken: {result.meta['springs_broken']}"
            + (f" (first at t = {first:.6g} s)" if first is not None else "")
        )
    if wrote is not None:
        lines.append(f"  wrote {wrote}")
    from animsim.analysis.check import wrap

    typer.echo("\n".join(wrap(line) for line in lines), err=stream_err)


def _drift_of(compiled: Any, result: Any) -> Any:
    """The run's energy-drift verdict (animsim.measures.drift), with the run's own threshold."""
    from animsim.measures.drift import DEFAULT_DRIFT_WARN_PERCENT, META_THRESHOLD_KEY, drift

    threshold = result.meta.get(META_THRESHOLD_KEY, DEFAULT_DRIFT_WARN_PERCENT)
    return drift(compiled, result.energy_start, result.energy_end, threshold)


def _drift_warning(scene: Path, compiled: Any, result: Any) -> None:
    """A drift beyond --drift-warn is a warning on stderr, also with --quiet (the run still succeeds)."""
    verdict = _drift_of(compiled, result)
    if verdict.warning and result.status != "unstable":  # an unstable run has its own report
        err(f"{scene}: warning: {verdict.warning_text()}")


def _summary_notes(compiled: Any, result: Any) -> list[str]:
    """Summary lines about what the numbers mean: the method really run."""
    from animsim.measures.effective import fallback_note

    note = fallback_note(compiled)
    return [] if note is None else [f"  note: {note}"]


@limit_options
def explain(
    scene: SceneArg,
    integrator: Annotated[
        str | None,
        typer.Option(help="Explain with this integrator instead.", autocompletion=complete_integrator),
    ] = None,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Show what SCENE compiles to: counts, the stages run each step, and what was left out."""
    from animsim import api
    from animsim.analysis.check import wrap

    for line in api.explain(scene, integrator=integrator, backend=checked_backend(backend), limits=limits):
        typer.echo(wrap(line))
