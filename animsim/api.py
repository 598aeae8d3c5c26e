"""The Python API: what notebooks, scripts and every ``animsim`` command call.

    scene = animsim.load("scenes/cloth.yaml")      # or animsim.loads(text)
    traj = animsim.simulate(scene)                 # a Trajectory
    traj.positions                                 # (F, N, 3), NaN where not alive
    rows = animsim.compare(scene, integrators=["euler", "rk4"], dts=[0.01, 0.005])

Bad scenes raise :class:`animsim.SceneError`, whose ``diagnostics`` are the
``FILE:LINE:COLUMN: key.path: message`` lines the command line prints.

Each function is documented here and does its work in :mod:`animsim.commands` (in the
module named for it), imported only when the function is called, so that importing
animsim loads only what is used.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from animsim.commands.arguments import MAX_SEED as MAX_SEED
from animsim.commands.arguments import PLOT_KINDS as PLOT_KINDS
from animsim.commands.arguments import type_name
from animsim.commands.outcomes import RunOutcome, Trajectory
from animsim.errors import SceneError
from animsim.errors import UsageError as UsageError
from animsim.scene.models import Scene


def load(path: str | Path, *, limits: Any = None) -> Scene:
    """Read, parse and validate a scene file (every problem as a SceneError)."""
    from animsim.preflight import check_starts
    from animsim.scene.loader import load_scene
    from animsim.scene.yaml_reader import Limits

    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"load() takes the path of a scene file (str or Path), not {type_name(path)}")

    loaded = load_scene(path, limits or Limits())
    check_starts(loaded, loaded.scene)
    return _named(loaded)


def loads(text: str, name: str = "scene", *, limits: Any = None) -> Scene:
    """The same from YAML text; diagnostics name the file ``<name>``."""
    from animsim.preflight import check_starts
    from animsim.scene.loader import load_scene_text
    from animsim.scene.yaml_reader import Limits

    if not isinstance(text, str):
        hint = "; for a file use load(path)" if isinstance(text, os.PathLike) else ""
        raise TypeError(f"loads() takes the scene's YAML text as a str, not {type_name(text)}{hint}")

    loaded = load_scene_text(text, f"<{name}>", limits or Limits())
    check_starts(loaded, loaded.scene)
    scene = _named(loaded)
    return scene if scene.name else scene.model_copy(update={"name": name})


def _named(loaded: Any) -> Scene:
    scene = loaded.scene if loaded.scene.name else loaded.scene.model_copy(update={"name": loaded.name})
    scene._source = {"file": loaded.file, "sha256": loaded.sha256}
    return scene


def prepare(
    scene: Scene,
    *,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    seed: int | None = None,
    limits: Any = None,
    fmt: str = "csv",
    loaded: Any = None,
    consumer: str | None = None,
) -> tuple[Scene, Any]:
    """The scene with overrides (checked by the file's rules) and its pre-flight estimate.

    Refuses (UsageError, exit 2) a run that would exceed the step or memory
    limits before anything is allocated, and (SceneError, exit 2) a scene in a
    refused cell of the support table for ``consumer`` (:mod:`animsim.support`;
    None: what the simulation itself cannot do).
    """
    from animsim.commands import inputs

    return inputs.prepare(
        scene,
        integrator=integrator,
        dt=dt,
        duration=duration,
        seed=seed,
        limits=limits,
        fmt=fmt,
        loaded=loaded,
        consumer=consumer,
    )


def prepare_file(
    path: Path,
    limits: Any,
    *,
    fmt: str = "csv",
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    seed: int | None = None,
    consumer: str | None = None,
) -> tuple[Any, Scene, Any]:
    """Load a scene file, apply overrides and check the step and memory limits.

    Every command that compiles a scene goes through here, so none of them
    allocates before the pre-flight has said the scene fits. Returns
    (LoadedScene, Scene with overrides, preflight.Estimate).
    """
    from animsim.commands import inputs

    return inputs.prepare_file(
        path, limits, fmt=fmt, integrator=integrator, dt=dt, duration=duration, seed=seed, consumer=consumer
    )


def compile(scene: Scene, backend: str = "auto", *, name: str | None = None) -> Any:
    """The compiled scene (:class:`animsim.compile.Compiled`) that :func:`simulate` runs:
    what ``explain`` shows and the stability analysis reads, before any step."""
    from animsim.commands import simulation

    return simulation.compile(scene, backend, name=name)


def simulate(
    scene: Scene | Any,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    seed: int | None = None,
    backend: str = "auto",
    *,
    output: str | Path | None = None,
    sinks: Sequence[Any] = (),
    stop: Callable[[], bool] | None = None,
    progress: Callable[[int, int], None] | None = None,
    notice: Callable[[str], None] | None = None,
    observers: Sequence[Callable[[Any], None]] = (),
    limits: Any = None,
    meta: dict[str, Any] | None = None,
    keep: bool = True,
) -> Trajectory:
    """Run ``scene`` (with overrides as on the command line) and return its Trajectory.

    ``scene`` may also be what :func:`compile` returned (then the overrides must
    be None). ``output``: stream the frames to a file instead of keeping them in
    memory (any format ``animsim run`` writes, by suffix); the Trajectory then
    holds the metadata only. ``sinks``: more frame sinks to feed; ``keep=False``
    keeps no frames in memory (the sinks have them).
    """
    from animsim.commands import simulation

    return simulation.simulate(
        scene,
        integrator,
        dt,
        duration,
        seed,
        backend,
        output=output,
        sinks=sinks,
        stop=stop,
        progress=progress,
        notice=notice,
        observers=observers,
        limits=limits,
        meta=meta,
        keep=keep,
    )


def compare(
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
    """One dict per (integrator, dt) with the columns of ``animsim compare``
    (``comparison=True``: the whole :class:`animsim.analysis.compare.Comparison`,
    with the reference, the observed orders, the plan and the time taken).

    ``integrators``, ``dts``: default every fixed-step method at 2 dt, dt, dt/2
    and dt/4 of the scene's dt. ``duration``: compare over the first seconds
    of the scene only. ``budget`` (seconds, None: no limit): probe the scene
    first and cut what was left to the default (dt/4, then the window, then
    the methods) until the estimated run time fits, as ``animsim compare``
    does; ``on_plan(plan)`` hears the :class:`~animsim.analysis.compare.Plan`
    before the runs start. ``scene`` may be a scene file (its limits checked
    with ``limits``); ``integrators`` and ``dts`` may be the command line's
    comma-separated text. ``output`` (CSV) and ``plot`` (PNG, SVG, PDF) are
    checked before any run and written after.
    """
    from animsim.commands.compare_command import compare_command

    return compare_command(
        scene,
        integrators,
        dts,
        output=output,
        plot=plot,
        limits=limits,
        reference=reference,
        repeat=repeat,
        comparison=comparison,
        duration=duration,
        budget=budget,
        backend=backend,
        name=name,
        jobs=jobs,
        scheduler=scheduler,
        max_steps=max_steps,
        progress=progress,
        notice=notice,
        on_plan=on_plan,
    )


# --- what each command does, as one call ------------------------------------------------
# The command line parses options, makes one of these calls, prints and sets the exit
# status; everything between (pre-flight, sinks, compiling, drawing) happens in the call.


def run(
    source: str | Path | Scene,
    output: str | Path | None = None,
    *,
    fmt: str | None = None,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    seed: int | None = None,
    backend: str = "auto",
    extra_columns: bool = False,
    drift_warn: float | None = None,
    limits: Any = None,
    stop: Callable[[], bool] | None = None,
    progress: Callable[[int, int], None] | None = None,
    notice: Callable[[str], None] | None = None,
    warn: Callable[[str], None] | None = None,
) -> RunOutcome:
    """Simulate a scene file (or Scene) into a trajectory file and its ``.meta.json``: ``animsim run``.

    ``output`` defaults to ``<scene stem>.<format>`` here; ``"-"`` is CSV on stdout.
    Everything that can be refused (format, folder, disk space, the step and
    memory limits) is refused before the first step. ``warn`` receives the
    stability warning of a step beyond its limit, before the run.
    """
    from animsim.commands.run_command import run_command

    return run_command(
        source,
        output,
        fmt=fmt,
        integrator=integrator,
        dt=dt,
        duration=duration,
        seed=seed,
        backend=backend,
        extra_columns=extra_columns,
        drift_warn=drift_warn,
        limits=limits,
        stop=stop,
        progress=progress,
        notice=notice,
        warn=warn,
    )


def explain(
    source: str | Path | Scene,
    *,
    integrator: str | None = None,
    backend: str = "auto",
    limits: Any = None,
) -> list[str]:
    """What a scene compiles to, as the lines ``animsim explain`` prints: counts, the
    stages each step runs, and what was left out because the scene does not need it."""
    from animsim.commands.explain_command import explain_command

    return explain_command(source, integrator=integrator, backend=backend, limits=limits)


def check(
    paths: Sequence[str | Path],
    *,
    quiet: bool = False,
    echo: Callable[[str], None] = print,
    echo_err: Callable[[str], None] = print,
    limits: Any = None,
    drift_warn: float | None = None,
    backend: str = "auto",
) -> bool:
    """Validate, analyse and run each scene file on ``backend``, reporting through
    ``echo``/``echo_err`` as ``animsim check`` does; True only if every scene is valid and stable."""
    from animsim.analysis.check import check_scenes
    from animsim.measures.drift import check_threshold

    return check_scenes(
        [Path(p) for p in paths],
        prepare=prepare_file,
        quiet=quiet,
        echo=echo,
        echo_err=echo_err,
        limits=limits,
        drift_warn=None if drift_warn is None else check_threshold(drift_warn),
        backend=backend,
    )


def render(
    source: str | Path | Scene | Trajectory,
    gif: str | Path | None = None,
    mp4: str | Path | None = None,
    *,
    fps: float = 25.0,
    view: str | None = None,
    size: str | None = None,
    azimuth: float | None = None,
    elevation: float | None = None,
    distance: float | None = None,
    dot_radius: float = 3.0,
    scene: str | Path | None = None,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    integrators: str | Sequence[str] | None = None,
    limits: Any = None,
    stop: Callable[[], bool] | None = None,
    progress: Callable[[int, int], None] | None = None,
    backend: str = "auto",
) -> Any:
    """Draw an animation (GIF and/or MP4): ``animsim render``; a scene is simulated on ``backend``.

    ``source`` is a scene file or Scene (simulated, recording at ``fps``), a
    trajectory file (.csv, .npz; ``scene`` adds its springs and planes) or a
    Trajectory from :func:`simulate`. ``integrators``: the scene once per
    method, panels side by side. Returns :class:`animsim.render.RenderResult`.
    """
    from animsim.commands.render_command import render_command

    return render_command(
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
        backend=backend,
    )


def view(
    source: str | Path,
    output: str | Path,
    *,
    integrators: str | Sequence[str] | None = None,
    fps: float = 25.0,
    view: str = "3d",
    scene: str | Path | None = None,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    limits: Any = None,
    stop: Callable[[], bool] | None = None,
    backend: str = "auto",
) -> Any:
    """Write one self-contained HTML page that plays the animation: ``animsim view``; a scene
    is simulated on ``backend``.
    Returns :class:`animsim.commands.viewer_command.ViewSummary` (the summary line and notes)."""
    from animsim.commands.viewer_command import view_command

    return view_command(
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
        backend=backend,
    )


def plot(
    source: str | Path,
    output: str | Path,
    *,
    kind: str = "trajectory",
    scene: str | Path | None = None,
    view: str | None = None,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    integrators: str | Sequence[str] | None = None,
    particles: str | Sequence[str] | None = None,
    limits: Any = None,
    backend: str = "auto",
) -> Path:
    """Draw particle paths, the energy split into its parts, or phase portraits (PNG, SVG,
    PDF): ``animsim plot``. ``source`` is a scene (simulated first) or a trajectory file."""
    from animsim.commands.plot_command import plot_command

    return plot_command(
        source,
        output,
        kind=kind,
        scene=scene,
        view=view,
        integrator=integrator,
        dt=dt,
        duration=duration,
        integrators=integrators,
        particles=particles,
        limits=limits,
        backend=backend,
    )


def sweep(
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
    """Run a scene file for every combination of ``sets`` values (``"KEY=V1,V2,..."``) and
    ``integrators`` on ``backend``: ``animsim sweep``. Writes the table as CSV (``output``) and a
    plot of ``y`` over ``x`` (``plot``) when asked. ``duration`` replaces the scene's in every
    case. Returns :class:`animsim.analysis.sweep.SweepTable`; unstable and invalid cases
    are rows."""
    from animsim.commands.sweep_command import sweep_command

    return sweep_command(
        source,
        sets,
        integrators=integrators,
        reference=reference,
        output=output,
        plot=plot,
        x=x,
        y=y,
        jobs=jobs,
        scheduler=scheduler,
        limits=limits,
        progress=progress,
        backend=backend,
        duration=duration,
    )


def schema() -> str:
    """The scene JSON Schema as text (``animsim schema``; ``schemas/scene.schema.json`` is it)."""
    from animsim.scene.schema import schema_text

    return schema_text()


def init(path: str | Path, template: str = "projectile", *, force: bool = False) -> list[str]:
    """Write a commented starter scene and ``scene.schema.json`` beside it (``animsim init``);
    returns the lines the command prints."""
    from animsim.templates import write_starter

    return list(write_starter(Path(path), template, force=force))


__all__ = [
    "RunOutcome",
    "Scene",
    "SceneError",
    "Trajectory",
    "check",
    "compare",
    "compile",
    "explain",
    "init",
    "load",
    "loads",
    "plot",
    "prepare",
    "render",
    "run",
    "schema",
    "simulate",
    "sweep",
    "view",
]
