"""``animsim check``: validate, analyse and run each scene, report drift and stability.

This is what CI runs over ``scenes/``: exit 0 only if every scene is valid and
ran stable.
"""

from __future__ import annotations

import shutil
import textwrap
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from animsim.compile import compile_scene
from animsim.console import table_width
from animsim.engine import STATUS_OK, run
from animsim.errors import AnimsimError
from animsim.measures import stability
from animsim.measures.drift import DEFAULT_DRIFT_WARN_PERCENT, drift
from animsim.measures.effective import fallback_note

# Below this energy scale (J) a relative drift means nothing; report absolute.
ENERGY_FLOOR = 1e-12


def energy_drift(e0: float, e1: float) -> float:
    """Relative energy change (e1 - e0)/|e0|, against a floor for scenes near zero energy."""
    return (e1 - e0) / max(abs(e0), ENERGY_FLOOR)


def _energy_report(compiled: Any, result: Any, drift_warn: float) -> str:
    """Energy at start and end, and the drift verdict (animsim.measures.drift)."""
    text = f"energy {result.energy_start:.4g} -> {result.energy_end:.4g} J"
    verdict = drift(compiled, result.energy_start, result.energy_end, drift_warn)
    if verdict.relative is None:
        return f"{text}, {verdict.text()}"
    return f"{text}, {verdict.text()}: integration error, the scene being conservative"


def _momentum_report(compiled: Any, result: Any) -> str:
    """Angular momentum about the origin at the start and the end (scenes with rigid bodies)."""
    dyn = compiled.dynamics
    ends = []
    for state in (compiled.initial, result.final_state):
        mass = np.where(state.particle_inv_mass > 0, state.particle_mass, 0.0)
        ends.append(
            dyn.bodies.angular_momentum(
                state.particle_position,
                state.particle_velocity,
                state.body_orientation,
                state.body_angular_velocity,
                mass,
            )
        )
    l0, l1 = (float(np.linalg.norm(v)) for v in ends)
    return f"angular momentum |L| {l0:.6g} -> {l1:.6g} kg m^2/s (about the origin, particles and bodies)"


def check_scenes(
    paths: Sequence[Path],
    *,
    prepare: Callable[[Path, Any], tuple[Any, Any, Any]],
    quiet: bool = False,
    echo: Callable[[str], None] = print,
    echo_err: Callable[[str], None] = print,
    limits: Any = None,
    drift_warn: float | None = None,
    backend: str = "auto",
) -> bool:
    """``prepare(path, limits)`` loads a scene file as every command does (the API's
    ``prepare_file``: the load, the overrides and the pre-flight, giving (LoadedScene, Scene,
    Estimate)); ``limits`` (a preflight.RunLimits) bounds every scene as ``animsim run`` would;
    ``drift_warn`` (percent) is the energy drift above which a conservative scene gets a warning."""
    warn = DEFAULT_DRIFT_WARN_PERCENT if drift_warn is None else drift_warn
    all_ok = True
    tally: dict[str, int] = {}
    for path in paths:
        try:
            loaded, scene, _ = prepare(path, limits, consumer="check")
            compiled = compile_scene(scene, loaded.name, backend=backend)
        except AnimsimError as exc:
            echo_err(str(exc))
            echo_err(f"{path}: INVALID")
            all_ok = False
            tally["invalid"] = tally.get("invalid", 0) + 1
            continue
        notes = []
        report = stability.analyse(compiled)
        fallback = fallback_note(compiled)
        if fallback is not None:
            notes.append(f"note: {fallback}")
        if report is not None:
            notes.extend(report.lines())
            if report.dt_exceeds_limit:
                notes.append("warning: dt exceeds the stable limit for this integrator")
        result = run(compiled)
        tally[result.status] = tally.get(result.status, 0) + 1
        head = [
            f"{path}: {result.status} ({compiled.integrator_name}, dt {compiled.clock.dt:g}, "
            f"{result.steps_taken} steps, {result.wall_time:.2f} s)",
            f"  {_energy_report(compiled, result, warn)}",
        ]
        verdict = drift(compiled, result.energy_start, result.energy_end, warn)
        if verdict.warning and result.status == STATUS_OK:
            echo_err(wrap(f"{path}: warning: {verdict.warning_text()}"))
        if compiled.system.body_count:
            notes.append(_momentum_report(compiled, result))
        if result.status != STATUS_OK:
            all_ok = False
            for line in head:
                echo_err(wrap(line))
            if result.failure is not None:
                echo_err(wrap("  " + result.failure.describe()))
        elif not quiet:
            for line in head:
                echo(wrap(line))
        if not quiet or result.status != STATUS_OK:
            for line in notes:
                echo(wrap(f"  {line}"))
    # Always, also with --quiet: silence after a check reads as "did it run?".
    echo(tally_line(len(paths), tally))
    return all_ok


def wrap(line: str, width: int | None = None) -> str:
    """``line`` broken at spaces to the screen's width, continuation lines indented under it.

    Numbers never break (no word is split), so a narrow terminal shows them whole.
    """
    width = width or table_width() or shutil.get_terminal_size().columns
    if len(line) <= width:
        return line
    indent = " " * (len(line) - len(line.lstrip(" ")) + 4)
    return textwrap.fill(
        line,
        width=width,
        subsequent_indent=indent,
        break_long_words=False,
        break_on_hyphens=False,
    )


def tally_line(total: int, tally: dict[str, int]) -> str:
    """``12 scenes: 11 ok, 1 unstable`` (ok first, then the rest by name)."""
    order = sorted(tally, key=lambda status: (status != "ok", status))
    counts = ", ".join(f"{tally[status]} {status}" for status in order)
    return f"{total} scene{'s' if total != 1 else ''}: {counts}"
