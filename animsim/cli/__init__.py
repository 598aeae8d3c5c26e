"""The ``animsim`` command line (contract: ``cli.md``).

Commands stay thin: parse options, call the library, and turn an
:class:`~animsim.errors.AnimsimError` into an exit status in one place
(:func:`main`). Exit 0 done, 1 the simulation failed or a check found a
problem, 2 the input or the usage is wrong, 130 interrupted.

The package holds one module per concern: :mod:`~animsim.cli.entry` the app,
its help words and the entry point; :mod:`~animsim.cli.options` the options
the commands share; :mod:`~animsim.cli.terminal` messages, progress and
signals; then the commands by family: :mod:`~animsim.cli.runs` (run, explain),
:mod:`~animsim.cli.scenes` (schema, init, check), :mod:`~animsim.cli.pictures`
(render, view), :mod:`~animsim.cli.studies` (sweep, compare) and
:mod:`~animsim.cli.plots` (plot). Everything a user or a test imported from
``animsim.cli`` is importable from here as before.
"""

from __future__ import annotations

import os

# One BLAS thread unless the user says otherwise, set before NumPy loads: the
# loop's only BLAS calls are dot products for the energy watchdog, too small to
# gain from threads, and on a busy machine OpenBLAS's spinning threads made
# each one cost 20 ms instead of 0.1 ms (a 100,000-particle fountain, which is
# checked every step, ran at 18 steps/s instead of 65).
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# Everything that was importable from the command line when it was one module, the
# helpers tests reach (_LIMIT_PARAMS, _notice, _progress) under their old names too.
from animsim.cli.entry import app, main  # noqa: E402
from animsim.cli.options import LIMIT_PARAMS as _LIMIT_PARAMS  # noqa: E402, F401
from animsim.cli.options import (  # noqa: E402
    BackendOpt,
    DriftWarnOpt,
    SceneArg,
    limit_options,
    make_limits,
)
from animsim.cli.pictures import render, view  # noqa: E402
from animsim.cli.plots import PlotKind, plot  # noqa: E402
from animsim.cli.runs import explain, run  # noqa: E402
from animsim.cli.scenes import check, init, schema, schema_text  # noqa: E402
from animsim.cli.studies import ReferenceKind, compare, sweep  # noqa: E402
from animsim.cli.terminal import PROGRESS_AFTER_SECONDS  # noqa: E402
from animsim.cli.terminal import notice_sink as _notice  # noqa: E402, F401
from animsim.cli.terminal import progress_bar as _progress  # noqa: E402, F401

__all__ = [
    "PROGRESS_AFTER_SECONDS",
    "BackendOpt",
    "DriftWarnOpt",
    "PlotKind",
    "ReferenceKind",
    "SceneArg",
    "app",
    "check",
    "compare",
    "explain",
    "init",
    "limit_options",
    "main",
    "make_limits",
    "plot",
    "render",
    "run",
    "schema",
    "schema_text",
    "sweep",
    "view",
]
