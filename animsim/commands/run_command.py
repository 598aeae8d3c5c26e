"""``animsim run`` as one call: a scene simulated into a trajectory file and its
``.meta.json``, everything that can be refused refused before the first step.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from animsim.commands.inputs import bound_growth, check_output, prepared, uses_numba
from animsim.commands.outcomes import RunOutcome
from animsim.commands.simulation import compile, simulate
from animsim.compile_notice import compile_notices
from animsim.errors import UsageError
from animsim.export.sinks import format_for, open_sink
from animsim.measures import stability
from animsim.measures.drift import DEFAULT_DRIFT_WARN_PERCENT, META_THRESHOLD_KEY, check_threshold
from animsim.preflight import RunLimits, check_disk, check_ply_output
from animsim.record import recording_rule
from animsim.scene.loader import scene_stem
from animsim.scene.models import Scene


def run_command(
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
    """The work of :func:`animsim.api.run`."""
    limits = limits or RunLimits()
    threshold = check_threshold(DEFAULT_DRIFT_WARN_PERCENT if drift_warn is None else drift_warn)
    to_stdout = output is not None and str(output) == "-"
    fmt = format_for(None if output is None else Path(output), fmt)

    name_of = scene_stem(source) if isinstance(source, str | Path) else (source.name or "scene")
    out = Path(output) if output is not None else Path(f"{name_of}.{fmt}")
    if to_stdout and fmt != "csv":
        raise UsageError(f"--format {fmt} cannot go to stdout; give a file with -o")
    sc, name, est, loaded = prepared(
        source, limits, fmt=fmt, integrator=integrator, dt=dt, duration=duration, seed=seed, consumer=fmt
    )
    scene_path = Path(source) if isinstance(source, str | Path) else Path(f"{name}.yaml")
    if fmt == "ply":
        check_ply_output(out, scene_path)
    elif not to_stdout:
        check_output(out, scene_path)
        check_disk(out, est, fmt, sc, limits)

    # every kernel numba compiles (scene compile, first steps, births) is announced as it starts
    with compile_notices(notice, numba=uses_numba(backend)):
        compiled = compile(sc, backend, name=name)
        bound_growth(compiled, est, limits)
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
