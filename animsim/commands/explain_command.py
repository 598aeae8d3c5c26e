"""``animsim explain`` as one call: what a scene compiles to, as the lines it prints."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from animsim.commands.inputs import prepared, source_label
from animsim.commands.simulation import compile
from animsim.console import count_text, point_particles
from animsim.measures.effective import fallback_note
from animsim.scene.models import Scene


def explain_command(
    source: str | Path | Scene,
    *,
    integrator: str | None = None,
    backend: str = "auto",
    limits: Any = None,
) -> list[str]:
    """The work of :func:`animsim.api.explain`."""
    sc, name, _, _ = prepared(source, limits, integrator=integrator, consumer="explain")
    c = compile(sc, backend, name=name)
    s = c.system
    points, pinned = point_particles(s)
    lines = [
        f"scene {c.name!r} ({source_label(source)})",
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
