"""``animsim plot`` as one call: particle paths, the energy split into its parts, or phase
portraits, of a scene (simulated first) or a trajectory file.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from animsim.analysis.compare import integrator_names
from animsim.commands.arguments import PLOT_KINDS
from animsim.commands.inputs import check_output, prepare_file
from animsim.commands.phase import energy_parts_of, phase_command
from animsim.commands.simulation import simulate
from animsim.compile import compile_scene
from animsim.errors import UsageError
from animsim.export.pictures import AXES, VIEW_NAMES, figure_format, plot_energy_parts, plot_trajectory
from animsim.export.trajectory import is_trajectory, read_trajectory
from animsim.render import view_up


def plot_command(
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
    """The work of :func:`animsim.api.plot`."""
    out, src = Path(output), Path(source)
    if kind not in PLOT_KINDS:
        raise UsageError(f"--kind {kind!r}: choose one of {', '.join(PLOT_KINDS)}")
    figure_format(out)
    if view is not None and view not in AXES:
        raise UsageError(f"--view {view!r}: plot takes {VIEW_NAMES}")
    check_output(out, src)
    from_file = is_trajectory(src)
    if kind != "phase" and (integrators is not None or particles is not None):
        raise UsageError("--integrators and --particles go with --kind phase")
    prepare_path = lambda path, **kw: prepare_file(path, limits, consumer="plot", **kw)  # noqa: E731
    if kind == "phase":
        phase_command(
            src,
            out,
            from_file=from_file,
            scene=None if scene is None else Path(scene),
            prepare=prepare_path,
            integrators=None if integrators is None else ",".join(integrator_names(integrators)),
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
        loaded, sc, _ = prepare_path(scene_path, integrator=integrator, dt=dt, duration=duration)
        # simulated for the energy of a scene; a trajectory's scene is only read
        compiled = compile_scene(sc, loaded.name, backend="numpy" if from_file else backend)
    if kind == "energy":
        if compiled is None:
            raise UsageError("--kind energy needs the scene: give a scene, or --scene with the trajectory")

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

    plot_trajectory(
        traj, out, view=view, title=name, up=None if compiled is None else view_up(compiled.scene)
    )
    return out
