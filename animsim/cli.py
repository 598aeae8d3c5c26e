"""The ``animsim`` command line (contract: ``cli.md``).

Commands stay thin: parse options, call the library, and turn an
:class:`~animsim.errors.AnimsimError` into an exit status in one place
(:func:`main`). Exit 0 done, 1 the simulation failed or a check found a
problem, 2 the input or the usage is wrong, 130 interrupted.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer

from animsim import __version__
from animsim.errors import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_USAGE, AnimsimError, UsageError

class _App(typer.Typer):
    """A Typer app whose call maps errors to exit statuses (see :func:`main`).

    ``[project.scripts] animsim = "animsim.cli:app"`` calls this object, so the
    mapping must live in ``__call__``, not only in a separate main().
    """

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if kwargs.get("standalone_mode") is False:
            return super().__call__(*args, **kwargs)
        main(kwargs.get("args") if "args" in kwargs else (args[0] if args else None))


app = _App(
    name="animsim",
    help="Physically based animation from a text file: particles, springs, cloth, hair, particle systems.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"animsim {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """animsim: write a scene in YAML, simulate it, compare integrators, render it."""


# --- shared options ---------------------------------------------------------------

SceneArg = Annotated[Path, typer.Argument(help="The scene file (YAML).", show_default=False, metavar="SCENE")]
MaxFileSize = Annotated[int, typer.Option("--max-file-size", help="Largest scene file in bytes.", min=1)]
MaxDepth = Annotated[int, typer.Option("--max-depth", help="Deepest YAML nesting.", min=1)]
MaxNodes = Annotated[int, typer.Option("--max-nodes", help="Most YAML nodes after alias expansion.", min=1)]
MaxSteps = Annotated[int, typer.Option("--max-steps", help="Most steps a run may take.", min=1)]
BackendOpt = Annotated[
    str,
    typer.Option(
        "--backend",
        help="numpy (default), numba (compiled; pip install -e '.[fast]') or auto (numba when installed and able).",
    ),
]

DEFAULT_MAX_STEPS = 100_000_000


class Format(str, Enum):
    csv = "csv"
    npz = "npz"


def _backend(name: str) -> str:
    """Check a --backend value (the library also accepts the internal 'reference')."""
    from animsim.backends import BACKENDS

    if name not in BACKENDS:
        raise UsageError(f"--backend: unknown backend {name!r} (valid: {', '.join(BACKENDS)})")
    return name


def _limits(max_file_size: int, max_depth: int, max_nodes: int):
    from animsim.scene.loader import Limits

    return Limits(max_file_bytes=max_file_size, max_depth=max_depth, max_nodes=max_nodes)


def _err(text: str) -> None:
    typer.echo(text, err=True)


class _StopFlag:
    """Set by SIGINT/SIGTERM; the loop polls it at each step boundary."""

    def __init__(self) -> None:
        self.signal: int | None = None

    def __call__(self) -> bool:
        return self.signal is not None


@contextmanager
def _graceful_stop():
    flag = _StopFlag()

    def handler(signum: int, frame: Any) -> None:
        if flag.signal is not None:  # a second Ctrl-C: stop now
            raise KeyboardInterrupt
        flag.signal = signum

    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, handler)
    try:
        yield flag
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def check_output_path(output: Path, scene_path: Path) -> None:
    """Refuse, before any step, an output that cannot be written."""
    parent = output.parent if str(output.parent) else Path(".")
    if not parent.exists():
        raise UsageError(f"{output}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise UsageError(f"{output}: {parent} is not a folder")
    if output.is_dir():
        raise UsageError(f"{output}: is a folder; give a file name")
    try:
        if output.exists() and output.resolve() == scene_path.resolve():
            raise UsageError(f"{output}: is the scene file itself; choose another output")
    except OSError:
        pass
    if output.resolve() == scene_path.resolve():
        raise UsageError(f"{output}: is the scene file itself; choose another output")
    if not os.access(parent, os.W_OK):
        raise UsageError(f"{output}: the folder {parent} is not writable")


# --- run ----------------------------------------------------------------------------


@app.command()
def run(
    scene: SceneArg,
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="Trajectory file; default <scene stem>.csv here; '-' for stdout."),
    ] = None,
    integrator: Annotated[str | None, typer.Option(help="Override the scene's integrator.")] = None,
    dt: Annotated[float | None, typer.Option(help="Override the step size (s).")] = None,
    duration: Annotated[float | None, typer.Option(help="Override the duration (s).")] = None,
    seed: Annotated[int | None, typer.Option(help="Override the random seed.")] = None,
    format: Annotated[Format | None, typer.Option("--format", help="Trajectory format; default from the suffix, else csv.")] = None,
    extra_columns: Annotated[bool, typer.Option("--extra-columns", help="Add age, size, r, g, b, a columns (particle systems).")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    max_file_size: MaxFileSize = 50 * 1024 * 1024,
    max_depth: MaxDepth = 100,
    max_nodes: MaxNodes = 100_000,
    max_steps: MaxSteps = DEFAULT_MAX_STEPS,
    backend: BackendOpt = "numpy",
) -> None:
    """Simulate SCENE and write its trajectory (CSV or NPZ) and a .meta.json beside it."""
    from animsim.compile import compile_scene, with_overrides
    from animsim.scene.loader import load_scene
    from animsim.simulate import STATUS_INTERRUPTED, STATUS_UNSTABLE, run as simulate

    loaded = load_scene(scene, _limits(max_file_size, max_depth, max_nodes))
    sc = with_overrides(loaded.scene, integrator=integrator, dt=dt, duration=duration, seed=seed)
    to_stdout = output is not None and str(output) == "-"
    out = output if output is not None else Path(f"{scene.stem}.csv")
    fmt = format or (Format.npz if out.suffix.lower() == ".npz" else Format.csv)
    if to_stdout and fmt is Format.npz:
        raise UsageError("--format npz cannot go to stdout; give a file with -o")
    if not to_stdout:
        check_output_path(out, scene)
    compiled = compile_scene(sc, loaded.name, backend=_backend(backend))
    if compiled.clock.steps > max_steps:
        raise UsageError(
            f"{scene}: {compiled.clock.steps} steps is more than the limit of {max_steps} (raise it with --max-steps)"
        )
    if fmt is Format.npz:
        from animsim.export.npz import NpzSink

        sink: Any = NpzSink(out)
    else:
        from animsim.export.csv import CsvSink

        sink = CsvSink("-" if to_stdout else out, extra_columns=extra_columns)
    extra = {"scene_sha256": loaded.sha256, "scene_file": str(scene)}
    with _graceful_stop() as stop, _progress(compiled.clock.steps, quiet) as progress:
        result = simulate(compiled, [sink], stop=stop, progress=progress, meta_extra=extra)
    if not quiet:
        _summary(compiled, result, None if to_stdout else out)
    if result.status == STATUS_UNSTABLE:
        assert result.failure is not None
        _err(f"{scene}: {result.failure.describe()}")
        _err(f"the frames before the failure are in {out}")
        raise typer.Exit(EXIT_FAILED)
    if result.status == STATUS_INTERRUPTED:
        _err(f"{scene}: interrupted at step {result.steps_taken} (t = {result.final_state.time:.6g} s); frames so far in {out}")
        raise typer.Exit(EXIT_INTERRUPTED)


@contextmanager
def _progress(total: int, quiet: bool):
    """A rich progress bar on stderr, only on a terminal and only for long runs."""
    if quiet or total < 20_000 or not sys.stderr.isatty():
        yield None
        return
    from rich.progress import Progress

    with Progress(transient=True, console=_stderr_console()) as bar:
        task = bar.add_task("simulating", total=total)
        stride = max(1, total // 200)

        def update(step: int, _total: int) -> None:
            if step % stride == 0 or step == _total:
                bar.update(task, completed=step)

        yield update


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


def _summary(compiled: Any, result: Any, out: Path | None) -> None:
    stream_err = out is None  # trajectory went to stdout: keep stdout clean
    lines = [
        f"{compiled.name}: {compiled.system.particle_count} particles, {compiled.system.spring_count} springs, "
        f"{result.steps_taken}/{compiled.clock.steps} steps of {compiled.clock.dt:g} s with {compiled.integrator_name}",
        f"  wall time {result.wall_time:.3f} s, {result.frames} frames, {result.force_evals} force evaluations",
        f"  energy {result.energy_start:.6g} J -> {result.energy_end:.6g} J, status {result.status}",
    ]
    if out is not None:
        lines.append(f"  wrote {out} and {out}.meta.json")
    typer.echo("\n".join(lines), err=stream_err)


# --- explain ------------------------------------------------------------------------


@app.command()
def explain(
    scene: SceneArg,
    integrator: Annotated[str | None, typer.Option(help="Explain with this integrator instead.")] = None,
    backend: BackendOpt = "numpy",
) -> None:
    """Show what SCENE compiles to: counts, the stages run each step, and what was left out."""
    from animsim.compile import compile_scene, with_overrides
    from animsim.scene.loader import load_scene

    loaded = load_scene(scene)
    sc = with_overrides(loaded.scene, integrator=integrator)
    c = compile_scene(sc, loaded.name, backend=_backend(backend))
    s = c.system
    typer.echo(f"scene {c.name!r} ({scene})")
    typer.echo(
        f"  {s.particle_count} particles ({int(s.particle_pinned.sum())} pinned), {s.spring_count} springs, "
        f"{len(sc.planes)} planes, {len(sc.emitters)} emitters"
    )
    typer.echo(f"  {c.clock.steps} steps of {c.clock.dt:g} s to t = {c.clock.duration:g} s, seed {c.seed}")
    typer.echo("each step runs:")
    for stage in c.stages:
        typer.echo(f"  + {stage}")
    typer.echo("left out (the scene does not need them):")
    for item in c.left_out:
        typer.echo(f"  - {item}")


# --- schema ---------------------------------------------------------------------------


def schema_text() -> str:
    from animsim.scene.models import Scene

    schema = Scene.model_json_schema()
    schema = {"$schema": schema.pop("$schema"), **schema}
    return json.dumps(schema, indent=2) + "\n"


@app.command()
def schema() -> None:
    """Print the scene JSON Schema (schemas/scene.schema.json is this output)."""
    sys.stdout.write(schema_text())


# --- check ------------------------------------------------------------------------------


@app.command()
def check(
    scenes: Annotated[list[Path], typer.Argument(help="Scene files.", show_default=False)],
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Only problems.")] = False,
) -> None:
    """Validate, analyse and run each scene; exit 0 only if every one is valid and stable."""
    from animsim.analysis.check import check_scenes

    ok = check_scenes(scenes, quiet=quiet, echo=typer.echo, echo_err=_err)
    if not ok:
        raise typer.Exit(EXIT_FAILED)


# --- entry point ----------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> None:
    """Run the app; every AnimsimError becomes a message and an exit status, never a traceback."""
    try:
        typer.Typer.__call__(app, args=argv, prog_name="animsim", standalone_mode=False)
    except AnimsimError as exc:
        _err(str(exc))
        sys.exit(exc.exit_code)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except (typer.Abort, KeyboardInterrupt):
        _err("animsim: interrupted")
        sys.exit(EXIT_INTERRUPTED)
    except Exception as exc:  # click usage errors and anything unexpected
        # Typer vendors its own copy of click, so match click's exceptions by
        # their base class name rather than importing click.
        if any(c.__name__ == "ClickException" for c in type(exc).__mro__):
            exc.show()  # type: ignore[attr-defined]
            sys.exit(exc.exit_code or EXIT_USAGE)  # type: ignore[attr-defined]
        if os.environ.get("ANIMSIM_DEBUG"):
            raise
        _err(f"animsim: internal error: {type(exc).__name__}: {exc}")
        _err("this is a bug in animsim; run again with ANIMSIM_DEBUG=1 for the traceback")
        sys.exit(EXIT_FAILED)
    sys.exit(0)
