"""A scene compiled and run: what :func:`animsim.api.compile` and
:func:`animsim.api.simulate` do, for them and for the commands that simulate.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from animsim.commands.arguments import type_name
from animsim.commands.inputs import bound_growth, prepare, uses_numba
from animsim.commands.outcomes import Trajectory
from animsim.compile import Compiled, compile_scene
from animsim.compile_notice import compile_notices
from animsim.engine import run
from animsim.errors import UsageError
from animsim.export.sinks import open_sink
from animsim.export.trajectory import TrajectoryCollector
from animsim.scene.models import Scene


def compile(scene: Scene, backend: str = "auto", *, name: str | None = None) -> Any:
    """The compiled scene (:class:`animsim.compile.Compiled`) that :func:`simulate` runs:
    what ``explain`` shows and the stability analysis reads, before any step."""
    return compile_scene(scene, name or scene.name or "scene", backend=backend)


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
    """The work of :func:`animsim.api.simulate`."""
    if not isinstance(scene, Scene | Compiled | dict):  # a dict is read as a scene (SceneError if wrong)
        hint = "; for a scene file use simulate(load(path))" if isinstance(scene, str | os.PathLike) else ""
        raise TypeError(
            f"simulate() takes a Scene (from load or loads) or a compiled scene, not {type_name(scene)}{hint}"
        )
    if isinstance(scene, Scene):
        sc, est = prepare(scene, integrator=integrator, dt=dt, duration=duration, seed=seed, limits=limits)
        numba = uses_numba(backend)
    else:
        est = None
        if any(v is not None for v in (integrator, dt, duration, seed)):
            raise UsageError("overrides go with a Scene, not with an already compiled scene")
        sc = scene.scene
        numba = scene.backend == "numba"
    # one announcement per kernel numba compiles, whether for the scene or in the run
    with compile_notices(notice, numba=numba):
        compiled = compile(sc, backend) if isinstance(scene, Scene) else scene
        if est is not None:
            bound_growth(compiled, est, limits)
        targets = list(sinks)
        collector = None
        if output is not None:
            targets.append(open_sink(Path(output), None, meta_rate=sc.record.fps))
        elif keep:
            collector = TrajectoryCollector()
            targets.append(collector)
        extra = dict(meta or {})
        source = getattr(sc, "_source", None)
        if source:
            extra.setdefault("scene_sha256", source["sha256"])
            extra.setdefault("scene_file", source["file"])
        result = run(
            compiled,
            targets,
            stop=stop,
            progress=progress,
            notice=notice,
            observers=observers,
            meta_extra=extra,
        )
    if collector is None:
        empty = np.zeros((0, 0, 3))
        traj = Trajectory(np.zeros(0), [], empty, empty)
    else:
        traj = Trajectory.from_long(collector.trajectory())
    traj.status = result.status
    traj.failure = result.failure
    traj.meta = result.meta
    traj.header = compiled.header
    _fill_bodies(traj, compiled)
    traj.result = result
    traj.compiled = compiled
    return traj


def _fill_bodies(traj: Trajectory, compiled: Any) -> None:
    """body_ids and the (F, B, ...) body arrays of a run with rigid bodies (kept in memory)."""
    system = compiled.system
    long = traj.frames_long
    if not system.body_count or long is None or long.orientation is None:
        return
    rows = slice(system.body_first, system.body_first + system.body_count)
    traj.body_ids = list(system.body_ids)
    traj.body_positions = traj.positions[:, rows]
    f, n = long.frame_count, len(long.ids)
    q = np.full((f, n, 4), np.nan)
    w = np.full((f, n, 3), np.nan)
    frame_of_row = np.repeat(np.arange(f), np.diff(long.frame_start))
    q[frame_of_row, long.particle] = long.orientation
    w[frame_of_row, long.particle] = long.angular_velocity
    traj.body_orientations = q[:, rows]
    traj.body_angular_velocities = w[:, rows]
