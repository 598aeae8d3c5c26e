"""``animsim view``: simulate (once per integrator) or read a trajectory, write the HTML viewer."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from animsim.analysis.compare import integrator_names, parse_integrators
from animsim.atomic import AtomicFile
from animsim.commands.inputs import check_output, prepare_file, refuse_bodies_in_file
from animsim.compile import compile_scene
from animsim.errors import UsageError
from animsim.export.raster import up_axis
from animsim.export.trajectory import is_trajectory, read_trajectory
from animsim.export.viewer import VIEWS, panel_from_trajectory, panels_html
from animsim.measures.energy_parts import energies_from_trajectory
from animsim.panel_runs import compile_each, simulate_panel
from animsim.scene import models as m

#: pages above this size get a note on stderr (they still work; they open slowly)
LARGE_PAGE_BYTES = 50_000_000


@dataclass
class ViewSummary:
    text: str = ""
    notes: list[str] = field(default_factory=list)
    interrupted: bool = False
    panels: int = 0
    bytes: int = 0


def _megabytes(n: int) -> str:
    return f"{n / 1e6:.2f} MB"


def write_view(
    source: Path,
    output: Path,
    *,
    prepare: Callable[..., tuple[Any, Any, Any]],
    integrators: str | None,
    fps: float,
    view: str,
    scene: Path | None,
    integrator: str | None,
    dt: float | None,
    duration: float | None,
    stop_context: Callable[[], Any] = contextlib.nullcontext,
    backend: str = "auto",
) -> ViewSummary:
    """Build the panels and write ``output`` (atomically). ``prepare`` is the CLI's scene loader;
    a scene is simulated on ``backend``."""
    summary = ViewSummary()
    from_file = is_trajectory(source)
    panels = []
    names: Sequence[str] | None = None
    if integrators is not None:
        if from_file:
            raise UsageError(
                "--integrators simulates the scene once per method: give the scene, not a trajectory"
            )
        if integrator is not None:
            raise UsageError("give --integrator or --integrators, not both")
        names = parse_integrators(integrators)
    if from_file:
        compiled = None
        if scene is not None:
            loaded, sc, _ = prepare(scene, integrator=integrator, dt=dt, duration=duration)
            compiled = compile_scene(sc, loaded.name)
        traj = read_trajectory(source)
        energies = None
        if compiled is not None and compiled.emitters is not None:
            # Who was alive with what mass is not in the file: no energy rather than a wrong one.
            summary.notes.append(
                "no energy plot: a particle system's energy needs the scene itself, not a trajectory"
            )
        elif compiled is not None:
            energies = energies_from_trajectory(compiled, traj)
        panels.append(panel_from_trajectory(traj, compiled, energies=energies, label=source.name))
        title = source.name if compiled is None else f"{compiled.name} ({source.name})"
        up = "y" if compiled is None else up_axis(compiled.scene)
        total = None
    else:
        loaded, sc, _ = prepare(source, integrator=integrator, dt=dt, duration=duration)
        sc = sc.model_copy(update={"record": m.Record(fps=fps)})
        compiled_runs = compile_each(sc, loaded.name, names, backend)
        with stop_context() as stop:
            for c in compiled_runs:
                run = simulate_panel(c, stop=stop)
                if run.result.status == "interrupted":
                    summary.interrupted = True
                    return summary
                if run.result.status == "unstable" and run.result.failure is not None:
                    summary.notes.append(f"{c.integrator_name}: {run.result.failure.describe()}")
                panels.append(run.panel)
        title = compiled_runs[0].name
        up = up_axis(compiled_runs[0].scene)
        total = compiled_runs[0].clock.duration
    page = panels_html(panels, title=title, up=up, view=view, duration=total)
    out = AtomicFile(output, "w", newline="\n")
    try:
        out.handle.write(page)
    except BaseException:
        out.abort()
        raise
    out.commit()
    size = len(page.encode("utf-8"))
    frames = max(len(p.times) for p in panels)
    particles = max(p.positions.shape[1] for p in panels)
    summary.panels = len(panels)
    summary.bytes = size
    what = f"{len(panels)} panels" if len(panels) > 1 else "1 panel"
    summary.text = f"wrote {output} ({_megabytes(size)}): {what}, {frames} frames, {particles} particles"
    if size > LARGE_PAGE_BYTES:
        summary.notes.append(
            f"{output} is {_megabytes(size)}: browsers take a while to open such a page; "
            "a lower --fps or a shorter --duration makes it smaller"
        )
    return summary


def view_command(
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
    """The work of :func:`animsim.api.view`."""
    import contextlib

    if view not in VIEWS:
        raise UsageError(f"--view {view!r}: choose one of {', '.join(VIEWS)}")
    if not (fps > 0 and fps < float("inf")):
        raise UsageError(f"--fps {fps}: must be a number > 0")
    out = Path(output)
    if out.suffix.lower() not in (".html", ".htm"):
        raise UsageError(f"-o {out}: the file name must end in .html")
    check_output(out, source)

    if scene is None and is_trajectory(Path(source)):
        refuse_bodies_in_file(
            read_trajectory(Path(source)), Path(source), "the viewer", "use animsim render SCENE --view 3d"
        )
    return write_view(
        Path(source),
        out,
        prepare=lambda path, **kw: prepare_file(path, limits, consumer="view", **kw),
        integrators=None if integrators is None else ",".join(integrator_names(integrators)),
        fps=fps,
        view=view,
        scene=None if scene is None else Path(scene),
        integrator=integrator,
        dt=dt,
        duration=duration,
        stop_context=lambda: contextlib.nullcontext(stop),
        backend=backend,
    )
