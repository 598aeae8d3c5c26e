"""``python -m benchmarks``: the whole suite (see :mod:`benchmarks.suite`)."""

import os
import sys

# As the animsim command does (animsim/cli.py), before NumPy loads: one BLAS thread.
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from benchmarks.suite import main  # noqa: E402

sys.exit(main())
