"""Runs made to be looked at: a compiled scene simulated once with every recorded frame and
its energy parts kept (the viewer's panels, side-by-side pictures, phase plots), one per
integrator when several are compared.

It stands above the loop and below the commands that show the runs
(:mod:`animsim.commands.viewer_command`, :mod:`animsim.commands.side_by_side`,
:mod:`animsim.commands.phase`), so the page and picture makers in :mod:`animsim.export`
never import the engine.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.compile import compile_scene, with_overrides
from animsim.engine import run
from animsim.export.trajectory import TrajectoryCollector
from animsim.export.viewer import ViewerPanel, panel_from_trajectory, panel_label
from animsim.measures.energy_parts import EnergyRecorder


def compile_each(
    scene: Any, name: str, integrators: Sequence[str] | None, backend: str = "auto"
) -> list[Any]:
    """One compiled scene per integrator (or the scene as it is when there are none), for ``backend``."""
    if not integrators:
        return [compile_scene(scene, name, backend=backend)]
    return [compile_scene(with_overrides(scene, integrator=i), name, backend=backend) for i in integrators]


@dataclass
class PanelRun:
    """What :func:`simulate_panel` returns: the panel and the run's outcome."""

    panel: ViewerPanel
    trajectory: Any
    energies: dict[str, np.ndarray]
    result: Any


def simulate_panel(compiled: Any, label: str | None = None, stop: Any = None) -> PanelRun:
    """Simulate ``compiled`` once, keeping every recorded frame and its energy parts.

    The one place where the viewer's panels, side-by-side pictures and phase plots run
    the simulator (so a switch to the public Python API is one edit here).
    """
    collector = TrajectoryCollector()
    energy = EnergyRecorder(compiled.dynamics)
    result = run(compiled, [collector], observers=[energy], stop=stop)
    traj = collector.trajectory()
    series = energy.series()
    series.pop("time")
    if len(next(iter(series.values()), ())) != traj.frame_count:
        series = {}  # a backend that does not call observers: no energy rather than a wrong one
    failure_time = result.failure.time if result.failure is not None else None
    panel = panel_from_trajectory(
        traj,
        compiled,
        energies=series or None,
        label=panel_label(compiled) if label is None else label,
        status=result.status,
        failure_time=failure_time,
    )
    return PanelRun(panel=panel, trajectory=traj, energies=series, result=result)
