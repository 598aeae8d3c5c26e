"""The ``animsim`` command line (contract: ``cli.md``).

Commands stay thin: parse options, call the library, and turn an
:class:`~animsim.errors.AnimsimError` into an exit status in one place
(:func:`main`). Exit 0 done, 1 the simulation failed or a check found a
problem, 2 the input or the usage is wrong, 130 interrupted.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

# One BLAS thread unless the user says otherwise, set before NumPy loads: the
# loop's only BLAS calls are dot products for the energy watchdog, too small to
# gain from threads, and on a busy machine OpenBLAS's spinning threads made
# each one cost 20 ms instead of 0.1 ms (a 100,000-particle fountain, which is
# checked every step, ran at 18 steps/s instead of 65).
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import typer  # noqa: E402

from animsim.errors import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_USAGE, AnimsimError, UsageError  # noqa: E402
from animsim.version import __version__  # noqa: E402


class _App(typer.Typer):
    """A Typer app whose call maps errors to exit statuses (see :func:`main`).

    ``[project.scripts] animsim = "animsim.cli:app"`` calls this object, so the
    mapping must live in ``__call__``, not only in a separate main().
    """

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if kwargs.get("standalone_mode") is False:
            return super().__call__(*args, **kwargs)
        main(kwargs.get("args") if "args" in kwargs else (args[0] if args else None))


# How help shows a value's type: words a user knows, not Python's names.
_TYPE_WORDS = {"str": "text", "float": "number", "int": "integer", "Path": "path", "path": "path"}


def _help_type(label: str | None) -> str | None:
    """``<bool>`` -> nothing (a flag takes no value), ``<list[Path]>`` -> ``<path>...``, ``<str>`` -> ``<text>``."""
    if not label or not label.startswith("<") or not label.endswith(">"):
        return label
    inner = label[1:-1]
    many = inner.startswith("list[") and inner.endswith("]")
    if many:
        inner = inner[5:-1]
    if inner == "bool":
        return None
    word = _TYPE_WORDS.get(inner.removesuffix(" range"), inner.removesuffix(" range"))
    return f"<{word}>" + ("..." if many else "")


def _plain_help_types() -> None:
    """Make typer's help show :func:`_help_type` words (it prints ``<bool>`` for flags and ``--help``).

    Typer has no option for this, so its one display method is wrapped; the
    values parsed are unchanged.
    """
    from typer.core import TyperArgument, TyperOption

    for cls in (TyperArgument, TyperOption):
        original = cls.display_type_rich
        if getattr(original, "_animsim", False):
            continue

        def display(self: Any, ctx: Any, _original: Any = original) -> str | None:
            if getattr(self, "is_flag", False):
                return None
            return _help_type(_original(self, ctx))

        display._animsim = True  # type: ignore[attr-defined]
        cls.display_type_rich = display  # type: ignore[method-assign]


_plain_help_types()

app = _App(
    name="animsim",
    help="Physically based animation from a text file: particles, springs, cloth, hair, particle systems.\n\n"
    "Tab completion of commands and options: animsim --install-completion (bash, zsh, fish, PowerShell), "
    "then open a new shell.",
    add_completion=True,
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
    ctx: typer.Context,
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """animsim: write a scene in YAML, simulate it, compare integrators, render it."""
    if ctx.invoked_subcommand != "run":
        # only run's start-up keeps Python's collector paused (until its first step, see
        # animsim.startup); the other commands' work (rendering, many runs) collects as usual
        from animsim.startup import resume_collector

        resume_collector()


# --- shared options ---------------------------------------------------------------


# Tab completion of option values. The names come from where the code keeps them;
# each import happens only when the shell asks for a completion.
def _matching(names: Any, incomplete: str) -> list[str]:
    return [n for n in names if n.startswith(incomplete)]


def _complete_integrator(incomplete: str) -> list[str]:
    from animsim.methods import names

    INTEGRATOR_NAMES = names()

    return _matching(INTEGRATOR_NAMES, incomplete)


def _complete_integrators(incomplete: str) -> list[str]:
    """A comma-separated list: complete its last name, offer none twice."""
    from animsim.methods import names

    INTEGRATOR_NAMES = names()

    head, _, last = incomplete.rpartition(",")
    given = set(head.split(",")) if head else set()
    prefix = f"{head}," if head else ""
    return [prefix + n for n in INTEGRATOR_NAMES if n.startswith(last) and n not in given]


def _complete_backend(incomplete: str) -> list[str]:
    from animsim.backends import BACKENDS

    return _matching(BACKENDS, incomplete)


def _complete_template(incomplete: str) -> list[str]:
    from animsim.templates import TEMPLATES

    return _matching(TEMPLATES, incomplete)


def _complete_render_view(incomplete: str) -> list[str]:
    from animsim.export.raster import VIEWS

    return _matching(VIEWS, incomplete)


def _complete_viewer_view(incomplete: str) -> list[str]:
    from animsim.export.viewer import VIEWS

    return _matching(VIEWS, incomplete)


def _complete_plot_view(incomplete: str) -> list[str]:
    from animsim.export.raster import ORTHO_VIEWS

    return _matching(ORTHO_VIEWS, incomplete)


SceneArg = Annotated[Path, typer.Argument(help="The scene file (YAML).", show_default=False, metavar="SCENE")]
BackendOpt = Annotated[
    str,
    typer.Option(
        "--backend",
        help="auto (the default of every command: numba when installed, else numpy), numpy, or numba "
        '(compiled; needs pip install -e ".\\[fast]").',
        autocompletion=_complete_backend,
    ),
]

DriftWarnOpt = Annotated[
    float,
    typer.Option(
        "--drift-warn",
        metavar="PERCENT",
        help="Warn when a conservative scene's energy drifts by more than PERCENT of its start.",
    ),
]

_LIMITS_PANEL = "Limits (what a scene may ask for)"

# The limit options, shared by every command that loads a scene (see
# limit_options). Sizes take suffixes (50MiB, 4GiB); counts take 1e9.
_LIMIT_PARAMS: dict[str, tuple[Any, Any]] = {
    "max_file_size": (
        Annotated[
            str,
            typer.Option(
                "--max-file-size", help="Largest scene file, e.g. 50MiB.", rich_help_panel=_LIMITS_PANEL
            ),
        ],
        "50MiB",
    ),
    "max_depth": (
        Annotated[
            int,
            typer.Option("--max-depth", help="Deepest YAML nesting.", min=1, rich_help_panel=_LIMITS_PANEL),
        ],
        100,
    ),
    "max_nodes": (
        Annotated[
            int,
            typer.Option(
                "--max-nodes", help="Most YAML nodes aliases may add.", min=1, rich_help_panel=_LIMITS_PANEL
            ),
        ],
        100_000,
    ),
    "max_steps": (
        Annotated[
            str,
            typer.Option(
                "--max-steps", help="Most steps a run may take (1e8).", rich_help_panel=_LIMITS_PANEL
            ),
        ],
        "100000000",
    ),
    "max_memory": (
        Annotated[
            str,
            typer.Option(
                "--max-memory",
                help="Memory budget for the live state, e.g. 4GiB.",
                rich_help_panel=_LIMITS_PANEL,
            ),
        ],
        "4GiB",
    ),
    "disk_check": (
        Annotated[
            bool,
            typer.Option(
                "--disk-check/--no-disk-check",
                help="Refuse a run whose estimated output exceeds the free disk space.",
                rich_help_panel=_LIMITS_PANEL,
            ),
        ],
        True,
    ),
    "mesh_dir": (
        Annotated[
            list[str] | None,
            typer.Option(
                "--mesh-dir",
                help="Also read mesh files under this folder (repeatable); by default only the scene's own.",
                rich_help_panel=_LIMITS_PANEL,
            ),
        ],
        None,
    ),
}


def limit_options(func: Any) -> Any:
    """Give a command the limit options; it receives them as ``limits: RunLimits``.

    One decorator instead of six parameters copied into every command, so
    run, check, explain and any later command (compare, render, ...) take the
    same options with the same defaults and the same parsing.
    """
    import functools
    import inspect

    sig = inspect.signature(func, eval_str=True)
    if "limits" not in sig.parameters:
        raise TypeError(f"{func.__name__} must take a 'limits' parameter")
    params = [p for p in sig.parameters.values() if p.name != "limits"]
    params += [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=annotation)
        for name, (annotation, default) in _LIMIT_PARAMS.items()
    ]

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {name: kwargs.pop(name, default) for name, (_, default) in _LIMIT_PARAMS.items()}
        kwargs["limits"] = make_limits(**values)
        return func(*args, **kwargs)

    wrapper.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    return wrapper


def make_limits(
    max_file_size: str | int = "50MiB",
    max_depth: int = 100,
    max_nodes: int = 100_000,
    max_steps: str | int = "100000000",
    max_memory: str | int = "4GiB",
    disk_check: bool = True,
    mesh_dir: list[str] | None = None,
):
    """RunLimits from the options' values (sizes and counts parsed here, once)."""
    from animsim.preflight import RunLimits, parse_count, parse_size

    return RunLimits(
        max_file_bytes=parse_size(str(max_file_size), "--max-file-size"),
        max_depth=max_depth,
        max_nodes=max_nodes,
        max_steps=parse_count(str(max_steps), "--max-steps"),
        max_memory=parse_size(str(max_memory), "--max-memory"),
        disk_check=disk_check,
        mesh_dirs=tuple(mesh_dir or ()),
    )


def _format_names(incomplete: str) -> list[str]:
    """Shell completion of ``--format``: the registered trajectory formats."""
    from animsim.export.sinks import formats

    return [name for name in formats() if name.startswith(incomplete)]


def _backend(name: str) -> str:
    """Check a --backend value (the library also accepts the internal 'reference')."""
    from animsim.backends import BACKENDS

    if name not in BACKENDS:
        raise UsageError(f"--backend: unknown backend {name!r} (valid: {', '.join(BACKENDS)})")
    return name


def _err(text: str) -> None:
    typer.echo(text, err=True)


class _StopFlag:
    """Set by SIGINT/SIGTERM; the loop polls it at each step boundary.

    The loop's first poll marks it as stepping. Before that (loading,
    compiling, which can take a minute with numba) nothing would read the
    flag, so a signal then stops at once instead (see _graceful_stop). So
    does a signal once the loop has said it is writing its files (``writing``):
    no step is left to finish, and the files are not made whole.
    """

    def __init__(self) -> None:
        self.signal: int | None = None
        self.stepping = False

    def __call__(self) -> bool:
        self.stepping = True
        return self.signal is not None

    def writing(self) -> None:
        self.stepping = False


@contextmanager
def _graceful_stop():
    flag = _StopFlag()

    def handler(signum: int, frame: Any) -> None:
        # Before the step loop, or a second Ctrl-C: unwind now (temporary files are removed,
        # nothing is written, exit 130). In the loop: finish the step and write the frames so far.
        if flag.signal is not None or not flag.stepping:
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


# --- run ----------------------------------------------------------------------------


@app.command()
@limit_options
def run(
    scene: SceneArg,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o", "--output", help="Trajectory file; default <scene stem>.csv here; '-' for stdout."
        ),
    ] = None,
    integrator: Annotated[
        str | None, typer.Option(help="Override the scene's integrator.", autocompletion=_complete_integrator)
    ] = None,
    dt: Annotated[float | None, typer.Option(help="Override the step size (s).")] = None,
    duration: Annotated[float | None, typer.Option(help="Override the duration (s).")] = None,
    seed: Annotated[int | None, typer.Option(help="Override the random seed.")] = None,
    format: Annotated[
        str | None,
        typer.Option(
            "--format",
            help="Trajectory format (csv, npz, ply, usda, usdc, vtp, ...); default from the suffix "
            "(.npz, .ply, .usda, .usdc, .pvd; a folder means ply), else csv.",
            autocompletion=_format_names,
        ),
    ] = None,
    extra_columns: Annotated[
        bool, typer.Option("--extra-columns", help="Add age, size, r, g, b, a columns (particle systems).")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    backend: BackendOpt = "auto",
    drift_warn: DriftWarnOpt = 10.0,
    *,
    limits: Any = None,
) -> None:
    """Simulate SCENE and write its trajectory and a .meta.json beside it.

    Formats: CSV; NPZ; PLY (one binary file per frame, for Blender, Houdini,
    ParaView: -o out/frames.ply gives out/frames_0000.ply, ...; an existing
    folder gives <folder>/frames_0000.ply, ...); USD ASCII (-o anim.usda) or
    binary (-o anim.usdc); VTK for ParaView (-o run.pvd gives run_0000.vtp, ...).
    The output folder must exist.
    """
    from animsim import api

    with _graceful_stop() as stop, _progress(quiet) as progress:
        outcome = api.run(
            scene,
            output,
            fmt=format,
            integrator=integrator,
            dt=dt,
            duration=duration,
            seed=seed,
            backend=_backend(backend),
            extra_columns=extra_columns,
            drift_warn=drift_warn,
            limits=limits,
            stop=stop,
            progress=progress,
            notice=_notice(quiet),
            warn=lambda text: _err(f"{scene}: {text}"),
        )
    compiled, result, out = outcome.compiled, outcome.result, outcome.output
    if not quiet:
        _summary(compiled, result, outcome.wrote)
    _drift_warning(scene, compiled, result)
    if result.status == "unstable":
        assert result.failure is not None
        _err(f"{scene}: {result.failure.describe()}")
        _err(f"the frames before the failure are in {out}")
        raise typer.Exit(EXIT_FAILED)
    if result.status == "interrupted":
        _err(
            f"{scene}: interrupted at step {result.steps_taken} (t = {result.final_state.time:.6g} s); frames so far in {out}"
        )
        raise typer.Exit(EXIT_INTERRUPTED)


#: a run's progress bar opens once it has gone on this long (s): a run that ends sooner
#: needs none, and a longer one should not look hung
PROGRESS_AFTER_SECONDS = 2.0


@contextmanager
def _progress(
    quiet: bool,
    label: str = "simulating",
    at_least: int | None = None,
    after: float = PROGRESS_AFTER_SECONDS,
    clock: Any = None,
):
    """A rich progress bar on stderr, only on a terminal and only for long work: the
    callback gets (done, total) and opens the bar once ``after`` seconds have passed since
    its first call (or at once when ``total`` is at least ``at_least``)."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    import time

    from rich.progress import Progress

    now = clock or time.monotonic
    bar: Any = None
    task: Any = None
    first: float | None = None

    def update(done: int, total: int) -> None:
        nonlocal bar, task, first
        if bar is None:
            t = now()
            first = t if first is None else first
            long_run = at_least is not None and total >= at_least
            if done >= total or not (long_run or t - first >= after):
                return
            bar = Progress(transient=True, console=_stderr_console())
            bar.start()
            task = bar.add_task(label, total=total, completed=done)
        if done % max(1, total // 200) == 0 or done == total:
            bar.update(task, completed=done)

    try:
        yield update
    finally:
        if bar is not None:
            bar.stop()


def _notice(quiet: bool):
    """Where the engine's one-line notices (numba compiling on a first run) go: stderr, on a
    terminal, unless --quiet."""
    from animsim.console import terminal_notice

    return None if quiet else terminal_notice()


@contextmanager
def _compiling(quiet: bool, backend: str):
    """While a command runs, tell the person at the terminal when numba compiles a kernel
    family and about how long it takes (the notice of ``run``, for every other command)."""
    from animsim.backends import choose_backend
    from animsim.compile_notice import compile_notices

    numba = choose_backend(backend)[0] == "numba"
    with compile_notices(_notice(quiet) if numba else None, numba=numba):
        yield


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


def _summary(compiled: Any, result: Any, wrote: str | None) -> None:
    """Print the run summary; ``wrote`` names the files written (None: the trajectory went to stdout)."""
    from animsim.bodies.build import counts_text
    from animsim.console import steps_text

    stream_err = wrote is None  # trajectory went to stdout: keep stdout clean
    lines = [
        f"{compiled.name}: {counts_text(compiled)}, {steps_text(compiled, result)} with {compiled.integrator_name}",
        f"  wall time {result.wall_time:.3f} s, {result.frames} frames, {result.force_evals} force evaluations",
        f"  energy {result.energy_start:.6g} J -> {result.energy_end:.6g} J, status {result.status}, "
        + _drift_of(compiled, result).text(),
    ]
    lines.extend(_summary_notes(compiled, result))
    if "springs_broken" in result.meta:
        first = result.meta.get("first_break_time")
        lines.append(
            f"  springs broken: {result.meta['springs_broken']}"
            + (f" (first at t = {first:.6g} s)" if first is not None else "")
        )
    if wrote is not None:
        lines.append(f"  wrote {wrote}")
    from animsim.analysis.check import wrap

    typer.echo("\n".join(wrap(line) for line in lines), err=stream_err)


def _drift_of(compiled: Any, result: Any) -> Any:
    """The run's energy-drift verdict (animsim.measures.drift), with the run's own threshold."""
    from animsim.measures.drift import DEFAULT_DRIFT_WARN_PERCENT, META_THRESHOLD_KEY, drift

    threshold = result.meta.get(META_THRESHOLD_KEY, DEFAULT_DRIFT_WARN_PERCENT)
    return drift(compiled, result.energy_start, result.energy_end, threshold)


def _drift_warning(scene: Path, compiled: Any, result: Any) -> None:
    """A drift beyond --drift-warn is a warning on stderr, also with --quiet (the run still succeeds)."""
    verdict = _drift_of(compiled, result)
    if verdict.warning and result.status != "unstable":  # an unstable run has its own report
        _err(f"{scene}: warning: {verdict.warning_text()}")


def _summary_notes(compiled: Any, result: Any) -> list[str]:
    """Summary lines about what the numbers mean: the method really run."""
    from animsim.measures.effective import fallback_note

    note = fallback_note(compiled)
    return [] if note is None else [f"  note: {note}"]


# --- explain ------------------------------------------------------------------------


@app.command()
@limit_options
def explain(
    scene: SceneArg,
    integrator: Annotated[
        str | None,
        typer.Option(help="Explain with this integrator instead.", autocompletion=_complete_integrator),
    ] = None,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Show what SCENE compiles to: counts, the stages run each step, and what was left out."""
    from animsim import api
    from animsim.analysis.check import wrap

    for line in api.explain(scene, integrator=integrator, backend=_backend(backend), limits=limits):
        typer.echo(wrap(line))


# --- schema ---------------------------------------------------------------------------


def schema_text() -> str:
    from animsim import api

    return api.schema()


@app.command()
def schema() -> None:
    """Print the scene JSON Schema (schemas/scene.schema.json is this output)."""
    sys.stdout.write(schema_text())


# --- init -------------------------------------------------------------------------------


def _template_help() -> str:
    from animsim.templates import TEMPLATES

    return "Starter scene: " + "; ".join(f"{k} ({t.summary})" for k, t in TEMPLATES.items()) + "."


@app.command()
def init(
    path: Annotated[
        Path, typer.Argument(help="The scene file to write, e.g. my_scene.yaml.", show_default=False)
    ],
    template: Annotated[
        str, typer.Option("--template", "-t", help=_template_help(), autocompletion=_complete_template)
    ] = "projectile",
    force: Annotated[bool, typer.Option("--force", help="Replace an existing file.")] = False,
) -> None:
    """Write a commented starter scene, and scene.schema.json beside it for editors."""
    from animsim import api

    for line in api.init(path, template, force=force):
        typer.echo(line)


# --- check ------------------------------------------------------------------------------


@app.command()
@limit_options
def check(
    scenes: Annotated[list[Path], typer.Argument(help="Scene files.", show_default=False)],
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Only problems.")] = False,
    drift_warn: DriftWarnOpt = 10.0,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Validate, analyse and run each scene; exit 0 only if every one is valid and stable.

    A conservative scene whose energy drifts by more than --drift-warn gets a
    warning; it still counts as stable.
    """
    from animsim import api

    with _compiling(quiet, _backend(backend)):
        ok = api.check(
            scenes,
            quiet=quiet,
            echo=typer.echo,
            echo_err=_err,
            limits=limits,
            drift_warn=drift_warn,
            backend=_backend(backend),
        )
    if not ok:
        raise typer.Exit(EXIT_FAILED)


# --- render -------------------------------------------------------------------------------


@app.command()
@limit_options
def render(
    source: Annotated[
        Path,
        typer.Argument(
            help="A scene (simulated first) or a trajectory (.csv, .npz).", metavar="SCENE_OR_TRAJECTORY"
        ),
    ],
    gif: Annotated[Path | None, typer.Option("--gif", help="Write an animated GIF here.")] = None,
    mp4: Annotated[
        Path | None, typer.Option("--mp4", help="Write an MP4 here (needs the mp4 extra: imageio-ffmpeg).")
    ] = None,
    fps: Annotated[
        float, typer.Option("--fps", help="Frames per second; GIF delays come in 10 ms steps.")
    ] = 25.0,
    view: Annotated[
        str | None,
        typer.Option(
            "--view",
            help="xy, xz, yz, zy (orthographic: the across axis, then the up one) or 3d "
            "(perspective); default: from the side, up drawn upward, when gravity points down y or z "
            "(from above when the motion is flat), else the two axes along which it is widest.",
            autocompletion=_complete_render_view,
        ),
    ] = None,
    size: Annotated[
        str | None,
        typer.Option(
            "--size",
            help="WIDTHxHEIGHT in pixels; default 480 on the longer side, shaped like the motion (16:9 at most).",
        ),
    ] = None,
    scene: Annotated[
        Path | None,
        typer.Option("--scene", help="The scene of a trajectory, to draw its springs and planes."),
    ] = None,
    azimuth: Annotated[float | None, typer.Option(help="3d camera: degrees around the up axis.")] = None,
    elevation: Annotated[float | None, typer.Option(help="3d camera: degrees above the horizon.")] = None,
    distance: Annotated[
        float | None, typer.Option(help="3d camera: distance from the centre (m); default fits the bounds.")
    ] = None,
    dot_radius: Annotated[
        float, typer.Option("--dot-radius", help="Radius in pixels of particles that have no size.")
    ] = 3.0,
    integrator: Annotated[
        str | None, typer.Option(help="Override the scene's integrator.", autocompletion=_complete_integrator)
    ] = None,
    dt: Annotated[float | None, typer.Option(help="Override the step size (s).")] = None,
    duration: Annotated[float | None, typer.Option(help="Override the duration (s).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="Comma-separated methods: the scene once per method, panels side by side.",
            autocompletion=_complete_integrators,
        ),
    ] = None,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Render an animation: particles as dots (size and colour over life), springs as lines, planes as the ground."""
    from animsim import api

    with (
        _graceful_stop() as stop,
        _progress(quiet, "rendering", at_least=50) as progress,
        _compiling(quiet, _backend(backend)),
    ):
        result = api.render(
            source,
            gif,
            mp4,
            fps=fps,
            view=view,
            size=size,
            azimuth=azimuth,
            elevation=elevation,
            distance=distance,
            dot_radius=dot_radius,
            scene=scene,
            integrator=integrator,
            dt=dt,
            duration=duration,
            integrators=integrators,
            limits=limits,
            stop=stop,
            progress=progress,
            backend=_backend(backend),
        )
    outs = " and ".join(str(p) for p in result.outputs)
    if result.status == "interrupted":
        if result.outputs:
            _err(f"{source}: interrupted; {outs} has the {result.frames} frames drawn so far")
        else:
            _err(f"{source}: interrupted before the first frame was drawn; nothing written")
        raise typer.Exit(EXIT_INTERRUPTED)
    if not quiet:
        if result.panels:
            typer.echo(
                f"wrote {outs}: {len(result.panels)} panels ({', '.join(result.panels)}), "
                f"{result.frames} frames at {fps:g} fps"
            )
        else:
            typer.echo(
                f"wrote {outs}: {result.frames} frames at {fps:g} fps, view {result.view}, {result.size}"
            )
    if result.status == "unstable":
        if result.panels:
            # A method that blows up is what the picture is there to show, not a failure of the command.
            _err(f"{source}: a panel is marked: {result.failure.describe()}")
            return
        _err(f"{source}: {result.failure.describe()}")
        raise typer.Exit(EXIT_FAILED)


# --- view ---------------------------------------------------------------------------------


@app.command()
@limit_options
def view(
    source: Annotated[
        Path,
        typer.Argument(
            help="A scene (simulated first) or a trajectory (.csv, .npz).", metavar="SCENE_OR_TRAJECTORY"
        ),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="The HTML file to write.")],
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="Comma-separated methods: one panel per method, played in step.",
            autocompletion=_complete_integrators,
        ),
    ] = None,
    fps: Annotated[float, typer.Option("--fps", help="Frames per second recorded for playback.")] = 25.0,
    view: Annotated[
        str,
        typer.Option(
            "--view",
            help="The view it opens with: 3d, xy, xz, yz or zy.",
            autocompletion=_complete_viewer_view,
        ),
    ] = "3d",
    scene: Annotated[
        Path | None,
        typer.Option("--scene", help="The scene of a trajectory, for springs, pins, planes and energy."),
    ] = None,
    integrator: Annotated[
        str | None, typer.Option(help="Override the scene's integrator.", autocompletion=_complete_integrator)
    ] = None,
    dt: Annotated[float | None, typer.Option(help="Override the step size (s).")] = None,
    duration: Annotated[float | None, typer.Option(help="Override the duration (s).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Write one self-contained HTML page that plays the animation (opens offline, in any current browser).

    Play and pause, a time slider, playback speed, a 3D view to orbit, pan and
    zoom (and xy, xz, yz, zy views), springs, planes, pinned particles, colour and
    size over life, and an energy plot whose cursor follows the time. With
    --integrators the scene runs once per method, the panels side by side.
    """
    from animsim import api

    with _graceful_stop() as stop, _compiling(quiet, _backend(backend)):
        summary = api.view(
            source,
            output,
            integrators=integrators,
            fps=fps,
            view=view,
            scene=scene,
            integrator=integrator,
            dt=dt,
            duration=duration,
            limits=limits,
            stop=stop,
            backend=_backend(backend),
        )
    if summary.interrupted:
        _err(f"{source}: interrupted; {output} was not written")
        raise typer.Exit(EXIT_INTERRUPTED)
    if not quiet:
        typer.echo(summary.text)
    for note in summary.notes:
        _err(f"{source}: {note}")


# --- sweep ------------------------------------------------------------------------------


class ReferenceKind(StrEnum):
    """What "exact" is for compare and sweep: a closed form, a converged run, or whichever fits."""

    auto = "auto"
    analytic = "analytic"
    fine = "fine"


@app.command()
@limit_options
def sweep(
    scene: SceneArg,
    set_: Annotated[
        list[str],
        typer.Option(
            "--set",
            help="KEY=V1,V2,...: a dotted key of the scene (springs.0.ks, structures.0.structural.ks, dt) "
            "and its values; repeat for more axes.",
            show_default=False,
            metavar="KEY=V1,V2,...",
        ),
    ] = [],  # noqa: B006 (typer reads the default; never mutated)
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="Comma-separated methods: one more axis.",
            autocompletion=_complete_integrators,
        ),
    ] = None,
    reference: Annotated[
        ReferenceKind | None,
        typer.Option(help="Add an error column against this reference (fine: RK4 at dt/16)."),
    ] = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="The table as CSV.")] = None,
    plot: Annotated[Path | None, typer.Option("--plot", help="Plot --y over --x (PNG, SVG, PDF).")] = None,
    x: Annotated[str | None, typer.Option("--x", help="Swept key on the x axis; default the first.")] = None,
    y: Annotated[
        str | None, typer.Option("--y", help="Column to plot; default error with --reference, else drift.")
    ] = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Local worker processes.", min=1)] = 1,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Dask scheduler address, or 'local' for a LocalCluster (--jobs workers); "
            # \\[ keeps rich markup from eating the extra's name.
            'needs pip install "animsim\\[dask]".',
        ),
    ] = None,
    duration: Annotated[
        float | None, typer.Option(help="Override the duration (s) of every case (a short sweep first).")
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No table, only the files.")] = False,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Run SCENE for every combination of --set values (and --integrators) and tabulate the outcome.

    Each case is re-validated by the scene rules (a refused value is an
    'invalid' row; a key that does not exist is an error before any run) and
    gets its own seed from the scene's seed and its case number, so serial,
    --jobs and --scheduler runs give the same rows. Unstable and invalid
    cases are rows, not failures: the exit status is 0 once the table is
    made, 1 only if a case crashed (status 'error').
    """
    from animsim import api
    from animsim.analysis import sweep as sw

    with _cases_progress(quiet) as progress, _compiling(quiet, _backend(backend)):
        table = api.sweep(
            scene,
            set_,
            integrators=integrators,
            reference=reference.value if reference is not None else None,
            output=output,
            plot=plot,
            x=x,
            y=y,
            jobs=jobs,
            scheduler=scheduler,
            limits=limits,
            progress=progress,
            backend=_backend(backend),
            duration=duration,
        )
    if not quiet:
        sw.print_table(table, _stdout_console())
    counts = table.counts()
    if scheduler is not None:
        where = "Dask LocalCluster" if scheduler == "local" else f"Dask at {scheduler}"
    else:
        where = f"{jobs} processes" if jobs > 1 else "serial"
    summary = ", ".join(f"{n} {status}" for status, n in counts.items())
    wrote = [str(p) for p in (output, plot) if p is not None]
    _err(f"{len(table.rows)} cases ({where}): {summary}" + (f"; wrote {', '.join(wrote)}" if wrote else ""))
    if counts.get(sw.STATUS_ERROR):
        raise typer.Exit(EXIT_FAILED)


@contextmanager
def _cases_progress(quiet: bool):
    """A bar of finished cases on stderr, only on a terminal (cli.md)."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from rich.progress import Progress

    with Progress(transient=True, console=_stderr_console()) as bar:
        task = bar.add_task("cases", total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def _stdout_console():
    from animsim.console import stdout_console

    return stdout_console()


# --- compare ------------------------------------------------------------------------------


@app.command()
@limit_options
def compare(
    scene: SceneArg,
    integrators: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated methods, e.g. euler,midpoint,rk4; default every fixed-step method.",
            autocompletion=_complete_integrators,
        ),
    ] = None,
    dt: Annotated[
        str | None,
        typer.Option(
            "--dt",
            help="Comma-separated step sizes (s); default 2 dt, dt, dt/2 and dt/4 of the scene's dt "
            "(dt/8 instead of 2 dt when 2 dt is longer than the duration), without dt/4 when the four "
            "do not fit --budget.",
        ),
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option(
            "--duration",
            help="Compare over the first S seconds of the scene; default all of it, or as much as "
            "fits --budget.",
        ),
    ] = None,
    budget: Annotated[
        float,
        typer.Option(
            "--budget",
            metavar="SECONDS",
            min=0,
            help="How long compare may take (the probe included, numba compiling not), estimated from "
            "a short timed probe of the scene: what you do not name (--integrators, --dt, --duration) "
            "is cut until the estimate fits (an RK4 reference's extra steps, then dt/4, then the window "
            "down to half the scene, then the methods, then the window again), and what was cut is "
            "printed. Options you name are run as given; the estimate says when they will take "
            "longer. 0: no budget.",
        ),
    ] = 20.0,  # animsim.analysis.compare.DEFAULT_BUDGET (a test keeps them equal)
    reference: Annotated[
        ReferenceKind,
        typer.Option(
            help="What 'exact' is: analytic (a closed form; exit 2 if the scene has none), fine (a converged "
            "run: DOP853 for smooth scenes, else RK4 with dt halved until it stops changing), or auto "
            "(analytic when possible); the one used is printed."
        ),
    ] = ReferenceKind.auto,
    repeat: Annotated[
        int,
        typer.Option(
            help="Timed runs per row after its accuracy run (the median is reported); more runs, steadier "
            "timings. 0 times the accuracy run itself, recording included: cheaper, less exact.",
            min=0,
        ),
    ] = 1,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="Write the table as CSV.")] = None,
    plot: Annotated[
        Path | None,
        typer.Option(help="Work-precision and convergence diagrams; .png, .svg or .pdf."),
    ] = None,
    fail_on_unstable: Annotated[
        bool, typer.Option("--fail-on-unstable", help="Exit 1 if any run was unstable.")
    ] = False,
    jobs: Annotated[
        int,
        typer.Option(
            "--jobs",
            "-j",
            min=1,
            help="Worker processes for the rows. Default 1 (serial): timings need a quiet machine, "
            "and parallel rows share the cores they are timed on; the errors are the same either way.",
        ),
    ] = 1,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Dask scheduler address, or 'local' for a LocalCluster (--jobs workers); "
            'needs pip install "animsim\\[dask]". Same caveat on timings as --jobs.',
        ),
    ] = None,
    backend: Annotated[
        str,
        typer.Option(
            "--backend",
            help="auto (default: numba when installed and it can run the scene, else numpy), numpy or numba "
            '(needs pip install -e ".\\[fast]"). Rows and any RK4 reference run on it; DOP853 on numpy.',
        ),
    ] = "auto",
    *,
    limits: Any = None,
) -> None:
    """Run SCENE with each integrator at each step size; report error against run time.

    Each row is one run: its largest, final and RMS position error against the
    reference at common record times, its energy error (conservative scenes),
    the median simulation time and force evaluations. Under the table: each
    integrator's observed order of convergence.

    Cost: before the runs, a short timed probe of the scene on the chosen
    backend estimates the total, which is printed. With default options the
    plan is cut to fit --budget (20 s), and what was cut is printed; options
    you name are run as given. At the end, the time taken is printed beside
    the estimate.

    An unstable run is a row with status 'unstable', not a failure of the
    comparison: the exit status is 0 when the comparison itself completed
    (use --fail-on-unstable to exit 1 instead), 2 for a bad scene or option.
    """
    from animsim import api
    from animsim.analysis.compare import left_out, summary_lines, table
    from animsim.console import terminal_notice

    with _compare_progress() as (progress, planned):

        def announce(plan: Any) -> None:
            from animsim.analysis.check import wrap
            from animsim.console import table_width

            for line in plan.lines():  # at the screen's width, as the table under it
                _err(wrap(line, table_width(sys.stderr)))
            planned(len(plan.integrators) * len(plan.dts))

        result = api.compare(
            scene,
            integrators,
            dt,
            output=output,
            plot=plot,
            limits=limits,
            duration=duration,
            budget=budget,
            reference=reference.value,
            repeat=repeat,
            backend=_backend(backend),
            jobs=jobs,
            scheduler=scheduler,
            progress=progress,
            notice=terminal_notice(),
            on_plan=announce,
            comparison=True,
        )
    console = _stdout_console()
    console.print(table(result, width=console.width))
    hidden = left_out(result, console.width)
    if hidden:
        console.print(
            f"(left out at {console.width} columns: {', '.join(hidden)}; a wider window or -o FILE.csv has them)",
            highlight=False,
            markup=False,
        )
    for line in summary_lines(result):
        console.print(line, highlight=False, markup=False)
    for path in (output, plot):
        if path is not None:
            console.print(f"wrote {path}", highlight=False, markup=False)
    if fail_on_unstable and result.any_unstable:
        raise typer.Exit(EXIT_FAILED)


@contextmanager
def _compare_progress():
    """A transient progress bar on stderr (terminal only), advanced once per run; yields
    (update, planned): ``planned(total)`` sets the number of runs once they are known."""
    if not sys.stderr.isatty():
        yield None, lambda total: None
        return
    from rich.progress import Progress

    with Progress(transient=True, console=_stderr_console()) as bar:
        task = bar.add_task("probing", total=None)

        def planned(total: int) -> None:
            bar.update(task, total=total, description="comparing")

        def update(label: str) -> None:
            bar.update(task, description=label)
            if not label.startswith("reference"):
                bar.advance(task)

        yield update, planned


# --- plot -------------------------------------------------------------------------------


class PlotKind(StrEnum):
    trajectory = "trajectory"
    energy = "energy"
    phase = "phase"


@app.command()
@limit_options
def plot(
    source: Annotated[
        Path,
        typer.Argument(
            help="A scene (simulated first) or a trajectory (.csv, .npz).", metavar="SCENE_OR_TRAJECTORY"
        ),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="Picture file: .png, .svg or .pdf.")],
    kind: Annotated[
        PlotKind,
        typer.Option(
            "--kind",
            help="Paths of particles; energy against time (kinetic, gravitational, spring, ...); "
            "or phase: position against velocity per particle and axis.",
        ),
    ] = PlotKind.trajectory,
    scene: Annotated[
        Path | None, typer.Option("--scene", help="The scene of a trajectory (needed for --kind energy).")
    ] = None,
    view: Annotated[
        str | None,
        typer.Option(
            "--view",
            help="xy, xz, yz or zy; default: chosen as render chooses it.",
            autocompletion=_complete_plot_view,
        ),
    ] = None,
    integrator: Annotated[
        str | None, typer.Option(help="Override the scene's integrator.", autocompletion=_complete_integrator)
    ] = None,
    dt: Annotated[float | None, typer.Option(help="Override the step size (s).")] = None,
    duration: Annotated[float | None, typer.Option(help="Override the duration (s).")] = None,
    integrators: Annotated[
        str | None,
        typer.Option(
            "--integrators",
            help="--kind phase: comma-separated methods, overlaid.",
            autocompletion=_complete_integrators,
        ),
    ] = None,
    particles: Annotated[
        str | None,
        typer.Option("--particles", help="--kind phase: comma-separated particle ids; default up to 3."),
    ] = None,
    backend: BackendOpt = "auto",
    *,
    limits: Any = None,
) -> None:
    """Draw particle paths, the energy of a run split into its parts (and its drift), or phase portraits."""
    from animsim import api

    with _compiling(False, _backend(backend)):
        api.plot(
            source,
            output,
            kind=kind.value,
            scene=scene,
            view=view,
            integrator=integrator,
            dt=dt,
            duration=duration,
            integrators=integrators,
            particles=particles,
            limits=limits,
            backend=_backend(backend),
        )
    typer.echo(f"wrote {output}")


# --- entry point ----------------------------------------------------------------------------


def _sigterm_as_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> None:
    """Run the app; every AnimsimError becomes a message and an exit status, never a traceback."""
    from animsim.startup import pause_collector, resume_collector

    if argv is None:  # the process's own command line, not a call from Python with arguments
        pause_collector()  # during start-up (animsim.startup)
    # Outside a run's step loop (loading, compiling, assembling an NPZ), SIGTERM
    # unwinds like Ctrl-C, so temporary files are removed and the status is 130
    # instead of the process vanishing mid-write.
    old_term = None
    if (
        threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    ):
        old_term = signal.signal(signal.SIGTERM, _sigterm_as_interrupt)
    try:
        _main(argv)
    finally:
        resume_collector()  # a command that ran no simulation
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


def _refuse_repeated_options(args: list[str]) -> None:
    """An option that takes one value, given twice (``run X -o a.npz -o b.usda``): click keeps
    the last and drops the first without a word, so the user would miss a file they asked for."""
    from typer.core import TyperOption  # typer carries its own click: its classes, not click's

    commands = getattr(typer.main.get_command(app), "commands", {})
    if not args or args[0] not in commands:
        return
    command = commands[args[0]]
    seen: dict[str, list[str]] = {}
    tokens = args[1:]
    for i, token in enumerate(tokens):
        if token == "--":
            break
        for param in command.params:
            if not isinstance(param, TyperOption) or param.multiple or param.is_flag or param.count:
                continue
            name = token.split("=", 1)[0] if token.startswith("--") else token
            if name in param.opts or name in param.secondary_opts:
                value = (
                    token.split("=", 1)[1] if "=" in token else (tokens[i + 1] if i + 1 < len(tokens) else "")
                )
                seen.setdefault("/".join(param.opts), []).append(value)
    for opts, values in seen.items():
        if len(values) > 1:
            raise UsageError(f"{opts} given {len(values)} times ({', '.join(values)}): give it once")


def _main(argv: list[str] | None) -> None:
    try:
        _refuse_repeated_options(sys.argv[1:] if argv is None else list(argv))
        # Without standalone mode, click *returns* the code of a typer.Exit
        # raised in a command (interrupted 130, unstable 1) instead of raising.
        status = typer.Typer.__call__(app, args=argv, prog_name="animsim", standalone_mode=False)
    except AnimsimError as exc:
        _err(str(exc))
        sys.exit(exc.exit_code)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except (typer.Abort, KeyboardInterrupt):
        _err("animsim: interrupted")
        sys.exit(EXIT_INTERRUPTED)
    except BrokenPipeError:
        # The reader of stdout went away (`animsim run -o - | head`): not an error to report.
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silences the flush at exit
        sys.exit(EXIT_FAILED)
    except MemoryError:
        _err("animsim: out of memory; lower the scene's size or --max-memory so the pre-flight refuses it")
        sys.exit(EXIT_FAILED)
    except OSError as exc:  # a write that failed outside the atomic sinks (e.g. stdout on a full disk)
        where = f"{exc.filename}: " if exc.filename else ""
        _err(f"animsim: {where}{exc.strerror or exc}")
        sys.exit(EXIT_FAILED)
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
    sys.exit(status if isinstance(status, int) and not isinstance(status, bool) else 0)
