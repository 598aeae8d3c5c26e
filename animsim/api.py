"""The Python API: what notebooks, scripts and every ``animsim`` command call.

    scene = animsim.load("scenes/cloth.yaml")      # or animsim.loads(text)
    traj = animsim.simulate(scene)                 # a Trajectory
    traj.positions                                 # (F, N, 3), NaN where not alive
    rows = animsim.compare(scene, integrators=["euler", "rk4"], dts=[0.01, 0.005])

Bad scenes raise :class:`animsim.SceneError`, whose ``diagnostics`` are the
``FILE:LINE:COLUMN: key.path: message`` lines the command line prints.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from animsim.errors import SceneError, UsageError
from animsim.scene.models import Scene


def _type_name(value: Any) -> str:
    return "None" if value is None else type(value).__name__


def load(path: str | Path, *, limits: Any = None) -> Scene:
    """Read, parse and validate a scene file (every problem as a SceneError)."""
    from animsim.preflight import check_starts
    from animsim.scene.loader import Limits, load_scene

    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"load() takes the path of a scene file (str or Path), not {_type_name(path)}")

    loaded = load_scene(path, limits or Limits())
    check_starts(loaded, loaded.scene)
    return _named(loaded)


def loads(text: str, name: str = "scene", *, limits: Any = None) -> Scene:
    """The same from YAML text; diagnostics name the file ``<name>``."""
    from animsim.preflight import check_starts
    from animsim.scene.loader import Limits, load_scene_text

    if not isinstance(text, str):
        hint = "; for a file use load(path)" if isinstance(text, os.PathLike) else ""
        raise TypeError(f"loads() takes the scene's YAML text as a str, not {_type_name(text)}{hint}")

    loaded = load_scene_text(text, f"<{name}>", limits or Limits())
    check_starts(loaded, loaded.scene)
    scene = _named(loaded)
    return scene if scene.name else scene.model_copy(update={"name": name})


def _named(loaded: Any) -> Scene:
    scene = loaded.scene if loaded.scene.name else loaded.scene.model_copy(update={"name": loaded.name})
    scene._source = {"file": loaded.file, "sha256": loaded.sha256}
    return scene


def _bound_growth(compiled: Any, est: Any, limits: Any) -> None:
    """What grows during the run (particle contacts' candidate list) stays within the memory
    limit left after the rest of the pre-flight's estimate (StepStage.bound_memory)."""
    from animsim.preflight import RunLimits

    budget = est.growth_budget(limits or RunLimits())
    for stage in compiled.post_step:
        stage.bound_memory(budget)


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
    from animsim.preflight import RunLimits, check_limits

    _check_overrides(dt=dt, duration=duration, seed=seed)
    limits = limits or RunLimits()
    sc = scene
    if any(v is not None for v in (integrator, dt, duration, seed)):
        from animsim.compile import with_overrides

        sc = with_overrides(sc, integrator=integrator, dt=dt, duration=duration, seed=seed)
    from animsim import support

    source = loaded if loaded is not None else _Loaded(scene)
    est = check_limits(source, sc, limits, fmt=fmt, overridden=dt is not None or duration is not None)
    support.check(source, sc, consumer)
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
    consumer: str | None = None,
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
        consumer=consumer,
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
    from animsim.compile import Compiled
    from animsim.compile_notice import compile_notices
    from animsim.engine import run
    from animsim.export.trajectory import TrajectoryCollector

    if not isinstance(scene, Scene | Compiled | dict):  # a dict is read as a scene (SceneError if wrong)
        hint = "; for a scene file use simulate(load(path))" if isinstance(scene, str | os.PathLike) else ""
        raise TypeError(
            f"simulate() takes a Scene (from load or loads) or a compiled scene, not {_type_name(scene)}{hint}"
        )
    if isinstance(scene, Scene):
        sc, est = prepare(scene, integrator=integrator, dt=dt, duration=duration, seed=seed, limits=limits)
        numba = _uses_numba(backend)
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
            _bound_growth(compiled, est, limits)
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


#: the largest seed: seeds are stored and hashed as signed 64-bit integers (the scene key's bound)
MAX_SEED = 2**63 - 1


def _check_overrides(*, dt: Any = None, duration: Any = None, seed: Any = None) -> None:
    """TypeError for overrides of the wrong type (a str dt, a float seed); the values' ranges are
    checked with the file's rules when they are applied."""
    import numbers

    for key, value in (("dt", dt), ("duration", duration)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise TypeError(f"{key} must be a number of seconds, not {_type_name(value)} {value!r}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral)):
        raise TypeError(f"seed must be a whole number from 0 to {MAX_SEED}, not {_type_name(seed)} {seed!r}")


def _uses_numba(backend: str) -> bool:
    from animsim.backends import choose_backend

    return choose_backend(backend)[0] == "numba"


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
    from dataclasses import asdict

    from animsim.analysis import compare as cmp

    source = scene  # what the outputs must not overwrite (a file), see _check_output
    if not isinstance(scene, Scene):
        loaded, _, _ = prepare_file(Path(scene), limits, consumer="compare")  # the file's limits
        scene, name = loaded.scene, name or loaded.name
    for path in (output, plot):
        if path is not None:
            _check_output(Path(path), source)
    if plot is not None:
        from animsim.export.plots import plot_format

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
        from animsim.export.plots import write_compare_plot

        write_compare_plot(result, Path(plot))
    return result if comparison else [asdict(row) for row in result.rows]


# --- what each command does, as one call ------------------------------------------------
# The command line parses options, makes one of these calls, prints and sets the exit
# status; everything between (pre-flight, sinks, compiling, drawing) happens here.


def _source_label(source: Any) -> str:
    return str(source) if isinstance(source, str | Path) else (getattr(source, "name", None) or "scene")


def _prepared(source: str | Path | Scene, limits: Any, **overrides: Any) -> tuple[Scene, str, Any, Any]:
    """(scene with overrides, name, pre-flight estimate, loaded file or None) of a path or a Scene."""
    if isinstance(source, Scene):
        sc, est = prepare(source, limits=limits, **overrides)
        return sc, source.name or "scene", est, None
    loaded, sc, est = prepare_file(Path(source), limits, **overrides)
    return sc, loaded.name, est, loaded


def _refuse_bodies_in_file(traj: Any, path: Path, what: str, instead: str) -> None:
    """A trajectory file with rigid bodies and not their shapes (a CSV; an NPZ carries them),
    drawn without its scene, would show them as dots; a run with solid colliders (its
    sidecar says how many) from a file that does not carry them would leave them out.
    Both refused before anything is drawn (the support table's cells, for a file without
    a scene)."""
    q = traj.orientation
    drawn = traj.drawables or {}
    if q is not None and np.isfinite(q).any() and not drawn.get("bodies"):
        raise UsageError(
            f"{path}: the file holds rigid bodies, which {what} draws as dots at their centres; {instead}"
        )
    from animsim.export.meta import meta_path

    try:
        count = json.loads(meta_path(path).read_text(encoding="utf-8")).get("solid_colliders", 0)
    except (OSError, ValueError, AttributeError):  # no sidecar, or not one of ours: nothing to say
        count = 0
    if isinstance(count, int) and count > 0 and not drawn.get("colliders"):
        raise UsageError(
            f"{path}: the run had {count} solid collider(s), which this file does not carry, so "
            f"{what} would leave them out; {instead}, or give the scene with --scene, or write the "
            "run as NPZ (-o run.npz), which carries them"
        )


def _check_output(output: Path, source: Any) -> None:
    from animsim.preflight import check_output_path

    check_output_path(output, Path(source) if isinstance(source, str | Path) else Path("scene.yaml"))


@dataclass
class RunOutcome:
    """What :func:`run` did: the compiled scene, the engine's result and the files written."""

    compiled: Any
    result: Any
    output: Path
    #: the files written, as a phrase for a summary; None when the frames went to stdout
    wrote: str | None

    @property
    def status(self) -> str:
        return self.result.status


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
    from animsim.export.sinks import format_for, open_sink
    from animsim.measures import stability
    from animsim.measures.drift import DEFAULT_DRIFT_WARN_PERCENT, META_THRESHOLD_KEY, check_threshold
    from animsim.preflight import RunLimits, check_disk, check_ply_output
    from animsim.record import recording_rule

    limits = limits or RunLimits()
    threshold = check_threshold(DEFAULT_DRIFT_WARN_PERCENT if drift_warn is None else drift_warn)
    to_stdout = output is not None and str(output) == "-"
    fmt = format_for(None if output is None else Path(output), fmt)
    from animsim.scene.loader import scene_stem

    name_of = scene_stem(source) if isinstance(source, str | Path) else (source.name or "scene")
    out = Path(output) if output is not None else Path(f"{name_of}.{fmt}")
    if to_stdout and fmt != "csv":
        raise UsageError(f"--format {fmt} cannot go to stdout; give a file with -o")
    sc, name, est, loaded = _prepared(
        source, limits, fmt=fmt, integrator=integrator, dt=dt, duration=duration, seed=seed, consumer=fmt
    )
    scene_path = Path(source) if isinstance(source, str | Path) else Path(f"{name}.yaml")
    if fmt == "ply":
        check_ply_output(out, scene_path)
    elif not to_stdout:
        _check_output(out, scene_path)
        check_disk(out, est, fmt, sc, limits)
    from animsim.compile_notice import compile_notices

    # every kernel numba compiles (scene compile, first steps, births) is announced as it starts
    with compile_notices(notice, numba=_uses_numba(backend)):
        compiled = compile(sc, backend, name=name)
        _bound_growth(compiled, est, limits)
        report = stability.analyse(compiled)
        if report.dt_exceeds_limit and warn is not None:  # before the first step; the watchdog judges
            warn(f"warning: {report.verdict()}")
        sink: Any = open_sink(
            Path("-") if to_stdout else out,
            fmt,
            # the frame rate recorded at, when there is one (the scene's, or the 60 fps default)
            meta_rate=recording_rule(sc.record.every, sc.record.fps, compiled.clock.dt)[1],
            extra_columns=extra_columns,
            expected_frames=len(compiled.record_steps),
        )
        extra: dict[str, Any] = {META_THRESHOLD_KEY: threshold}
        if loaded is not None:
            extra.update(scene_sha256=loaded.sha256, scene_file=str(source))
        result = simulate(
            compiled, sinks=[sink], keep=False, stop=stop, progress=progress, meta=extra, notice=notice
        ).result
    wrote: str | None = None if to_stdout else f"{out} and {out}.meta.json"
    if fmt == "ply" and sink.written:
        first, last = sink.written[0], sink.written[-1]
        span = f"{first}" if first == last else f"{first} .. {last.name}"
        wrote = f"{len(sink.written)} PLY frames {span}, {sink.ids_path} and {out}.meta.json"
    if fmt == "vtp" and sink.times:
        frames = [p for p in sink.written if p.suffix == ".vtp"]
        span = f"{frames[0]}" if len(frames) == 1 else f"{frames[0]} .. {frames[-1].name}"
        wrote = f"{sink.pvd_path} ({len(frames)} VTK frames {span}), {sink.ids_path} and {out}.meta.json"
    return RunOutcome(compiled, result, out, wrote)


def explain(
    source: str | Path | Scene,
    *,
    integrator: str | None = None,
    backend: str = "auto",
    limits: Any = None,
) -> list[str]:
    """What a scene compiles to, as the lines ``animsim explain`` prints: counts, the
    stages each step runs, and what was left out because the scene does not need it."""
    from animsim.console import count_text, point_particles
    from animsim.measures.effective import fallback_note

    sc, name, _, _ = _prepared(source, limits, integrator=integrator, consumer="explain")
    c = compile(sc, backend, name=name)
    s = c.system
    points, pinned = point_particles(s)
    lines = [
        f"scene {c.name!r} ({_source_label(source)})",
        f"  {points} particles ({pinned} pinned), {s.spring_count} springs, "
        f"{len(sc.planes)} planes, {len(sc.emitters)} emitters"
        + (f", {count_text(s.body_count, 'rigid body', 'rigid bodies')}" if s.body_count else ""),
        f"  {c.clock.steps} steps of {c.clock.dt:g} s to t = {c.clock.duration:g} s, seed {c.seed}",
        "each step runs:",
    ]
    note = fallback_note(c)
    for stage in c.stages:
        if note is not None and stage.startswith("integrator:"):
            stage = f"integrator: {note}"  # what the step really computes
        lines.append(f"  + {stage}")
    lines.append("left out (the scene does not need them):")
    lines.extend(f"  - {item}" for item in c.left_out)
    return lines


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
    from animsim.export.trajectory import is_trajectory, read_trajectory
    from animsim.render import RenderOptions, render_scene, render_trajectory, validate
    from animsim.scene import models as m

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
            _check_output(out, source)
    from_file = isinstance(source, str | Path) and is_trajectory(Path(source))
    if integrators is not None:
        if from_file or isinstance(source, Trajectory):
            raise UsageError(
                "--integrators simulates the scene once per method: give the scene, not a trajectory"
            )
        if integrator is not None:
            raise UsageError("give --integrator or --integrators, not both")
        from animsim.commands.side_by_side import render_side_by_side
        from animsim.panel_runs import compile_each

        names = _integrator_names(integrators)
        sc, name, _, _ = _prepared(
            source,  # type: ignore[arg-type]
            limits,
            dt=dt,
            duration=duration,
            consumer="render",
        )
        sc = sc.model_copy(update={"record": m.Record(fps=fps)})
        result = render_side_by_side(
            compile_each(sc, name, names, backend), gif_path, mp4_path, opts, stop=stop
        )
        result.panels = list(names)
        return result
    if isinstance(source, Trajectory):
        return render_trajectory(source.frames_long, gif_path, mp4_path, opts, compiled=source.compiled)
    compiled = None
    traj_path = Path(source) if from_file and isinstance(source, str | Path) else None
    from_traj = None if traj_path is None else read_trajectory(traj_path)
    if traj_path is not None and scene is None:
        what = "a render of a trajectory file"
        _refuse_bodies_in_file(from_traj, traj_path, what, "render the scene: animsim render SCENE")
    scene_source = (Path(scene) if scene is not None else None) if from_file else source
    if scene_source is not None:
        sc, name, est, _ = _prepared(
            scene_source,
            limits,
            integrator=integrator,
            dt=dt,
            duration=duration,
            consumer="render_trajectory" if from_file else "render",
        )
        if not from_file:
            sc = sc.model_copy(update={"record": m.Record(fps=fps)})  # exactly the frames shown
        from animsim.compile import compile_scene

        # a trajectory's scene is only drawn (springs, planes), never stepped: NumPy compiles it
        compiled = compile_scene(sc, name, backend="numpy" if from_file else backend)
        _bound_growth(compiled, est, limits)
    if from_traj is not None:
        return render_trajectory(from_traj, gif_path, mp4_path, opts, compiled=compiled)
    total = compiled.record_steps.size
    tick = None if progress is None else (lambda done: progress(done, total))
    return render_scene(compiled, gif_path, mp4_path, opts, progress=tick, stop=stop)


def _integrator_names(integrators: str | Sequence[str]) -> list[str]:
    from animsim.analysis.compare import parse_integrators

    text = integrators if isinstance(integrators, str) else ",".join(integrators)
    return list(parse_integrators(text))


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
    import contextlib

    from animsim.commands.viewer_command import write_view
    from animsim.export.viewer import VIEWS

    if view not in VIEWS:
        raise UsageError(f"--view {view!r}: choose one of {', '.join(VIEWS)}")
    if not (fps > 0 and fps < float("inf")):
        raise UsageError(f"--fps {fps}: must be a number > 0")
    out = Path(output)
    if out.suffix.lower() not in (".html", ".htm"):
        raise UsageError(f"-o {out}: the file name must end in .html")
    _check_output(out, source)
    from animsim.export.trajectory import is_trajectory, read_trajectory

    if scene is None and is_trajectory(Path(source)):
        _refuse_bodies_in_file(
            read_trajectory(Path(source)), Path(source), "the viewer", "use animsim render SCENE --view 3d"
        )
    return write_view(
        Path(source),
        out,
        prepare=lambda path, **kw: prepare_file(path, limits, consumer="view", **kw),
        integrators=None if integrators is None else ",".join(_integrator_names(integrators)),
        fps=fps,
        view=view,
        scene=None if scene is None else Path(scene),
        integrator=integrator,
        dt=dt,
        duration=duration,
        stop_context=lambda: contextlib.nullcontext(stop),
        backend=backend,
    )


PLOT_KINDS = ("trajectory", "energy", "phase")


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
    from animsim.export.pictures import AXES, VIEW_NAMES, figure_format, plot_trajectory
    from animsim.export.trajectory import is_trajectory, read_trajectory

    out, src = Path(output), Path(source)
    if kind not in PLOT_KINDS:
        raise UsageError(f"--kind {kind!r}: choose one of {', '.join(PLOT_KINDS)}")
    figure_format(out)
    if view is not None and view not in AXES:
        raise UsageError(f"--view {view!r}: plot takes {VIEW_NAMES}")
    _check_output(out, src)
    from_file = is_trajectory(src)
    if kind != "phase" and (integrators is not None or particles is not None):
        raise UsageError("--integrators and --particles go with --kind phase")
    prepare_path = lambda path, **kw: prepare_file(path, limits, consumer="plot", **kw)  # noqa: E731
    if kind == "phase":
        from animsim.commands.phase import phase_command

        phase_command(
            src,
            out,
            from_file=from_file,
            scene=None if scene is None else Path(scene),
            prepare=prepare_path,
            integrators=None if integrators is None else ",".join(_integrator_names(integrators)),
            particles=particles if particles is None or isinstance(particles, str) else ",".join(particles),
            integrator=integrator,
            dt=dt,
            duration=duration,
            backend=backend,
        )
        return out
    scene_path = (None if scene is None else Path(scene)) if from_file else src
    compiled = None
    if scene_path is not None:
        from animsim.compile import compile_scene

        loaded, sc, _ = prepare_path(scene_path, integrator=integrator, dt=dt, duration=duration)
        # simulated for the energy of a scene; a trajectory's scene is only read
        compiled = compile_scene(sc, loaded.name, backend="numpy" if from_file else backend)
    if kind == "energy":
        if compiled is None:
            raise UsageError("--kind energy needs the scene: give a scene, or --scene with the trajectory")
        from animsim.commands.phase import energy_parts_of
        from animsim.export.pictures import plot_energy_parts

        times, parts = energy_parts_of(compiled, read_trajectory(src) if from_file else None)
        plot_energy_parts(
            times,
            parts,
            out,
            title=f"{compiled.name}: {compiled.integrator_name}, dt {compiled.clock.dt:g} s",
            conservative=compiled.conservative,
        )
        return out
    if from_file:
        traj, name = read_trajectory(src), src.stem
    else:
        assert compiled is not None
        traj, name = simulate(compiled).frames_long, compiled.name
    from animsim.render import view_up

    plot_trajectory(
        traj, out, view=view, title=name, up=None if compiled is None else view_up(compiled.scene)
    )
    return out


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
    from animsim.analysis import sweep as sw
    from animsim.preflight import RunLimits
    from animsim.scene.loader import load_scene

    src = Path(source)
    # The file limits apply here; each case's step and memory pre-flight would need
    # the sweep's own variants (see docs/limits.md).
    limits = limits or RunLimits()
    loaded = load_scene(src, limits.loader)
    from animsim import support

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
        _check_output(Path(plot), src)
    if output is not None:
        _check_output(Path(output), src)
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
        from animsim.commands import sweep_plot

        sweep_plot.plot_table(table, Path(plot), x_key, y_col)
    return table


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
