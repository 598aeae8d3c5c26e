"""The ``<output>.meta.json`` file written beside every trajectory."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from animsim.atomic import AtomicFile, commit_together, writing


def meta_path(output: str | Path) -> Path:
    return Path(f"{output}.meta.json")


def meta_file(output: str | Path, meta: dict[str, Any]) -> AtomicFile:
    """Write the metadata to a temporary file; the caller commits it."""
    f = AtomicFile(meta_path(output), "w")
    try:
        with writing(f.path):
            f.handle.write(json.dumps(meta, indent=2, sort_keys=True, allow_nan=True) + "\n")
    except BaseException:
        f.abort()
        raise
    return f


def commit_with_meta(data: AtomicFile, output: str | Path, meta: dict[str, Any] | None) -> None:
    """Commit a finished output and its metadata together, or neither.

    Both are made whole (flushed, fsynced, closed) before either is renamed,
    so a full disk that shows only at fsync or close leaves the old
    trajectory *and* the old metadata in place (see atomic.commit_together).
    """
    try:
        staged = meta_file(output, meta) if meta is not None else None
    except BaseException:
        data.abort()
        raise
    commit_together(data, staged)


#: metadata that differs between two runs of the same scene and seed (timings): only the
#: ``.meta.json`` sidecar holds it, so a file that embeds the metadata (USD) is byte-identical
RUN_DEPENDENT_KEYS = frozenset({"wall_time", "compile_time"})


def reproducible(meta: dict[str, Any]) -> dict[str, Any]:
    """``meta`` without :data:`RUN_DEPENDENT_KEYS`: what a data file may embed."""
    return {k: v for k, v in meta.items() if str(k) not in RUN_DEPENDENT_KEYS}


UNITS = "SI: m, kg, s"
_AXES = "xyz"


def up_axis(gravity: tuple[float, float, float] | None) -> str:
    """The axis opposite to gravity when gravity points along one (``"y"``, ``"-z"``, ...), else ``"y"``.

    ``"y"`` is animsim's convention (the example scenes use g = [0, -9.81, 0])
    and what the USD export states unless gravity says Z is up.
    """
    if gravity is None:
        return "y"
    g = [float(c) for c in gravity]
    norm = sum(c * c for c in g) ** 0.5
    if norm == 0:
        return "y"
    k = max(range(3), key=lambda i: abs(g[i]))
    if abs(g[k]) < 0.999 * norm:  # tilted gravity: no axis is up
        return "y"
    return _AXES[k] if g[k] < 0 else f"-{_AXES[k]}"


def run_facts(compiled: Any, state: Any) -> dict[str, Any]:
    """Counts and conventions for ``meta.json`` that say what the numbers mean.

    ``particles``: particles that exist from the start (listed and structure
    ones), not the emitter pools; ``pool_size``: slots the emitters may fill;
    ``born``: particles the emitters made; ``alive_at_end``: particles alive in
    the final state; ``units``; ``up_axis`` (:func:`up_axis` of the scene's
    gravity); ``fps``: recorded frames per second (the scene's ``record.fps``,
    else one frame every ``record.every`` steps of ``dt``).
    """
    emitters = compiled.emitters
    pools = list(getattr(emitters, "pools", []) or [])
    pool_size = int(sum(p.capacity for p in pools))
    total = int(compiled.system.particle_count)
    fixed = total - pool_size
    alive = getattr(state, "particle_alive", None)
    alive_at_end = total if alive is None else int(alive.sum())
    scene = compiled.scene
    gravity = [f.g for f in scene.forces if getattr(f, "type", None) == "gravity"]
    g = tuple(sum(v[i] for v in gravity) for i in range(3)) if gravity else None
    if scene.record.fps is not None:
        fps = float(scene.record.fps)
    else:
        fps = 1.0 / (compiled.clock.dt * (scene.record.every or 1))
    return {
        "particles": fixed,
        "pool_size": pool_size,
        "born": int(sum(p.born for p in pools)),
        "alive_at_end": alive_at_end,
        "units": UNITS,
        "up_axis": up_axis(g),  # type: ignore[arg-type]
        "fps": fps,
    }
