"""The errors animsim turns into exit statuses.

Every user-facing failure is an :class:`AnimsimError`; the CLI catches it once
and maps ``exit_code`` to the process status (``cli.md``: 1 the simulation
failed or a check found a problem, 2 the input or the usage is wrong).
"""

from __future__ import annotations

from dataclasses import dataclass

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


@dataclass(frozen=True)
class Diagnostic:
    """One problem in a scene file, located at a YAML node.

    ``line`` and ``column`` are 1-based, as editors show them.
    """

    file: str
    line: int
    column: int
    path: str
    message: str

    def __str__(self) -> str:
        # line 0: a scene built in Python has no lines to point at
        where = f"{self.file}:{self.line}:{self.column}" if self.line else self.file
        return f"{where}: {self.path}: {self.message}" if self.path else f"{where}: {self.message}"


class AnimsimError(Exception):
    """Base of every error meant for the user, never shown with a traceback."""

    exit_code = EXIT_FAILED


class UsageError(AnimsimError):
    """The command line or a file given on it is wrong (exit 2)."""

    exit_code = EXIT_USAGE


class SceneError(AnimsimError):
    """A scene that cannot be run: every problem found, each with its place."""

    exit_code = EXIT_USAGE

    def __init__(self, diagnostics: list[Diagnostic]):
        self.diagnostics = sorted(diagnostics, key=lambda d: (d.file, d.line, d.column, d.path))
        super().__init__("\n".join(str(d) for d in self.diagnostics))


class SimulationError(AnimsimError):
    """The run itself failed (unstable, or an output could not be written)."""

    exit_code = EXIT_FAILED
