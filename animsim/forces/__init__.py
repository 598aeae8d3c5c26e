"""Force terms: one small module per family.

Every term has the same contract (:class:`ForceTerm`): ``accumulate(x, v, t,
out)`` adds its force on every particle, in newtons, into ``out`` (N, 3). It
never allocates in proportion to the scene after construction except where
NumPy forces a temporary, never loops over particles in Python, and never
validates (the scene was validated once, before compiling).

``potential(x)`` returns the stored energy (J) for conservative terms and is
None for dissipative ones; energy reports and the stability watchdog sum it.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class ForceTerm(Protocol):
    #: one line for ``animsim explain``
    label: str

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None: ...

    def potential(self, x: np.ndarray) -> float | None: ...
