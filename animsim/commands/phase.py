"""``animsim plot --kind phase`` and the split energy of ``--kind energy``: runs in, figures out."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from animsim.analysis.compare import parse_integrators
from animsim.compile import compile_scene
from animsim.errors import UsageError
from animsim.export.pictures import PhaseRun, phase_particles, plot_phase
from animsim.export.trajectory import read_trajectory
from animsim.export.viewer import dense_frames, panel_label, pinned_for
from animsim.measures.energy_parts import energies_from_trajectory
from animsim.panel_runs import compile_each, simulate_panel


def energy_parts_of(compiled: Any, traj: Any = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(times, parts) of a run of ``compiled`` (simulated), or of a trajectory of its scene."""
    if traj is not None:
        return np.asarray(traj.times, dtype=np.float64), energies_from_trajectory(compiled, traj)
    run = simulate_panel(compiled)
    return np.asarray(run.trajectory.times, dtype=np.float64), run.energies


def phase_command(
    source: Path,
    output: Path,
    *,
    from_file: bool,
    scene: Path | None,
    prepare: Callable[..., tuple[Any, Any, Any]],
    integrators: str | None,
    particles: str | None,
    integrator: str | None,
    dt: float | None,
    duration: float | None,
    backend: str = "auto",
) -> None:
    """Simulate once per integrator on ``backend`` (or read a trajectory) and draw the phase portraits."""
    requested = [p.strip() for p in particles.split(",") if p.strip()] if particles is not None else None
    if particles is not None and not requested:
        raise UsageError("--particles: give at least one particle id")
    runs: list[PhaseRun] = []
    pinned: np.ndarray
    if from_file:
        if integrators is not None:
            raise UsageError(
                "--integrators simulates the scene once per method: give the scene, not a trajectory"
            )
        traj = read_trajectory(source)
        dense = dense_frames(traj)
        runs.append(PhaseRun(source.name, list(traj.ids), dense["position"], dense["velocity"]))
        pinned = np.zeros(len(traj.ids), dtype=bool)
        if scene is not None:
            loaded, sc, _ = prepare(scene)
            pinned = pinned_for(compile_scene(sc, loaded.name), traj.ids)
        title = f"{source.name}: phase portrait"
    else:
        names = None
        if integrators is not None:
            if integrator is not None:
                raise UsageError("give --integrator or --integrators, not both")
            names = parse_integrators(integrators)
        loaded, sc, _ = prepare(source, integrator=integrator, dt=dt, duration=duration)
        compiled = compile_each(sc, loaded.name, names, backend)
        for c in compiled:
            run = simulate_panel(c)
            dense = dense_frames(run.trajectory)
            failure = run.result.failure
            runs.append(
                PhaseRun(
                    panel_label(c),
                    list(run.trajectory.ids),
                    dense["position"],
                    dense["velocity"],
                    status=run.result.status,
                    failure_time=None if failure is None else failure.time,
                )
            )
        pinned = run.panel.pinned if run.panel.pinned is not None else np.zeros(len(runs[0].ids), dtype=bool)
        title = f"{compiled[0].name}: phase portrait"
    rows = phase_particles(runs[0], pinned, requested)
    plot_phase(runs, output, rows=rows, title=title)
