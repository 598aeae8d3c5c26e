"""The options the commands share, and how their values are checked.

The scene argument, ``--backend`` and ``--drift-warn`` as annotated types; the
limit options every command that loads a scene takes (:func:`limit_options`
adds them, :func:`make_limits` parses them into a ``RunLimits``); the shell
completions of option values (integrator, backend, template, view and format
names, each imported only when the shell asks); and :func:`checked_backend`,
which refuses an unknown ``--backend`` as a usage error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from animsim.errors import UsageError


# Tab completion of option values. The names come from where the code keeps them;
# each import happens only when the shell asks for a completion.
def _matching(names: Any, incomplete: str) -> list[str]:
    return [n for n in names if n.startswith(incomplete)]


def complete_integrator(incomplete: str) -> list[str]:
    from animsim.methods import names

    INTEGRATOR_NAMES = names()

    return _matching(INTEGRATOR_NAMES, incomplete)


def complete_integrators(incomplete: str) -> list[str]:
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


def complete_template(incomplete: str) -> list[str]:
    from animsim.templates import TEMPLATES

    return _matching(TEMPLATES, incomplete)


def complete_render_view(incomplete: str) -> list[str]:
    from animsim.export.raster import VIEWS

    return _matching(VIEWS, incomplete)


def complete_viewer_view(incomplete: str) -> list[str]:
    from animsim.export.viewer import VIEWS

    return _matching(VIEWS, incomplete)


def complete_plot_view(incomplete: str) -> list[str]:
    from animsim.export.raster import ORTHO_VIEWS

    return _matching(ORTHO_VIEWS, incomplete)


SceneArg = Annotated[Path, typer.Argument(help="The scene file (YAML).", show_default=False, metavar="SCENE")]
SourceArg = Annotated[
    Path,
    typer.Argument(
        help="A scene (simulated first) or a trajectory (.csv, .npz).", metavar="SCENE_OR_TRAJECTORY"
    ),
]
# the overrides of a scene's integrator, step and duration, as run, render, view and plot take them
IntegratorOpt = Annotated[
    str | None, typer.Option(help="Override the scene's integrator.", autocompletion=complete_integrator)
]
DtOpt = Annotated[float | None, typer.Option(help="Override the step size (s).")]
DurationOpt = Annotated[float | None, typer.Option(help="Override the duration (s).")]
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
LIMIT_PARAMS: dict[str, tuple[Any, Any]] = {
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
        for name, (annotation, default) in LIMIT_PARAMS.items()
    ]

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {name: kwargs.pop(name, default) for name, (_, default) in LIMIT_PARAMS.items()}
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


def format_names(incomplete: str) -> list[str]:
    """Shell completion of ``--format``: the registered trajectory formats."""
    from animsim.export.sinks import formats

    return [name for name in formats() if name.startswith(incomplete)]


def checked_backend(name: str) -> str:
    """Check a --backend value (the library also accepts the internal 'reference')."""
    from animsim.backends import BACKENDS

    if name not in BACKENDS:
        raise UsageError(f"--backend: unknown backend {name!r} (valid: {', '.join(BACKENDS)})")
    return name
