"""``animsim check``: validate, analyse and run each scene, report drift and stability.

This is what CI runs over ``scenes/``: exit 0 only if every scene is valid and
ran stable.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from animsim.errors import AnimsimError

# Below this energy scale (J) a relative drift means nothing; report absolute.
ENERGY_FLOOR = 1e-12


def energy_drift(e0: float, e1: float) -> float:
    """Relative energy change (e1 - e0)/|e0|, against a floor for scenes near zero energy."""
    return (e1 - e0) / max(abs(e0), ENERGY_FLOOR)


def _energy_report(compiled: Any, result: Any, drift_warn: float) -> str:
    """Energy at start and end, and the drift verdict (animsim.analysis.drift)."""
    from animsim.analysis.drift import drift

    text = f"energy {result.energy_start:.4g} -> {result.energy_end:.4g} J"
    verdict = drift(compiled, result.energy_start, result.energy_end, drift_warn)
    if verdict.relative is None:
        return f"{text}, {verdict.text()}"
    return f"{text}, {verdict.text()}: integration error, the scene being conservative"


def check_scenes(
    paths: Sequence[Path],
    *,
    quiet: bool = False,
    echo: Callable[[str], None] = print,
    echo_err: Callable[[str], None] = print,
    limits: Any = None,
    drift_warn: float | None = None,
) -> bool:
    """``limits`` (a preflight.RunLimits) bounds every scene as ``animsim run`` would;
    ``drift_warn`` (percent) is the energy drift above which a conservative scene gets a warning."""
    from animsim.analysis.drift import DEFAULT_DRIFT_WARN_PERCENT, drift
    from animsim.api import prepare_file as prepare_scene
    from animsim.compile import compile_scene
    from animsim.engine import STATUS_OK, run

    warn = DEFAULT_DRIFT_WARN_PERCENT if drift_warn is None else drift_warn
    all_ok = True
    for path in paths:
        try:
            loaded, scene, _ = prepare_scene(path, limits)
            compiled = compile_scene(scene, loaded.name)
        except AnimsimError as exc:
            echo_err(str(exc))
            echo_err(f"{path}: INVALID")
            all_ok = False
            continue
        notes = []
        from animsim.analysis import stability

        report = stability.analyse(compiled)
        from animsim.analysis.effective import fallback_note

        fallback = fallback_note(compiled)
        if fallback is not None:
            notes.append(f"note: {fallback}")
        if report is not None:
            notes.extend(report.lines())
            if report.dt_exceeds_limit:
                notes.append("warning: dt exceeds the stable limit for this integrator")
        result = run(compiled)
        head = (
            f"{path}: {result.status} ({compiled.integrator_name}, dt {compiled.clock.dt:g}, "
            f"{result.steps_taken} steps, {result.wall_time:.2f} s; {_energy_report(compiled, result, warn)})"
        )
        verdict = drift(compiled, result.energy_start, result.energy_end, warn)
        if verdict.warning and result.status == STATUS_OK:
            echo_err(f"{path}: warning: {verdict.warning_text()}")
        if result.status != STATUS_OK:
            all_ok = False
            echo_err(head)
            if result.failure is not None:
                echo_err("  " + result.failure.describe())
        elif not quiet:
            echo(head)
        if not quiet or result.status != STATUS_OK:
            for line in notes:
                echo(f"  {line}")
    return all_ok
