"""The ``animsim`` application and its entry point.

The Typer app (whose call maps errors to exit statuses, so the console script
``animsim = "animsim.cli:app"`` gets them too), the words its help uses for
value types, the root callback (``--version``), the registration of every
command in the order ``animsim --help`` lists them, and :func:`main`, which
turns an :class:`~animsim.errors.AnimsimError` (and Ctrl-C, a broken pipe,
a full disk, an internal error) into a message and an exit status in one
place.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from typing import Annotated, Any

import typer

from animsim.cli.pictures import render, view
from animsim.cli.plots import plot
from animsim.cli.runs import explain, run
from animsim.cli.scenes import check, init, schema
from animsim.cli.studies import compare, sweep
from animsim.cli.terminal import err
from animsim.errors import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_USAGE, AnimsimError, UsageError
from animsim.version import __version__


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


# The commands, in the order `animsim --help` lists them.
for _command in (run, explain, schema, init, check, render, view, sweep, compare, plot):
    app.command()(_command)


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
        err(str(exc))
        sys.exit(exc.exit_code)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except (typer.Abort, KeyboardInterrupt):
        err("animsim: interrupted")
        sys.exit(EXIT_INTERRUPTED)
    except BrokenPipeError:
        # The reader of stdout went away (`animsim run -o - | head`): not an error to report.
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silences the flush at exit
        sys.exit(EXIT_FAILED)
    except MemoryError:
        err("animsim: out of memory; lower the scene's size or --max-memory so the pre-flight refuses it")
        sys.exit(EXIT_FAILED)
    except OSError as exc:  # a write that failed outside the atomic sinks (e.g. stdout on a full disk)
        where = f"{exc.filename}: " if exc.filename else ""
        err(f"animsim: {where}{exc.strerror or exc}")
        sys.exit(EXIT_FAILED)
    except Exception as exc:  # click usage errors and anything unexpected
        # Typer vendors its own copy of click, so match click's exceptions by
        # their base class name rather than importing click.
        if any(c.__name__ == "ClickException" for c in type(exc).__mro__):
            exc.show()  # type: ignore[attr-defined]
            sys.exit(exc.exit_code or EXIT_USAGE)  # type: ignore[attr-defined]
        if os.environ.get("ANIMSIM_DEBUG"):
            raise
        err(f"animsim: internal error: {type(exc).__name__}: {exc}")
        err("this is a bug in animsim; run again with ANIMSIM_DEBUG=1 for the traceback")
        sys.exit(EXIT_FAILED)
    sys.exit(status if isinstance(status, int) and not isinstance(status, bool) else 0)
