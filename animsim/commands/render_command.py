"""``animsim render`` as one call: a scene, a trajectory file or a Trajectory drawn as a GIF
and/or MP4, one panel per method with ``integrators``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from animsim.analysis.compare import integrator_names
from animsim.commands.inputs import bound_growth, check_output, prepared, refuse_bodies_in_file
from animsim.commands.outcomes import Trajectory
from animsim.commands.side_by_side import render_side_by_side
from animsim.compile import compile_scene
from animsim.errors import UsageError
from animsim.export.trajectory import is_trajectory, read_trajectory
from animsim.panel_runs import compile_each
from animsim.render import RenderOptions, render_scene, render_trajectory, validate
from animsim.scene import models as m
from animsim.scene.models import Scene


def render_command(
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
    """The work of :func:`animsim.api.render`."""
    opts = RenderOptions(
        fps=fps,
        size=size,
        view=view,
        azimuth=azimuth,
        elevation=elevation,
        distance=distance,
        dot_radius=dot_radius,
    )
    gif_path = None if gif is None else Path(gif)
    mp4_path = None if mp4 is None else Path(mp4)
    validate(gif_path, mp4_path, opts)
    for out in (gif_path, mp4_path):
        if out is not None:
            check_output(out, source)
    from_file = isinstance(source, str | Path) and is_trajectory(Path(source))
    if integrators is not None:
        return _side_by_side(
            source, integrators, integrator, gif_path, mp4_path, opts, from_file,
            limits=limits, dt=dt, duration=duration, backend=backend, stop=stop,
        )  # fmt: skip
    if isinstance(source, Trajectory):
        return render_trajectory(source.frames_long, gif_path, mp4_path, opts, compiled=source.compiled)
    compiled = None
    traj_path = Path(source) if from_file and isinstance(source, str | Path) else None
    from_traj = None if traj_path is None else read_trajectory(traj_path)
    if traj_path is not None and scene is None:
        what = "a render of a trajectory file"
        refuse_bodies_in_file(from_traj, traj_path, what, "render the scene: animsim render SCENE")
    scene_source = (Path(scene) if scene is not None else None) if from_file else source
    if scene_source is not None:
        sc, name, est, _ = prepared(
            scene_source,
            limits,
            integrator=integrator,
            dt=dt,
            duration=duration,
            consumer="render_trajectory" if from_file else "render",
        )
        if not from_file:
            sc = sc.model_copy(update={"record": m.Record(fps=fps)})  # exactly the frames shown

        # a trajectory's scene is only drawn (springs, planes), never stepped: NumPy compiles it
        compiled = compile_scene(sc, name, backend="numpy" if from_file else backend)
        bound_growth(compiled, est, limits)
    if from_traj is not None:
        return render_trajectory(from_traj, gif_path, mp4_path, opts, compiled=compiled)
    total = compiled.record_steps.size
    tick = None if progress is None else (lambda done: progress(done, total))
    return render_scene(compiled, gif_path, mp4_path, opts, progress=tick, stop=stop)


def _side_by_side(
    source: str | Path | Scene | Trajectory,
    integrators: str | Sequence[str],
    integrator: str | None,
    gif_path: Path | None,
    mp4_path: Path | None,
    opts: RenderOptions,
    from_file: bool,
    *,
    limits: Any,
    dt: float | None,
    duration: float | None,
    backend: str,
    stop: Callable[[], bool] | None,
) -> Any:
    """``render --integrators``: the scene simulated once per method, drawn side by side."""
    if from_file or isinstance(source, Trajectory):
        raise UsageError(
            "--integrators simulates the scene once per method: give the scene, not a trajectory"
        )
    if integrator is not None:
        raise UsageError("give --integrator or --integrators, not both")

    names = integrator_names(integrators)
    sc, name, _, _ = prepared(
        source,  # type: ignore[arg-type]
        limits,
        dt=dt,
        duration=duration,
        consumer="render",
    )
    sc = sc.model_copy(update={"record": m.Record(fps=opts.fps)})
    result = render_side_by_side(compile_each(sc, name, names, backend), gif_path, mp4_path, opts, stop=stop)
    result.panels = list(names)
    return result
