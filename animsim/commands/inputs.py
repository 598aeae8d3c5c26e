"""A scene on its way into a command: loaded, with its overrides checked by the file's
rules, through the pre-flight (step and memory limits, the support table) before anything
is allocated; and the command's output paths checked before the first step.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from animsim import support
from animsim.backends import choose_backend
from animsim.commands.arguments import check_overrides
from animsim.compile import with_overrides
from animsim.errors import UsageError
from animsim.export.meta import meta_path
from animsim.preflight import RunLimits, check_limits, check_output_path
from animsim.scene.loader import load_scene
from animsim.scene.models import Scene
from animsim.scene.yaml_reader import Marks


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
    """See :func:`animsim.api.prepare`."""
    check_overrides(dt=dt, duration=duration, seed=seed)
    limits = limits or RunLimits()
    sc = scene
    if any(v is not None for v in (integrator, dt, duration, seed)):
        sc = with_overrides(sc, integrator=integrator, dt=dt, duration=duration, seed=seed)

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
    """See :func:`animsim.api.prepare_file`."""
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
        return Marks()

    @property
    def file(self) -> str:
        return (getattr(self.scene, "_source", None) or {}).get("file", "<python>")


def prepared(source: str | Path | Scene, limits: Any, **overrides: Any) -> tuple[Scene, str, Any, Any]:
    """(scene with overrides, name, pre-flight estimate, loaded file or None) of a path or a Scene."""
    if isinstance(source, Scene):
        sc, est = prepare(source, limits=limits, **overrides)
        return sc, source.name or "scene", est, None
    loaded, sc, est = prepare_file(Path(source), limits, **overrides)
    return sc, loaded.name, est, loaded


def source_label(source: Any) -> str:
    return str(source) if isinstance(source, str | Path) else (getattr(source, "name", None) or "scene")


def check_output(output: Path, source: Any) -> None:
    check_output_path(output, Path(source) if isinstance(source, str | Path) else Path("scene.yaml"))


def refuse_bodies_in_file(traj: Any, path: Path, what: str, instead: str) -> None:
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


def bound_growth(compiled: Any, est: Any, limits: Any) -> None:
    """What grows during the run (particle contacts' candidate list) stays within the memory
    limit left after the rest of the pre-flight's estimate (StepStage.bound_memory)."""
    budget = est.growth_budget(limits or RunLimits())
    for stage in compiled.post_step:
        stage.bound_memory(budget)


def uses_numba(backend: str) -> bool:
    return choose_backend(backend)[0] == "numba"
