"""What the commands show at the terminal while they work, and how they stop.

Messages on stderr (:func:`err`); Ctrl-C and SIGTERM turned into a flag the
step loop polls (:func:`graceful_stop`); the progress bar of a long run
(:func:`progress_bar`); where the engine's one-line notices go
(:func:`notice_sink`) and the notice that numba is compiling
(:func:`compiling`); and the rich console on stderr they draw on.
"""

from __future__ import annotations

import signal
import sys
from contextlib import contextmanager
from typing import Any

import typer


def err(text: str) -> None:
    typer.echo(text, err=True)


class _StopFlag:
    """Set by SIGINT/SIGTERM; the loop polls it at each step boundary.

    The loop's first poll marks it as stepping. Before that (loading,
    compiling, which can take a minute with numba) nothing would read the
    flag, so a signal then stops at once instead (see graceful_stop). So
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
def graceful_stop():
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


#: a run's progress bar opens once it has gone on this long (s): a run that ends sooner
#: needs none, and a longer one should not look hung
PROGRESS_AFTER_SECONDS = 2.0


@contextmanager
def progress_bar(
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
            bar = Progress(transient=True, console=stderr_console())
            bar.start()
            task = bar.add_task(label, total=total, completed=done)
        if done % max(1, total // 200) == 0 or done == total:
            bar.update(task, completed=done)

    try:
        yield update
    finally:
        if bar is not None:
            bar.stop()


def notice_sink(quiet: bool):
    """Where the engine's one-line notices (numba compiling on a first run) go: stderr, on a
    terminal, unless --quiet."""
    from animsim.console import terminal_notice

    return None if quiet else terminal_notice()


@contextmanager
def compiling(quiet: bool, backend: str):
    """While a command runs, tell the person at the terminal when numba compiles a kernel
    family and about how long it takes (the notice of ``run``, for every other command)."""
    from animsim.backends import choose_backend
    from animsim.compile_notice import compile_notices

    numba = choose_backend(backend)[0] == "numba"
    with compile_notices(notice_sink(quiet) if numba else None, numba=numba):
        yield


def stderr_console():
    from rich.console import Console

    return Console(stderr=True)
