"""The commands that study many runs of one scene: ``sweep`` runs every
combination of swept values and tabulates the outcome, ``compare`` runs each
integrator at each step size against a reference. Both take a
:class:`ReferenceKind`, and each has its own progress bar of runs.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from animsim.cli.options import BackendOpt, SceneArg, checked_backend, complete_integrators, limit_options
from animsim.cli.terminal import compiling, err, stderr_console
from animsim.errors import EXIT_FAILED


class ReferenceKind(StrEnum):
    """What "exact" is for compare and sweep: a closed form, a converged run, or whichever fits."""

    auto = "auto"
    analytic = "analytic"
    fine = "fine"


#: the Dask option of sweep and compare (compare adds a word on its timings)
SCHEDULER_HELP = (
    "Dask scheduler address, or 'local' for a LocalCluster (--jobs workers); "
    # \\[ keeps rich markup from eating the extra's name.
    'needs pip install "animsim\\[dask]".'
)


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
            autocompletion=complete_integrators,
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
    scheduler: Annotated[str | None, typer.Option("--scheduler", help=SCHEDULER_HELP)] = None,
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

    with _cases_progress(quiet) as progress, compiling(quiet, checked_backend(backend)):
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
            backend=checked_backend(backend),
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
    err(f"{len(table.rows)} cases ({where}): {summary}" + (f"; wrote {', '.join(wrote)}" if wrote else ""))
    if counts.get(sw.STATUS_ERROR):
        raise typer.Exit(EXIT_FAILED)


@contextmanager
def _cases_progress(quiet: bool):
    """A bar of finished cases on stderr, only on a terminal (cli.md)."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from rich.progress import Progress

    with Progress(transient=True, console=stderr_console()) as bar:
        task = bar.add_task("cases", total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def _stdout_console():
    from animsim.console import stdout_console

    return stdout_console()


# --- compare ------------------------------------------------------------------------------


# compare's options, declared once here so that its signature reads in a few lines
CompareIntegratorsOpt = Annotated[
    str | None,
    typer.Option(
        help="Comma-separated methods, e.g. euler,midpoint,rk4; default every fixed-step method.",
        autocompletion=complete_integrators,
    ),
]
CompareDtOpt = Annotated[
    str | None,
    typer.Option(
        "--dt",
        help="Comma-separated step sizes (s); default 2 dt, dt, dt/2 and dt/4 of the scene's dt "
        "(dt/8 instead of 2 dt when 2 dt is longer than the duration), without dt/4 when the four "
        "do not fit --budget.",
    ),
]
CompareDurationOpt = Annotated[
    float | None,
    typer.Option(
        "--duration",
        help="Compare over the first S seconds of the scene; default all of it, or as much as fits --budget.",
    ),
]
BudgetOpt = Annotated[
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
]
CompareReferenceOpt = Annotated[
    ReferenceKind,
    typer.Option(
        help="What 'exact' is: analytic (a closed form; exit 2 if the scene has none), fine (a converged "
        "run: DOP853 for smooth scenes, else RK4 with dt halved until it stops changing), or auto "
        "(analytic when possible); the one used is printed."
    ),
]
RepeatOpt = Annotated[
    int,
    typer.Option(
        help="Timed runs per row after its accuracy run (the median is reported); more runs, steadier "
        "timings. 0 times the accuracy run itself, recording included: cheaper, less exact.",
        min=0,
    ),
]
CompareOutputOpt = Annotated[Path | None, typer.Option("-o", "--output", help="Write the table as CSV.")]
ComparePlotOpt = Annotated[
    Path | None,
    typer.Option(help="Work-precision and convergence diagrams; .png, .svg or .pdf."),
]
FailOnUnstableOpt = Annotated[
    bool, typer.Option("--fail-on-unstable", help="Exit 1 if any run was unstable.")
]
CompareJobsOpt = Annotated[
    int,
    typer.Option(
        "--jobs",
        "-j",
        min=1,
        help="Worker processes for the rows. Default 1 (serial): timings need a quiet machine, "
        "and parallel rows share the cores they are timed on; the errors are the same either way.",
    ),
]
CompareSchedulerOpt = Annotated[
    str | None,
    typer.Option("--scheduler", help=SCHEDULER_HELP + " Same caveat on timings as --jobs."),
]
CompareBackendOpt = Annotated[
    str,
    typer.Option(
        "--backend",
        help="auto (default: numba when installed and it can run the scene, else numpy), numpy or numba "
        '(needs pip install -e ".\\[fast]"). Rows and any RK4 reference run on it; DOP853 on numpy.',
    ),
]


@limit_options
def compare(
    scene: SceneArg,
    integrators: CompareIntegratorsOpt = None,
    dt: CompareDtOpt = None,
    duration: CompareDurationOpt = None,
    budget: BudgetOpt = 20.0,  # animsim.analysis.compare.DEFAULT_BUDGET (a test keeps them equal)
    reference: CompareReferenceOpt = ReferenceKind.auto,
    repeat: RepeatOpt = 1,
    output: CompareOutputOpt = None,
    plot: ComparePlotOpt = None,
    fail_on_unstable: FailOnUnstableOpt = False,
    jobs: CompareJobsOpt = 1,
    scheduler: CompareSchedulerOpt = None,
    backend: CompareBackendOpt = "auto",
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
    from animsim.console import terminal_notice

    with _compare_progress() as (progress, planned):
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
            backend=checked_backend(backend),
            jobs=jobs,
            scheduler=scheduler,
            progress=progress,
            notice=terminal_notice(),
            on_plan=lambda plan: _announce_plan(plan, planned),
            comparison=True,
        )
    _print_comparison(result, output, plot)
    if fail_on_unstable and result.any_unstable:
        raise typer.Exit(EXIT_FAILED)


def _announce_plan(plan: Any, planned: Any) -> None:
    """The plan's lines on stderr, before the runs; the progress bar learns how many there are."""
    from animsim.analysis.check import wrap
    from animsim.console import table_width

    for line in plan.lines():  # at the screen's width, as the table under it
        err(wrap(line, table_width(sys.stderr)))
    planned(len(plan.integrators) * len(plan.dts))


def _print_comparison(result: Any, output: Path | None, plot: Path | None) -> None:
    """The table (what does not fit the width named under it), the summary, the files written."""
    from animsim.analysis.compare import left_out, summary_lines, table

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


@contextmanager
def _compare_progress():
    """A transient progress bar on stderr (terminal only), advanced once per run; yields
    (update, planned): ``planned(total)`` sets the number of runs once they are known."""
    if not sys.stderr.isatty():
        yield None, lambda total: None
        return
    from rich.progress import Progress

    with Progress(transient=True, console=stderr_console()) as bar:
        task = bar.add_task("probing", total=None)

        def planned(total: int) -> None:
            bar.update(task, total=total, description="comparing")

        def update(label: str) -> None:
            bar.update(task, description=label)
            if not label.startswith("reference"):
                bar.advance(task)

        yield update, planned
