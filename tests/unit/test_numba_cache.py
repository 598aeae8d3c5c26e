"""The disk-cache loader that skips numba's compiler set-up falls back to numba's own path.

``animsim.numba_cache.load_cached`` reaches into numba's private
cache machinery; on a numba whose internals differ it must say "not loaded"
(so the caller compiles or loads through the dispatcher), never break a run.
"""

from __future__ import annotations

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from animsim import numba_cache  # noqa: E402


def _fresh_kernel():
    # a new dispatcher each time (not cached on disk), so nothing is loaded yet
    @numba.njit("float64(float64[:])")
    def total(a):
        s = 0.0
        for x in a:
            s += x
        return s

    return total


def test_internals_that_differ_mean_not_loaded(monkeypatch: pytest.MonkeyPatch) -> None:
    kernel = numba.njit(cache=False)(lambda a: a.sum())
    sig = (numba.types.float64[::1],)

    class Broken:
        def _load_overload(self, *args: object) -> None:
            raise AttributeError("a numba with other internals")

    monkeypatch.setattr(kernel, "_cache", Broken(), raising=False)
    assert numba_cache.load_cached(kernel, sig) is False
    monkeypatch.undo()
    # nothing half-registered: numba's own path still compiles and runs it
    assert tuple(sig) not in kernel.overloads
    assert kernel(np.arange(4.0)) == 6.0


def test_a_miss_is_not_loaded() -> None:
    kernel = numba.njit(cache=False)(lambda a: a.sum())
    # the null cache of a function without cache=True never has an entry
    assert numba_cache.load_cached(kernel, (numba.types.float64[::1],)) is False


def test_an_overload_already_there_counts_as_loaded() -> None:
    kernel = _fresh_kernel()  # compiled eagerly for its signature
    assert numba_cache.load_cached(kernel, (numba.types.Array(numba.float64, 1, "A"),)) is True
