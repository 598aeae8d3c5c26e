"""The Python API: what notebooks, scripts and every ``animsim`` command call.

    scene = animsim.load("scenes/cloth.yaml")      # or animsim.loads(text)
    traj = animsim.simulate(scene)                 # a Trajectory
    traj.positions                                 # (F, N, 3), NaN where not alive
    rows = animsim.compare(scene, integrators=["euler", "rk4"], dts=[0.01, 0.005])

Bad scenes raise :class:`animsim.SceneError`, whose ``diagnostics`` are the
``FILE:LINE:COLUMN: key.path: message`` lines the command line prints.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from animsim.errors import SceneError, UsageError
from animsim.scene.models import Scene


def load(path: str | Path, *, limits: Any = None) -> Scene:
    """Read, parse and validate a scene file (every problem as a SceneError)."""
    from animsim.scene.loader import Limits, load_scene

    loaded = load_scene(path, limits or Limits())
    return _named(loaded)


def loads(text: str, name: str = "scene", *, limits: Any = None) -> Scene:
    """The same from YAML text; diagnostics name the file ``<name>``."""
    from animsim.scene.loader import Limits, load_scene_text

    loaded = load_scene_text(text, f"<{name}>", limits or Limits())
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
) -> tuple[Scene, Any]:
    """The scene with overrides (checked by the file's rules) and its pre-flight estimate.

    Refuses (UsageError, exit 2) a run that would exceed the step or memory
    limits before anything is allocated.
    """
    from animsim.preflight import RunLimits, check_limits

    limits = limits or RunLimits()
    sc = scene
    if any(v is not None for v in (integrator, dt, duration, seed)):
        from animsim.compile import with_overrides

        sc = with_overrides(sc, integrator=integrator, dt=dt, duration=duration, seed=seed)
    est = check_limits(
        loaded if loaded is not None else _Loaded(scene),
        sc,
        limits,
        fmt=fmt,
        overridden=dt is not None or duration is not None,
    )
    return sc, est


def prepare_file(
    path: Path,
    limits: Any,
    *,
    fmt: str = "csv",
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    seed: int | None = None,
) -> tuple[Any, Scene, Any]:
    """Load a scene file, apply overrides and check the step and memory limits.

    Every command that compiles a scene goes through here, so none of them
    allocates before the pre-flight has said the scene fits. Returns
    (LoadedScene, Scene with overrides, preflight.Estimate).
    """
    from animsim.preflight import RunLimits
    from animsim.scene.loader import load_scene

    limits = limits or RunLimits()
    loaded = load_scene(path, limits.loader)
    sc, est = prepare(
        loaded.scene,
        integrator=integrator,
        dt=dt,
        duration=duration,
        seed=seed,
        limits=limits,
        fmt=fmt,
        loaded=loaded,
    )
    return loaded, sc, est


@dataclass
class _Loaded:
    """What the pre-flight reads of a loaded file, for a scene made in Python."""

    scene: Scene

    @property
    def marks(self) -> Any:
        from animsim.scene.loader import Marks

        return Marks()

    @property
    def file(self) -> str:
        return (getattr(self.scene, "_source", None) or {}).get("file", "<python>")


@dataclass
class Trajectory:
    """A simulated run: frames as arrays, plus how the run went.

    ``positions`` and ``velocities`` are (F, N, 3) float64 with N every
    particle that lived, in creation order (``ids``), and NaN where a particle
    was not alive. With rigid bodies, ``body_*`` arrays hold the bodies.
    """

    times: np.ndarray
    ids: list[str]
    positions: np.ndarray
    velocities: np.ndarray
    status: str = "ok"
    failure: Any = None
    meta: dict[str, Any] = field(default_factory=dict)
    #: the same frames in long form (one row per alive particle), for exporters and pictures
    frames_long: Any = None
    #: the header of the run (springs, planes, ...), for exporters
    header: Any = None
    #: the engine's account of the run (steps, wall time, energies) and the compiled scene
    result: Any = None
    compiled: Any = None
    body_ids: list[str] = field(default_factory=list)
    body_positions: np.ndarray | None = None
    body_orientations: np.ndarray | None = None
    body_angular_velocities: np.ndarray | None = None

    @classmethod
    def from_long(cls, long: Any, **kw: Any) -> Trajectory:
        """Dense arrays from a long-form trajectory (:class:`animsim.export.trajectory.Trajectory`)."""
        f, n = long.frame_count, len(long.ids)
        x = np.full((f, n, 3), np.nan)
        v = np.full((f, n, 3), np.nan)
        frame_of_row = np.repeat(np.arange(f), np.diff(long.frame_start))
        x[frame_of_row, long.particle] = long.position
        v[frame_of_row, long.particle] = long.velocity
        return cls(np.asarray(long.times, dtype=np.float64), list(long.ids), x, v, frames_long=long, **kw)

    def to_pandas(self) -> Any:
        """A long DataFrame t, id, x, y, z, vx, vy, vz (rows of alive particles). Needs pandas."""
        try:
            import pandas as pd
        except ImportError:  # pragma: no cover - depends on the environment
            raise UsageError("to_pandas needs pandas: pip install pandas") from None
        alive = ~np.isnan(self.positions[..., 0])
        fi, pi = np.nonzero(alive)
        ids = np.array(self.ids, dtype=object)
        x, v = self.positions[fi, pi], self.velocities[fi, pi]
        return pd.DataFrame(
            {
                "t": self.times[fi],
                "id": ids[pi],
                "x": x[:, 0],
                "y": x[:, 1],
                "z": x[:, 2],
                "vx": v[:, 0],
                "vy": v[:, 1],
                "vz": v[:, 2],
            }
        )

    def save(self, path: str | Path, *, fmt: str | None = None) -> Path:
        """Write the trajectory in any format ``animsim run`` writes, chosen by suffix (atomic)."""
        from animsim.export.sinks import open_sink

        out = Path(path)
        sink = open_sink(out, fmt, meta_rate=None)
        sink.begin(self.header)
        for frame in self.frames_long.frames():
            sink.write(frame)
        sink.close(self.meta)
        return out

    def _repr_html_(self) -> str:
        from animsim.export import viewer

        return viewer.trajectory_html(self)


def compile(scene: Scene, backend: str = "auto", *, name: str | None = None) -> Any:
    """The compiled scene (:class:`animsim.compile.Compiled`) that :func:`simulate` runs:
    what ``explain`` shows and the stability analysis reads, before any step."""
    from animsim.compile import compile_scene

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
    """Run ``scene`` (with overrides as on the command line) and return its Trajectory.

    ``scene`` may also be what :func:`compile` returned (then the overrides must
    be None). ``output``: stream the frames to a file instead of keeping them in
    memory (any format ``animsim run`` writes, by suffix); the Trajectory then
    holds the metadata only. ``sinks``: more frame sinks to feed; ``keep=False``
    keeps no frames in memory (the sinks have them).
    """
    from animsim.engine import run
    from animsim.export.trajectory import TrajectoryCollector

    if isinstance(scene, Scene):
        sc, _ = prepare(scene, integrator=integrator, dt=dt, duration=duration, seed=seed, limits=limits)
        compiled = compile(sc, backend)
    else:
        if any(v is not None for v in (integrator, dt, duration, seed)):
            raise UsageError("overrides go with a Scene, not with an already compiled scene")
        compiled = scene
        sc = compiled.scene
    targets = list(sinks)
    collector = None
    if output is not None:
        from animsim.export.sinks import open_sink

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
        compiled, targets, stop=stop, progress=progress, notice=notice, observers=observers, meta_extra=extra
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


def compare(
    scene: Scene,
    integrators: Sequence[str] | None = None,
    dts: Sequence[float] | None = None,
    *,
    reference: str = "auto",
    repeat: int = 1,
    comparison: bool = False,
    duration: float | None = None,
    budget: float | None = None,
    backend: str = "numpy",
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
    before the runs start.
    """
    from dataclasses import asdict

    from animsim.analysis import compare as cmp

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
    return result if comparison else [asdict(row) for row in result.rows]


__all__ = ["Scene", "SceneError", "Trajectory", "compare", "compile", "load", "loads", "prepare", "simulate"]
