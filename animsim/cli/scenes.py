"""The commands about scene files themselves: ``schema`` prints the scene
JSON Schema (:func:`schema_text` is its text), ``init`` writes a commented
starter scene, and ``check`` validates, analyses and runs scenes.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from animsim.cli.options import BackendOpt, DriftWarnOpt, checked_backend, complete_template, limit_options
from animsim.cli.terminal import compiling, err
from animsim.errors import EXIT_FAILED


def schema_text() -> str:
    from animsim import api

    return api.schema()


def schema() -> None:
    """Print the scene JSON Schema (schemas/scene.schema.json is this output)."""
    sys.stdout.write(schema_text())


def _template_help() -> str:
    from animsim.templates import TEMPLATES

    return "Starter scene: " + "; ".join(f"{k} ({t.summary})" for k, t in TEMPLATES.items()) + "."


def init(
    path: Annotated[
        Path, typer.Argument(help="The scene file to write, e.g. my_scene.yaml.", show_default=False)
    ],
    template: Annotated[
        str, typer.Option("--template", "-t", help=_template_help(), autocompletion=complete_template)
    ] = "projectile",
    force: Annotated[bool, typer.Option("--force", help="Replace an existing file.")] = False,
) -> None:
    """Write a commented starter scene, and scene.schema.json beside it for editors."""
    from animsim import api

    for line in api.init(path, template, force=force):
        typer.echo(line)


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

    with compiling(quiet, checked_backend(backend)):
        ok = api.check(
            scenes,
            quiet=quiet,
            echo=typer.echo,
            echo_err=err,
            limits=limits,
            drift_warn=drift_warn,
            backend=checked_backend(backend),
        )
    if not ok:
        raise typer.Exit(EXIT_FAILED)
